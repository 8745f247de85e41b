"""The automatic uploader (`python -m onboard upload-daemon`): closed flights from the on-disk queue to the
ground app, oldest first, in the background.

A process of its own (systemd/directgeo-upload.service), beside the recorder: its failures, memory and I/O
never touch recording, and it runs at nice 10 in the idle I/O class (`onboard.upload.priority`). One loop:

    the oldest ready flight in `<data_dir>/upload/queue/` (the recorder queues each flight it closes)
    → held while the autopilot is armed, or while its state is unknown when `autopilot.link` is set
      (autopilot.json beside status.json: missing, older than `AUTOPILOT_STALE_S`, link down); checked before
      each flight and before each chunk, so arming mid-upload stops it at the next chunk
    → `Uploader.upload_flight` (resumable: the server says what it holds; every chunk and file by SHA-256)
    → done marker, then (`upload.delete_after_upload`) the files the server confirmed are deleted
    failures: the next attempt after `upload.backoff_min_s`, doubling to `upload.backoff_max_s`; a flight
    whose local copy no longer matches its manifest leaves the queue (`upload/failed/`), never uploaded.

`upload.json` beside status.json (atomic, every change and every `upload.poll_s`): queued, uploading, done,
last_result, last_error, last_success_wall_ns, bytes_sent (this process, all flights), and what it waits for.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from onboard.errors import InputError
from onboard.recorder.settings import Settings
from onboard.recorder.status import write_status
from onboard.upload.client import LocalCopyDamaged, Uploader, UploaderOptions, UploadError
from onboard.upload.queue import UploadQueue

log = logging.getLogger(__name__)

UPLOAD_STATUS_NAME = "upload.json"
AUTOPILOT_STATUS_NAME = "autopilot.json"
AUTOPILOT_STALE_S = 5.0
"""autopilot.json older than this (s; the recorder rewrites it every status.interval_s ≤ 2.5 s) says nothing
about the armed state: a stopped recorder, or a recorder whose autopilot feature failed."""


class Held(UploadError):
    """The upload stopped before a chunk: the vehicle armed (or its state became unknown), or a stop was asked."""


def armed_hold(snapshot: dict[str, Any] | None, age_s: float | None, link_configured: bool) -> str | None:
    """Why uploads must wait now (None: go). `snapshot` autopilot.json (None: missing or unreadable), `age_s` its
    age (s), `link_configured` whether the recorder has an autopilot link at all (without one nothing can arm
    it as far as we know, and uploads go)."""
    if not link_configured:
        return None
    if snapshot is None:
        return "autopilot state unknown (no autopilot.json)"
    if age_s is None or age_s > AUTOPILOT_STALE_S:
        return f"autopilot state unknown (autopilot.json {age_s if age_s is None else round(age_s, 1)} s old)"
    if snapshot.get("armed") is True:
        return "armed"
    if not snapshot.get("link_up"):
        return "autopilot link down: armed state unknown"
    if snapshot.get("armed") is not False:
        return "armed state unknown"
    return None


@dataclass
class UploadStatus:
    """upload.json (the pre-flight page reads the first seven keys)."""

    queued: int = 0
    uploading: str | None = None
    done: int = 0
    last_result: str | None = None
    last_error: str | None = None
    last_success_wall_ns: int | None = None
    bytes_sent: int = 0
    state: str = "starting"
    """idle (nothing ready), held (armed / state unknown), uploading, backoff (after a failure), stopped."""
    held_reason: str | None = None
    next_attempt_s: float | None = None
    failed: int = 0
    priority: dict[str, Any] = field(default_factory=dict)
    pid: int = field(default_factory=os.getpid)
    updated_wall_ns: int = 0

    def to_json(self) -> dict[str, Any]:
        """The JSON object written as upload.json."""
        return asdict(self)


class UploadService:
    """The loop of the module doc. `step()` does one thing and returns how long to wait (s); `run()` loops until
    `stop` is set. `uploader_for(before_chunk, on_chunk)` builds the HTTP uploader (a test passes its own)."""

    def __init__(self, settings: Settings, uploader_for: Callable[..., Uploader], stop: threading.Event,
                 wall_ns: Callable[[], int] = time.time_ns) -> None:
        self.settings = settings
        self.queue = UploadQueue(settings.data_dir)
        self.stop = stop
        self.wall_ns = wall_ns
        self.status = UploadStatus()
        self.status_path = settings.status_path.with_name(UPLOAD_STATUS_NAME)
        self.autopilot_path = settings.status_path.with_name(AUTOPILOT_STATUS_NAME)
        self._backoff_s = settings.upload_backoff_min_s
        self._last_status_write = 0.0
        self.uploader = uploader_for(self._before_chunk, self._on_chunk)

    # -- the armed gate ---------------------------------------------------------------------------------
    def hold_reason(self) -> str | None:
        """Why uploading must wait now (see `armed_hold`), read from autopilot.json."""
        snapshot: dict[str, Any] | None = None
        age_s: float | None = None
        try:
            import json

            stat = self.autopilot_path.stat()
            age_s = max(0.0, (self.wall_ns() - stat.st_mtime_ns) / 1e9)
            obj = json.loads(self.autopilot_path.read_text(encoding="utf-8"))
            snapshot = obj if isinstance(obj, dict) else None
        except (OSError, ValueError):
            snapshot = None
        return armed_hold(snapshot, age_s, bool(self.settings.autopilot_link))

    def _before_chunk(self) -> None:
        if self.stop.is_set():
            raise Held("stopping")
        why = self.hold_reason()
        if why is not None:
            raise Held(why)

    def _on_chunk(self, n_bytes: int) -> None:
        self.status.bytes_sent += n_bytes
        now = time.monotonic()
        if now - self._last_status_write >= 0.1:
            self.write_status()

    # -- status -----------------------------------------------------------------------------------------
    def write_status(self) -> None:
        """upload.json now (a failure is logged: the snapshot is for the page, the queue is on disk)."""
        st = self.status
        st.updated_wall_ns = self.wall_ns()
        self._last_status_write = time.monotonic()
        try:
            write_status(self.status_path, st.to_json())
        except OSError as exc:
            log.warning("upload.json not written: %s", exc)

    def _count(self) -> None:
        st = self.status
        st.queued = len(self.queue.entries())
        st.done = self.queue.done_count()

    # -- the loop ---------------------------------------------------------------------------------------
    def run(self) -> None:
        """Upload until `stop` is set."""
        while not self.stop.is_set():
            try:
                wait_s = self.step()
            except OSError as exc:  # the card (queue markers): report, wait, try again
                log.error("upload queue: %s", exc)
                self.status.last_error = f"queue: {exc}"
                wait_s = self.settings.upload_poll_s
            self.status.next_attempt_s = round(wait_s, 3) if wait_s > 0 else None
            self.write_status()
            if wait_s > 0:
                self.stop.wait(wait_s)
        self.status.state = "stopped"
        self.status.uploading = None
        self.write_status()

    def step(self) -> float:
        """One thing: upload the oldest ready flight, or say why not; returns the wait before the next step (s)."""
        st = self.status
        self._count()
        entry = self.queue.next_ready()
        if entry is None:
            st.state, st.held_reason = "idle", None
            return self.settings.upload_poll_s
        why = self.hold_reason()
        if why is not None:
            st.state, st.held_reason = "held", why
            return self.settings.upload_poll_s
        st.held_reason = None
        if not entry.flight_dir.is_dir():
            if entry.flight in self.queue.done():
                self.queue.mark_done(entry.flight, self.queue.done()[entry.flight])
            else:
                self._failed(entry.flight, f"{entry.flight_dir} is gone")
            return 0.0
        st.state, st.uploading = "uploading", entry.flight
        self.write_status()
        started = time.monotonic()
        try:
            report = self.uploader.upload_flight(entry.flight_dir)
        except Held as exc:
            st.state, st.held_reason = "held", str(exc)
            st.last_result = f"paused: {exc}"
            log.info("upload of %s paused: %s", entry.flight, exc)
            return self.settings.upload_poll_s
        except (LocalCopyDamaged, InputError) as exc:
            self._failed(entry.flight, str(exc))
            return 0.0
        except (UploadError, OSError) as exc:
            wait_s = self._backoff_s
            self._backoff_s = min(self._backoff_s * 2, self.settings.upload_backoff_max_s)
            st.state = "backoff"
            st.last_result = "failed, will retry"
            st.last_error = str(exc)
            log.warning("upload of %s failed (%s): next attempt in %.1f s", entry.flight, exc, wait_s)
            return wait_s
        finally:
            st.uploading = None
        elapsed_s = time.monotonic() - started
        self._backoff_s = self.settings.upload_backoff_min_s
        record: dict[str, Any] = {"flight_id": report.flight_id, "files": report.sha256,
                                  "bytes_sent": report.bytes_sent, "retries": report.retries,
                                  "elapsed_s": round(elapsed_s, 3), "done_wall_ns": self.wall_ns(), "deleted": []}
        # done first: a crash while deleting then leaves a done flight with some files, never a queued flight
        # whose folder is half gone
        self.queue.mark_done(entry.flight, record)
        if self.settings.upload_delete_after_upload:
            self.queue.mark_done(entry.flight, {**record, "deleted": self._delete(entry.flight_dir, report.sha256)})
        st.state = "idle"
        st.last_result = f"uploaded {entry.flight}"
        st.last_error = None
        st.last_success_wall_ns = self.wall_ns()
        log.info("flight %s uploaded as %s: %d bytes sent in %.1f s (%d retries)", entry.flight, report.flight_id,
                 report.bytes_sent, elapsed_s, report.retries)
        self._count()
        return 0.0

    def _failed(self, flight: str, error: str) -> None:
        log.error("flight %s cannot be uploaded: %s (moved to upload/failed)", flight, error)
        self.queue.mark_failed(flight, error, self.wall_ns())
        self.status.failed += 1
        self.status.last_result = f"failed: {flight}"
        self.status.last_error = error

    def _delete(self, flight_dir: Path, confirmed: dict[str, str]) -> list[str]:
        """Delete the files the server confirmed (relative names with `/` and SHA-256, `confirmed`), sub-folders
        such as radio/ included, deepest folder first; each folder goes once nothing else is left in it. A
        folder's closed manifest goes last and only with the folder: a flight folder left without it would look
        like an unclosed flight, which the recorder's next start resumes (and a sub-journal without it, like a
        torn one). Returns the names deleted."""
        from onboard.logger.journal import MANIFEST_NAME
        from onboard.upload.client import sha256_file

        deleted: list[str] = []
        by_folder: dict[str, list[str]] = {}
        for name in confirmed:
            by_folder.setdefault(name.rpartition("/")[0], []).append(name)
        folders = sorted({f for n in confirmed for f in _parents(n)}, key=lambda f: (-f.count("/"), f))
        for folder in [*folders, ""]:
            here = flight_dir / folder if folder else flight_dir
            names = sorted(n for n in by_folder.get(folder, []) if n.rpartition("/")[2] != MANIFEST_NAME)
            for name in names:
                if self._delete_file(flight_dir / name, confirmed[name], sha256_file):
                    deleted.append(name)
            manifest = f"{folder}/{MANIFEST_NAME}" if folder else MANIFEST_NAME
            try:
                left = [p.name for p in here.iterdir() if p.name != MANIFEST_NAME]
            except OSError:
                continue
            if manifest in confirmed and not left and self._delete_file(flight_dir / manifest, confirmed[manifest],
                                                                         sha256_file):
                deleted.append(manifest)
            try:
                here.rmdir()  # only if empty
            except OSError:
                pass
        return deleted

    @staticmethod
    def _delete_file(path: Path, digest: str, sha256_file: Callable[[Path], str]) -> bool:
        """Unlink `path` if it still has SHA-256 `digest` (changed since the upload: kept, logged)."""
        try:
            if sha256_file(path) != digest:
                log.warning("%s changed after its upload: kept", path)
                return False
            path.unlink()
            return True
        except OSError as exc:
            log.warning("%s not deleted: %s", path, exc)
            return False


def _parents(name: str) -> list[str]:
    """The folders of a relative `/` name, nearest first, the flight folder itself excluded: `a/b/c` → [`a/b`, `a`]."""
    parts = name.split("/")[:-1]
    return ["/".join(parts[:k]) for k in range(len(parts), 0, -1)]


def http_uploader_for(settings: Settings, token: str, stop: threading.Event) -> Callable[..., Uploader]:
    """The production uploader factory: httpx to `upload.url`, each request retried twice inside one attempt
    (the service's backoff handles longer outages), waits interruptible by `stop`."""
    options = UploaderOptions(chunk_bytes=max(1024, int(settings.upload_chunk_mib * 1024 * 1024)), max_retries=2,
                              backoff_initial_s=0.5, backoff_max_s=2.0, timeout_s=30.0)

    def sleep(seconds: float) -> None:
        stop.wait(seconds)

    def build(before_chunk: Callable[[], None], on_chunk: Callable[[int], None]) -> Uploader:
        return Uploader(settings.upload_url, token, options, sleep=sleep, before_chunk=before_chunk,
                        on_chunk=on_chunk)

    return build
