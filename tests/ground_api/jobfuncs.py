"""Job functions for the runner tests (module level: the runner's spawned child imports them by name)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any


def exits(settings: Any, params: dict[str, Any], files: dict[str, str | None], d: Path, out: Path) -> str:
    raise SystemExit(2)


def interrupted(settings: Any, params: dict[str, Any], files: dict[str, str | None], d: Path, out: Path) -> str:
    raise KeyboardInterrupt


def hangs(settings: Any, params: dict[str, Any], files: dict[str, str | None], d: Path, out: Path) -> str:
    time.sleep(3600)
    return "never"


def works(settings: Any, params: dict[str, Any], files: dict[str, str | None], d: Path, out: Path) -> str:
    return "ok"
