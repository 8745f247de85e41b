"""Tokens: create, list and revoke API tokens (admin only). The clear token is in the creation answer only."""

from __future__ import annotations

import datetime as dt
from typing import Annotated

from fastapi import APIRouter, Depends, HTTPException, Response, status
from pydantic import BaseModel, Field

from ground.api.auth import (
    Principal,
    Role,
    TokenNameTaken,
    create_token,
    default_token_name,
    list_tokens,
    require_role,
    revoke_token,
)
from ground.api.deps import StoreDep
from onboard.errors import InputError

router = APIRouter(prefix="/tokens", tags=["tokens"])
Admin = Annotated[Principal, Depends(require_role(Role.ADMIN))]


class TokenCreate(BaseModel):
    """A token to create: its role and (optionally) a name; default name `<role>-<8 hex digits>`."""

    role: Role
    name: str | None = Field(default=None, description="unique; 1-100 letters, digits, . _ @ + -")


class TokenOut(BaseModel):
    """A token as listed (no secret: only its SHA-256 is stored)."""

    id: str
    name: str
    role: Role
    created_at: dt.datetime
    revoked_at: dt.datetime | None
    last_used_at: dt.datetime | None


class TokenCreated(BaseModel):
    """A created token: `token` is the clear secret, shown this once."""

    id: str
    name: str
    role: Role
    token: str


@router.post("", response_model=TokenCreated, status_code=status.HTTP_201_CREATED, responses={409: {}, 422: {}})
def create(body: TokenCreate, store: StoreDep, _: Admin) -> TokenCreated:
    """Create a token; the answer holds the clear token, which cannot be shown again. 409 when the name is used."""
    name = body.name or default_token_name(body.role)
    try:
        token_id, clear = create_token(store, body.role, name)
    except TokenNameTaken as exc:
        raise HTTPException(status_code=409, detail=str(exc)) from exc
    except InputError as exc:
        raise HTTPException(status_code=422, detail=str(exc)) from exc
    return TokenCreated(id=token_id, name=name, role=body.role, token=clear)


@router.get("", response_model=list[TokenOut])
def list_all(store: StoreDep, _: Admin) -> list[TokenOut]:
    """Every token, active and revoked, without secrets."""
    return [TokenOut(**vars(t)) for t in list_tokens(store)]


@router.delete("/{token_id}", status_code=status.HTTP_204_NO_CONTENT, responses={404: {}})
def revoke(token_id: str, store: StoreDep, _: Admin) -> Response:
    """Revoke a token (by id or name): refused from now on. 404 when unknown or already revoked."""
    if not revoke_token(store, token_id):
        raise HTTPException(status_code=404, detail=f"no active token {token_id!r}")
    return Response(status_code=status.HTTP_204_NO_CONTENT)
