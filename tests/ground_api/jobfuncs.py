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


#: seconds `slow_adjust` waits before the real adjustment (long enough to kill its worker mid-job)
SLOW_S = 4.0


def slow_adjust(settings: Any, params: dict[str, Any], files: dict[str, str | None], d: Path, out: Path) -> str:
    """The real adjustment job, after SLOW_S seconds: same inputs, same outputs, with time to kill its worker."""
    from ground.api.job_kinds import adjust_job

    time.sleep(SLOW_S)
    return adjust_job(settings, params, files, d, out)
