"""Tokens with roles: who may call which route of the ground API.

A bearer token is either the bootstrap token of the settings ($DIRECTGEO_TOKEN / --token-file: the first
admin, `Principal.token_id` None) or one of the `api_tokens` rows, created by `create_token` (CLI
`python -m ground token create`, or `POST /tokens`) and kept only as its SHA-256.

Roles (ADMIN passes every check):
- DRONE: create flights and upload the files of the flights it created; nothing else.
- ENGINEER: read and process everything (flights, files, jobs, results, reports, exports), add files.
- WORKER: what a `ground worker` machine needs (read job specs and flight files, post job outputs/status).
- ADMIN: everything, and the tokens.

Routes state their roles with one dependency, `require_role(...)`; `document_roles(app)` then writes those
same roles into each operation's OpenAPI (`x-roles` and a "Roles: …" line), so what a route states and what it
checks cannot differ.
"""

# no `from __future__ import annotations`: FastAPI resolves the annotations of `RoleCheck.__call__` (an
# instance method, without the module globals a function carries) only when they are real objects
import datetime as dt
import hashlib
import hmac
import re
import secrets
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Annotated, Any

from fastapi import Depends, FastAPI, HTTPException, Request, status
from fastapi.dependencies.models import Dependant
from fastapi.routing import APIRoute
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy import or_, select
from starlette.routing import BaseRoute

from ground.api.roles import Role
from ground.api.settings import ApiSettings
from ground.store import ApiToken, Store, new_id
from onboard.errors import InputError

#: bytes of randomness of a created token (256 bits; token_urlsafe gives 43 characters)
TOKEN_BYTES = 32
#: `last_used_at` is written at most this often per token (s): not one database write per upload chunk
LAST_USED_RESOLUTION_S = 60.0
OPENAPI_ROLES_KEY = "x-roles"
__all__ = ["Principal", "Role", "authenticate", "check_flight_owner", "create_token", "document_roles",
           "hash_token", "list_tokens", "principal_for_id", "require_role", "revoke_token"]
_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._@+\-]{0,99}$")
_ID_RE = re.compile(r"^[0-9a-f]{32}$")

_bearer = HTTPBearer(auto_error=False, description="an API token: `python -m ground token create --role …`, "
                     "or the bootstrap admin token ($DIRECTGEO_TOKEN or --token-file)")
CredentialsDep = Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]


@dataclass(frozen=True)
class Principal:
    """Who is calling: the token's id (None for the bootstrap token), its name and its role."""

    token_id: str | None
    name: str
    role: Role


BOOTSTRAP_NAME = "bootstrap"


class TokenNameTaken(InputError):
    """`create_token` with a name another token already has."""


@dataclass(frozen=True)
class TokenInfo:
    """A token as listed: everything but its secret (which is not kept anyway)."""

    id: str
    name: str
    role: Role
    created_at: dt.datetime
    revoked_at: dt.datetime | None
    last_used_at: dt.datetime | None


def hash_token(token: str) -> str:
    """What the store keeps of a token: the hex SHA-256 of its UTF-8 bytes (why not a slow KDF: `ApiToken`)."""
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


def _aware(t: dt.datetime | None) -> dt.datetime | None:
    """SQLite returns naive datetimes for timezone columns: they were written in UTC."""
    return t.replace(tzinfo=dt.UTC) if t is not None and t.tzinfo is None else t


def authenticate(store: Store, settings: ApiSettings, token: str) -> Principal | None:
    """The principal of a bearer token, or None (unknown, revoked or empty).

    Constant-time: the bootstrap token is compared with `hmac.compare_digest`; a stored token is found by the
    SHA-256 of what was supplied (timing can only tell about that digest, not about a stored token's bytes) and
    the digests compared with `compare_digest` again.
    """
    if not token:
        return None
    if hmac.compare_digest(token.encode("utf-8"), settings.token.encode("utf-8")):
        return Principal(token_id=None, name=BOOTSTRAP_NAME, role=Role.ADMIN)
    digest = hash_token(token)
    with store.session() as s:
        row = s.scalar(select(ApiToken).where(ApiToken.token_sha256 == digest))
        if row is None or not hmac.compare_digest(row.token_sha256, digest) or row.revoked_at is not None:
            return None
        try:
            role = Role(row.role)
        except ValueError:  # a role this version does not know: refuse rather than guess
            return None
        now = dt.datetime.now(dt.UTC)
        last = _aware(row.last_used_at)
        if last is None or (now - last).total_seconds() >= LAST_USED_RESOLUTION_S:
            row.last_used_at = now
            s.commit()
        return Principal(token_id=row.id, name=row.name, role=role)


def principal_for_id(store: Store, token_id: str) -> Principal | None:
    """The principal of an active stored token by its id (e.g. a web session that keeps the token id, not the
    token), None when unknown or revoked: a revoked token ends the sessions opened with it."""
    with store.session() as s:
        row = s.get(ApiToken, token_id)
        if row is None or row.revoked_at is not None or row.role not in set(Role):
            return None
        return Principal(token_id=row.id, name=row.name, role=Role(row.role))


def check_token_name(name: str) -> str:
    """A token name (1–100 of letters, digits, . _ @ + -; not 32 hex digits, which would read as an id)."""
    if not _NAME_RE.match(name) or _ID_RE.match(name):
        raise InputError(f"token name {name!r}: 1-100 letters, digits, . _ @ + - (starting with a letter or "
                         "digit), and not 32 hex digits")
    return name


def default_token_name(role: Role) -> str:
    """`<role>-<8 random hex digits>`: the name of a token created without one."""
    return f"{Role(role).value}-{new_id()[:8]}"


def create_token(store: Store, role: Role, name: str) -> tuple[str, str]:
    """A new token of `role` named `name`: returns (token id, clear token). The clear token exists only in the
    return value: the store keeps its SHA-256. `TokenNameTaken` when the name is used (even by a revoked one)."""
    role = Role(role)
    check_token_name(name)
    clear = secrets.token_urlsafe(TOKEN_BYTES)
    with store.session() as s:
        if s.scalar(select(ApiToken.id).where(ApiToken.name == name)) is not None:
            raise TokenNameTaken(f"a token named {name!r} exists already")
        row = ApiToken(name=name, role=role.value, token_sha256=hash_token(clear))
        s.add(row)
        s.commit()
        return row.id, clear


def revoke_token(store: Store, token_id_or_name: str) -> bool:
    """Revoke the token with this id or name: True when it was active, False when unknown or already revoked."""
    with store.session() as s:
        row = s.scalar(select(ApiToken).where(or_(ApiToken.id == token_id_or_name,
                                                  ApiToken.name == token_id_or_name)))
        if row is None or row.revoked_at is not None:
            return False
        row.revoked_at = dt.datetime.now(dt.UTC)
        s.commit()
        return True


def list_tokens(store: Store) -> list[TokenInfo]:
    """Every token (active and revoked), oldest first, without secrets."""
    with store.session() as s:
        rows = s.scalars(select(ApiToken).order_by(ApiToken.created_at, ApiToken.name)).all()
        return [TokenInfo(id=r.id, name=r.name, role=Role(r.role), created_at=_aware(r.created_at),  # type: ignore[arg-type]
                          revoked_at=_aware(r.revoked_at), last_used_at=_aware(r.last_used_at)) for r in rows]


def _roles_text(roles: frozenset[Role]) -> str:
    return ", ".join(r.value for r in Role if r in roles)


class RoleCheck:
    """The dependency `require_role` returns: authenticates the bearer token and checks its role.

    `roles` is the set of roles allowed (ADMIN always included); `document_roles` reads it."""

    def __init__(self, roles: frozenset[Role]) -> None:
        self.roles = roles

    def __repr__(self) -> str:
        return f"require_role({_roles_text(self.roles)})"

    def __call__(self, request: Request, credentials: CredentialsDep) -> Principal:
        supplied = credentials.credentials if credentials is not None else ""
        store: Store = request.app.state.store
        settings: ApiSettings = request.app.state.settings
        principal = authenticate(store, settings, supplied)
        if principal is None:
            raise HTTPException(status_code=status.HTTP_401_UNAUTHORIZED,
                                detail="missing, unknown or revoked API token",
                                headers={"WWW-Authenticate": "Bearer"})
        if principal.role not in self.roles:
            raise HTTPException(status_code=status.HTTP_403_FORBIDDEN,
                                detail=f"a {principal.role.value} token may not do this "
                                       f"(roles: {_roles_text(self.roles)})")
        return principal


def require_role(*roles: Role) -> RoleCheck:
    """FastAPI dependency factory: the caller's `Principal` when its token has one of `roles` (or is ADMIN);
    401 without a valid token, 403 with another role. Use as
    `principal: Annotated[Principal, Depends(require_role(Role.ENGINEER))]` or in `dependencies=[…]`."""
    if not roles:
        raise ValueError("require_role needs at least one role")
    return RoleCheck(frozenset(Role(r) for r in roles) | {Role.ADMIN})


def check_flight_owner(principal: Principal, created_by: str | None) -> None:
    """403 when a DRONE token touches a flight another token created (other roles: every flight)."""
    if principal.role is Role.DRONE and (principal.token_id is None or principal.token_id != created_by):
        raise HTTPException(status_code=status.HTTP_403_FORBIDDEN,
                            detail="a drone token may only touch the flights it created")


def _role_checks(dependant: Dependant) -> list[RoleCheck]:
    found = [dependant.call] if isinstance(dependant.call, RoleCheck) else []
    for sub in dependant.dependencies:
        found.extend(_role_checks(sub))
    return found


def route_roles(route: APIRoute) -> frozenset[Role] | None:
    """The roles a route lets through (the intersection of its `require_role` dependencies), None when open."""
    checks = _role_checks(route.dependant)
    if not checks:
        return None
    allowed = frozenset(Role)
    for c in checks:
        allowed &= c.roles
    return allowed


def _api_routes(routes: Sequence[BaseRoute]) -> Iterator[APIRoute]:
    """The API routes, also those of included routers (FastAPI 0.16x keeps an included router as one
    `_IncludedRouter` entry whose `original_router` holds the routes; older versions copy the routes)."""
    for route in routes:
        if isinstance(route, APIRoute):
            yield route
        original = getattr(route, "original_router", None)
        if original is not None:
            yield from _api_routes(original.routes)


def document_roles(app: FastAPI) -> None:
    """Write each route's roles, read from its `require_role` dependencies, into its OpenAPI operation:
    `x-roles` (list of role names; absent on an open route) and a "Roles: …" line in the description.
    Called by `create_app` after every router is included (and before the schema is first built)."""
    for route in _api_routes(app.routes):
        roles = route_roles(route)
        if roles is None:
            continue
        names = [r.value for r in Role if r in roles]
        extra: dict[str, Any] = dict(route.openapi_extra or {})
        extra[OPENAPI_ROLES_KEY] = names
        route.openapi_extra = extra
        line = f"Roles: {', '.join(names)}."
        if line not in (route.description or ""):
            route.description = f"{route.description.rstrip()}\n\n{line}" if route.description else line
    app.openapi_schema = None  # rebuilt with the roles on first use
