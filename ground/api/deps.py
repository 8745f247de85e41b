"""FastAPI dependencies: settings and store (the token check is `ground.api.auth.require_role`)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from ground.api.settings import ApiSettings
from ground.store import Store


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

