"""Web sign-in sessions and CSRF tokens, kept server-side in the store (`ground.store.WebSession`).

The browser holds only a random session id in an HttpOnly, SameSite=Lax cookie; the store keeps its SHA-256
(a copy of the database opens no session), the session's CSRF token, who signed in and the expiry (UTC). The
user token typed at sign-in is checked once by `ground.api.auth.authenticate` and never kept.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import hmac
import secrets
from dataclasses import dataclass

from sqlalchemy import delete

from ground.api.auth import principal_for_id
from ground.store import Store, WebSession

#: the session cookie's name (its value: a random id, 43 URL-safe characters)
SESSION_COOKIE = "directgeo_session"
#: the sign-in form's CSRF cookie (double-submit: there is no session yet to hold the token)
LOGIN_CSRF_COOKIE = "directgeo_login_csrf"
#: the hidden form field every POST form carries
CSRF_FIELD = "csrf_token"
#: roles that may sign in to the web interface (people); drone and worker tokens are for machines
WEB_ROLES = ("engineer", "admin")


@dataclass(frozen=True)
class SignedIn:
    """Who a live session belongs to, and the CSRF token its forms must carry."""

    token_id: str | None
    name: str
    role: str
    csrf_token: str
    expires_at: dt.datetime


def _digest(session_id: str) -> str:
    return hashlib.sha256(session_id.encode()).hexdigest()


def new_secret() -> str:
    """A random URL-safe secret of 256 bits (session ids, CSRF tokens)."""
    return secrets.token_urlsafe(32)


def sign_in_refusal(role: str) -> str | None:
    """Why a token of `role` may not sign in (in words), or None when it may."""
    if role in WEB_ROLES:
        return None
    return (f"a {role} token cannot sign in to the web interface: it is for machines (a drone uploads its flights, "
            "a worker runs jobs). Sign in with an engineer or admin token.")


def open_session(store: Store, token_id: str | None, name: str, role: str, ttl_s: float, now: dt.datetime) -> tuple[str, SignedIn]:
    """Store a new session for a principal already checked; returns (cookie value, the session)."""
    session_id = new_secret()
    row = WebSession(id_sha256=_digest(session_id), csrf_token=new_secret(), token_id=token_id, name=name,
                     role=role, created_at=now, expires_at=now + dt.timedelta(seconds=ttl_s))
    with store.session() as s:
        s.execute(delete(WebSession).where(WebSession.expires_at <= now))  # the table does not grow forever
        s.add(row)
        s.commit()
    return session_id, SignedIn(token_id, name, role, row.csrf_token, row.expires_at)


def _aware(t: dt.datetime) -> dt.datetime:
    """SQLite hands back naive datetimes for timezone-aware columns: they were written in UTC."""
    return t if t.tzinfo is not None else t.replace(tzinfo=dt.UTC)


def find_session(store: Store, session_id: str | None, now: dt.datetime) -> SignedIn | None:
    """The live session of a cookie value; None when absent, unknown, expired, or its token was revoked or
    changed role since sign-in (such a row is deleted). A bootstrap-token session (token id None) lives until
    it expires."""
    if not session_id:
        return None
    with store.session() as s:
        row = s.get(WebSession, _digest(session_id))
        if row is None:
            return None
        if row.token_id is not None:
            principal = principal_for_id(store, row.token_id)
            revoked = principal is None or principal.role.value != row.role
        else:
            revoked = False
        if _aware(row.expires_at) <= now or revoked:
            s.delete(row)
            s.commit()
            return None
        return SignedIn(row.token_id, row.name, row.role, row.csrf_token, _aware(row.expires_at))


def close_session(store: Store, session_id: str | None) -> None:
    """Sign out: the session's row is deleted (the cookie alone opens nothing any more)."""
    if not session_id:
        return
    with store.session() as s:
        s.execute(delete(WebSession).where(WebSession.id_sha256 == _digest(session_id)))
        s.commit()


def close_sessions_of_token(store: Store, token_id: str) -> int:
    """Every session opened with a token (when it is revoked); returns how many were closed."""
    with store.session() as s:
        n = s.execute(delete(WebSession).where(WebSession.token_id == token_id)).rowcount
        s.commit()
    return int(n or 0)


def csrf_matches(expected: str | None, supplied: object) -> bool:
    """Whether a form's CSRF field equals the expected token (constant time; empty never matches)."""
    if not expected or not isinstance(supplied, str) or not supplied:
        return False
    return hmac.compare_digest(expected.encode(), supplied.encode())
