"""The upload queue on disk: one marker file per flight, written atomically, surviving reboots.

    <data_dir>/upload/queue/<flight>.json   {"flight": name, "ready": bool, "queued_wall_ns": int}
    <data_dir>/upload/done/<flight>.json    {"flight", "flight_id", "files": {name: sha256}, "bytes_sent",
                                             "done_wall_ns", "deleted"}
    <data_dir>/upload/failed/<flight>.json  {"flight", "error", "failed_wall_ns"}: the local copy is damaged

The recorder writes a flight's marker with `ready` false just before it closes the flight and rewrites it with
`ready` true once every file of the flight is closed (journal, events, the features' files); a marker left
not ready by a crash is made ready at the recorder's next start when that flight's manifest is closed
(`promote_closed`). The uploader takes ready markers oldest first (flight names sort in recording order).
No network, no clocks of its own: wall times are passed in.
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from onboard.formats.atomic import write_json_atomic

log = logging.getLogger(__name__)

UPLOAD_DIR = "upload"
QUEUE, DONE, FAILED = "queue", "done", "failed"


@dataclass(frozen=True)
class QueueEntry:
    """One queued flight: its name, folder, and whether every file of it is closed."""

    flight: str
    flight_dir: Path
    ready: bool


class UploadQueue:
    """The queue of `data_dir` (see module doc)."""

    def __init__(self, data_dir: Path) -> None:
        self.data_dir = Path(data_dir)
        self.root = self.data_dir / UPLOAD_DIR

    def _dir(self, kind: str) -> Path:
        return self.root / kind

    def _marker(self, kind: str, flight: str) -> Path:
        return self._dir(kind) / f"{flight}.json"

    def enqueue(self, flight: str, ready: bool, wall_ns: int) -> None:
        """Queue `flight` (a folder name in data_dir); `ready` once all its files are closed. A flight already
        uploaded is not queued again."""
        if self._marker(DONE, flight).exists():
            return
        self._dir(QUEUE).mkdir(parents=True, exist_ok=True)
        write_json_atomic(self._marker(QUEUE, flight), {"flight": flight, "ready": ready, "queued_wall_ns": wall_ns})

    def entries(self) -> list[QueueEntry]:
        """Queued flights, oldest first (unreadable markers are skipped with a warning)."""
        d = self._dir(QUEUE)
        if not d.is_dir():
            return []
        out = []
        for p in sorted(d.glob("flight-*.json"), key=lambda p: p.stem):
            try:
                obj = json.loads(p.read_text(encoding="utf-8"))
                out.append(QueueEntry(str(obj["flight"]), self.data_dir / str(obj["flight"]), bool(obj["ready"])))
            except (OSError, ValueError, KeyError, TypeError) as exc:
                log.warning("upload queue: %s unreadable (%s): skipped", p, exc)
        return out

    def next_ready(self) -> QueueEntry | None:
        """The oldest flight ready to upload."""
        return next((e for e in self.entries() if e.ready), None)

    def promote_closed(self, current: str | None) -> list[str]:
        """Markers left not ready by a crash whose flight is closed (and is not `current`, being recorded): made
        ready. Returns their names."""
        from onboard.logger.journal import read_manifest

        promoted = []
        for e in self.entries():
            if e.ready or e.flight == current:
                continue
            manifest = read_manifest(e.flight_dir)
            if manifest is not None and manifest.closed:
                obj = json.loads(self._marker(QUEUE, e.flight).read_text(encoding="utf-8"))
                write_json_atomic(self._marker(QUEUE, e.flight), {**obj, "ready": True})
                promoted.append(e.flight)
        return promoted

    def mark_done(self, flight: str, record: dict[str, Any]) -> None:
        """`flight` uploaded and verified: the done marker first, then the queue marker goes (a crash between
        leaves both, and `entries` skips nothing: the next upload of it sends nothing and ends here again)."""
        self._dir(DONE).mkdir(parents=True, exist_ok=True)
        write_json_atomic(self._marker(DONE, flight), {"flight": flight, **record})
        self._remove(QUEUE, flight)

    def mark_failed(self, flight: str, error: str, wall_ns: int) -> None:
        """`flight` cannot be uploaded as it is (its local copy is damaged): out of the queue, kept on disk."""
        self._dir(FAILED).mkdir(parents=True, exist_ok=True)
        write_json_atomic(self._marker(FAILED, flight), {"flight": flight, "error": error, "failed_wall_ns": wall_ns})
        self._remove(QUEUE, flight)

    def _remove(self, kind: str, flight: str) -> None:
        try:
            os.unlink(self._marker(kind, flight))
        except FileNotFoundError:
            pass

    def done(self) -> dict[str, dict[str, Any]]:
        """Uploaded flights: name → done record."""
        d = self._dir(DONE)
        out: dict[str, dict[str, Any]] = {}
        if d.is_dir():
            for p in sorted(d.glob("flight-*.json"), key=lambda p: p.stem):
                try:
                    out[p.stem] = json.loads(p.read_text(encoding="utf-8"))
                except (OSError, ValueError) as exc:
                    log.warning("upload queue: %s unreadable (%s)", p, exc)
        return out

    def done_count(self) -> int:
        """How many flights were uploaded."""
        d = self._dir(DONE)
        return len(list(d.glob("flight-*.json"))) if d.is_dir() else 0
