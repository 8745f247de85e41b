"""FastAPI dependencies: settings, store and the bearer-token check (constant-time)."""

from __future__ import annotations

import hmac
from typing import Annotated

from fastapi import Depends, HTTPException, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from ground.api.settings import ApiSettings
from ground.store import Store

_bearer = HTTPBearer(auto_error=False, description="the ground API token ($DIRECTGEO_TOKEN or --token-file)")


def get_settings(request: Request) -> ApiSettings:
    """The settings the app was created with."""
    settings: ApiSettings = request.app.state.settings
    return settings


def get_store(request: Request) -> Store:
    """The app's flight store."""
    store: Store = request.app.state.store
    return store


SettingsDep = Annotated[ApiSettings, Depends(get_settings)]
StoreDep = Annotated[Store, Depends(get_store)]
CredentialsDep = Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]


def require_token(credentials: CredentialsDep, settings: SettingsDep) -> None:
    """401 unless `Authorization: Bearer <token>` matches the configured token (compared in constant time)."""
    supplied = credentials.credentials if credentials is not None else ""
    if not hmac.compare_digest(supplied.encode(), settings.token.encode()):
        raise HTTPException(
            status_code=status.HTTP_401_UNAUTHORIZED,
            detail="missing or wrong API token",
            headers={"WWW-Authenticate": "Bearer"},
        )
