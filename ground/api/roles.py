"""The roles of API tokens (apart from `ground.api.auth` so the command line can name them without importing
FastAPI). What each may do: `ground.api.auth`."""

from __future__ import annotations

from enum import StrEnum


class Role(StrEnum):
    """What a token may do: drone (create flights, upload their files), engineer (read and process
    everything), admin (everything and the tokens), worker (a processing machine)."""

    DRONE = "drone"
    ENGINEER = "engineer"
    ADMIN = "admin"
    WORKER = "worker"
