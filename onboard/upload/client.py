"""Resumable, checksummed upload of a recorded flight to the ground API (httpx).

Reads the flight's `manifest.json` (onboard.logger.journal), checks every segment against the SHA-256 the
recorder wrote (a segment that no longer matches is reported, never uploaded as if good), hashes the other
files of the flight folder, creates the flight on the server (idempotent: same name and files re-open it),
then for each file asks the server how many bytes it holds (HEAD → Upload-Offset) and sends the rest in
chunks, each with its own SHA-256. Network errors and rejected chunks are retried with back-off; a 409 means
the server's offset moved: ask again and continue from there. The server verifies the whole file at the end.

Usage: `python -m onboard.upload --url http://ground:8600 [--token-file F] FLIGHT_DIR` (token also from
$DIRECTGEO_TOKEN). A drone token is enough (and all a drone should hold): the uploader only creates its flight,
asks offsets, sends chunks and reads its flight back.
"""

from __future__ import annotations

import hashlib
import logging
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import quote

import httpx

from onboard.errors import InputError, OnboardError
from onboard.formats.digest import sha256_file

log = logging.getLogger(__name__)

CHUNK_SHA_HEADER = "X-Chunk-SHA256"
OFFSET_HEADER = "Upload-Offset"
#: files of a flight folder that are never uploaded (temporary files of the recorder)
SKIP_SUFFIXES = (".tmp", ".part")
#: manifest roles by file name (the ground API queues the adjustment when trajectory+events+orientations exist)
ROLE_BY_NAME = {"events.jsonl": "events", "manifest.json": "manifest"}
ROLE_BY_SUFFIX = {".ubx": "raw", ".idx": "index", ".pos": "trajectory"}
ROVER_OBS_ROLE = "rover_obs"
"""Role of the flight's own journal segments (`NNNNNN.ubx` at the top): the rover of a ground RTK job."""
BASE_OBS_ROLE = "base_obs"
"""Role of the corrections journal's segments (`radio/NNNNNN.ubx`: the base's RTCM3 as received, over the
radio or reassembled from MAVLink GPS_RTCM_DATA): the base of a ground RTK job."""
REALTIME_TRAJECTORY_ROLE = "realtime_trajectory"
"""Role of the companion's real-time solution (`solution.pos`): kept apart from `trajectory` so that the
ground's adjustment uses the flight's post-processed RTK output unless a job names this file."""


def flight_file_role(name: str) -> str | None:
    """The role a file of a recorded flight folder has by its place (`name` relative, `/`-separated): the
    companion's layout (onboard.logger.journal) is known here, where the upload
    manifest is written, so the ground needs no knowledge of it."""
    from onboard.logger.journal import RADIO_DIR, SOLUTION_NAME, is_segment_name

    folder, _, base = name.rpartition("/")
    if is_segment_name(base) and folder in ("", RADIO_DIR):
        return ROVER_OBS_ROLE if folder == "" else BASE_OBS_ROLE
    if name == SOLUTION_NAME:
        return REALTIME_TRAJECTORY_ROLE
    return ROLE_BY_NAME.get(base) or ROLE_BY_SUFFIX.get(Path(base).suffix)


class UploadError(OnboardError):
    """The upload cannot complete (server refusal, corrupted local file, retries exhausted)."""


class LocalCopyDamaged(UploadError):
    """The flight on the card no longer matches its manifest (a segment changed or is missing): retrying cannot
    help, and it is never uploaded as if good."""


@dataclass(frozen=True)
class UploaderOptions:
    """Chunking and retry policy."""

    chunk_bytes: int = 4 * 1024 * 1024
    max_retries: int = 8
    backoff_initial_s: float = 0.5
    backoff_max_s: float = 30.0
    timeout_s: float = 60.0


@dataclass
class FileEntry:
    """A file to upload: name in the flight folder, size, SHA-256, role."""

    name: str
    size: int
    sha256: str
    role: str | None = None

    def to_json(self) -> dict[str, Any]:
        """Manifest entry as the API expects it."""
        return {"name": self.name, "size": self.size, "sha256": self.sha256, "role": self.role}


@dataclass
class UploadReport:
    """What an upload did: flight id, bytes sent (this run), per-file final state, retries used."""

    flight_id: str
    bytes_sent: int = 0
    chunks_sent: int = 0
    retries: int = 0
    files: dict[str, str] = field(default_factory=dict)
    sha256: dict[str, str] = field(default_factory=dict)
    """name → SHA-256 (hex) of every file, as the server confirmed it at the end (`_verify`)."""


def flight_files(flight_dir: Path) -> list[str]:
    """Names (relative, `/`-separated, sorted) of the files of a flight folder to upload: every regular file,
    sub-folders included (the `radio/` journal), but no hidden file or folder and no temporary file."""
    names = []
    for p in flight_dir.rglob("*"):
        rel = p.relative_to(flight_dir)
        if any(part.startswith(".") for part in rel.parts) or p.name.endswith(SKIP_SUFFIXES) or not p.is_file():
            continue
        names.append(rel.as_posix())
    return sorted(names)


def build_upload_manifest(flight_dir: str | Path, roles: dict[str, str] | None = None) -> tuple[str, list[FileEntry]]:
    """(flight name, files) for a flight folder, sub-folders included (names relative with `/`).

    Segments listed in the onboard manifest, or in a sub-journal's (`radio/manifest.json`), must still have the
    size and SHA-256 recorded there (else `LocalCopyDamaged`); other regular files are hashed now. Roles come
    from the file's place (`flight_file_role`); `roles` adds or overrides roles by relative name (e.g.
    {"poses.csv": "orientations"}).
    """
    from onboard.logger.journal import MANIFEST_NAME, read_manifest

    d = Path(flight_dir)
    if not d.is_dir():
        raise InputError(f"{d} is not a flight folder")
    names = flight_files(d)
    recorded: dict[str, Any] = {}
    name = d.name
    for manifest_name in [n for n in names if n.rpartition("/")[2] == MANIFEST_NAME]:
        folder = manifest_name.rpartition("/")[0]
        manifest = read_manifest(d / folder)
        if manifest is None:
            raise UploadError(f"{d / manifest_name} is unreadable; let the recorder rebuild it before uploading")
        recorded |= {f"{folder}/{s.name}" if folder else s.name: s for s in manifest.segments}
        if not folder:
            name = manifest.flight
    entries: list[FileEntry] = []
    for rel in names:
        p = d / rel
        size, digest = p.stat().st_size, sha256_file(p)
        seg = recorded.get(rel)
        if seg is not None and (seg.bytes != size or seg.sha256 != digest):
            raise LocalCopyDamaged(f"{p}: {size} bytes sha256 {digest[:12]}… but the manifest recorded {seg.bytes} bytes "
                              f"sha256 {seg.sha256[:12]}…: local copy damaged, not uploaded")
        entries.append(FileEntry(rel, size, digest, (roles or {}).get(rel) or flight_file_role(rel)))
    missing = set(recorded) - set(names)
    if missing:
        raise LocalCopyDamaged(f"segments listed in the manifest are missing: {', '.join(sorted(missing))}")
    if not entries:
        raise InputError(f"{d} holds no file to upload")
    return name, entries


class Uploader:
    """Uploads flight folders to one ground API with a bearer token."""

    def __init__(self, base_url: str, token: str, options: UploaderOptions | None = None,
                 client: httpx.Client | None = None, sleep: Callable[[float], None] = time.sleep,
                 before_chunk: Callable[[], None] | None = None,
                 on_chunk: Callable[[int], None] | None = None) -> None:
        """`before_chunk()` is called before every chunk is sent (it may raise to stop the upload there: the
        next run resumes from the server's offset); `on_chunk(n_bytes)` after every chunk the server took."""
        self.before_chunk = before_chunk
        self.on_chunk = on_chunk
        self.options = options or UploaderOptions()
        self.client = client or httpx.Client(base_url=base_url, timeout=self.options.timeout_s)
        self.headers = {"Authorization": f"Bearer {token}"}
        self.sleep = sleep
        self.chunk_bytes = self.options.chunk_bytes  # halved when the server says a chunk is over its limit

    def close(self) -> None:
        """Close the HTTP client."""
        self.client.close()

    def _request(self, report: UploadReport, method: str, url: str, **kw: Any) -> httpx.Response:
        """One request with retries on transport errors and 5xx; other statuses are returned to the caller."""
        delay = self.options.backoff_initial_s
        headers = {**self.headers, **kw.pop("headers", {})}
        for attempt in range(self.options.max_retries + 1):
            try:
                r = self.client.request(method, url, headers=headers, **kw)
                if r.status_code < 500:
                    return r
                err = f"HTTP {r.status_code}: {r.text[:200]}"
            except httpx.TransportError as exc:
                err = f"{type(exc).__name__}: {exc}"
            if attempt == self.options.max_retries:
                raise UploadError(f"{method} {url} failed after {attempt + 1} attempts: {err}")
            report.retries += 1
            log.warning("%s %s: %s; retry in %.1f s", method, url, err, delay)
            self.sleep(delay)
            delay = min(delay * 2, self.options.backoff_max_s)
        raise AssertionError("unreachable")

    def upload_flight(self, flight_dir: str | Path, roles: dict[str, str] | None = None) -> UploadReport:
        """Upload (or resume uploading) a flight folder; returns when the server holds every file verified."""
        d = Path(flight_dir)
        name, entries = build_upload_manifest(d, roles)
        report = UploadReport(flight_id="")
        r = self._request(report, "POST", "/flights", json={"name": name, "files": [e.to_json() for e in entries]})
        if r.status_code not in (200, 201):
            raise UploadError(f"server refused flight {name}: HTTP {r.status_code} {r.text[:300]}")
        flight = r.json()
        report.flight_id = flight["id"]
        state = {f["name"]: f for f in flight["files"]}
        for e in entries:
            if state.get(e.name, {}).get("status") == "complete":
                report.files[e.name] = "complete"
                continue
            self._upload_file(report, d / e.name, e)
        self._verify(report, entries)
        report.sha256 = {e.name: e.sha256 for e in entries}
        return report

    def add_files(self, flight_id: str, files: dict[str, Path], roles: dict[str, str] | None = None) -> UploadReport:
        """Add files to a flight the server already holds (`POST /flights/{id}/files` with their entries, e.g.
        the office's orientations and GCP for a drone's flight), then send them like a flight's (resumable,
        SHA-256 per chunk and per file); `files` maps the name on the server to the local file. Raises
        UploadError (HTTP 404/405 in its text when the server has no such flight or route)."""
        entries = [FileEntry(name, p.stat().st_size, sha256_file(p), (roles or {}).get(name))
                   for name, p in sorted(files.items())]
        report = UploadReport(flight_id=flight_id)
        r = self._request(report, "POST", f"/flights/{flight_id}/files",
                          json={"files": [e.to_json() for e in entries]})
        if r.status_code not in (200, 201):
            raise UploadError(f"server refused the files for flight {flight_id}: HTTP {r.status_code} {r.text[:300]}")
        state = {f["name"]: f for f in r.json().get("files", [])}
        for e in entries:
            if state.get(e.name, {}).get("status") == "complete":
                report.files[e.name] = "complete"
                continue
            self._upload_file(report, files[e.name], e)
        self._verify(report, entries)
        report.sha256 = {e.name: e.sha256 for e in entries}
        return report

    def _verify(self, report: UploadReport, entries: list[FileEntry]) -> None:
        """Ask the server for the flight once more: every file complete with our size and SHA-256."""
        r = self._request(report, "GET", f"/flights/{report.flight_id}")
        if r.status_code != 200:
            raise UploadError(f"cannot verify flight {report.flight_id}: HTTP {r.status_code}")
        held = {f["name"]: f for f in r.json()["files"]}
        for e in entries:
            f = held.get(e.name)
            if f is None or f["status"] != "complete" or f["size"] != e.size or f["sha256"] != e.sha256:
                raise UploadError(f"server does not hold {e.name} complete and verified: {f}")

    def _offset(self, report: UploadReport, url: str) -> int:
        r = self._request(report, "HEAD", url)
        if r.status_code != 200:
            raise UploadError(f"HEAD {url}: HTTP {r.status_code}")
        return int(r.headers[OFFSET_HEADER])

    def _upload_file(self, report: UploadReport, path: Path, entry: FileEntry) -> None:
        url = f"/flights/{report.flight_id}/files/{quote(entry.name, safe='')}"
        offset = self._offset(report, url)
        rejected = 0
        with open(path, "rb") as fh:
            while True:
                if offset >= entry.size and entry.size > 0:
                    break
                if self.before_chunk is not None:
                    self.before_chunk()
                fh.seek(offset)
                chunk = fh.read(self.chunk_bytes)
                r = self._request(report, "PUT", url, params={"offset": offset}, content=chunk,
                                  headers={CHUNK_SHA_HEADER: hashlib.sha256(chunk).hexdigest(),
                                           "Content-Type": "application/octet-stream"})
                if r.status_code == 200:
                    body = r.json()
                    report.bytes_sent += len(chunk)
                    report.chunks_sent += 1
                    if self.on_chunk is not None:
                        self.on_chunk(len(chunk))
                    offset = int(body["received"])
                    if body["status"] == "complete":
                        break
                    continue
                if r.status_code == 409 and "already complete" in r.text:
                    break
                if r.status_code == 413 and "limit" in r.text and len(chunk) > 1024:
                    self.chunk_bytes = max(1024, len(chunk) // 2)
                    log.info("server refused a %d-byte chunk; using %d-byte chunks", len(chunk), self.chunk_bytes)
                    continue
                if r.status_code in (409, 422) and rejected < self.options.max_retries:
                    # offset moved (another run) or the chunk arrived damaged / whole file restarted: ask again
                    rejected += 1
                    report.retries += 1
                    log.warning("%s at offset %d: HTTP %d %s; re-reading the server offset", entry.name, offset,
                                r.status_code, r.text[:200])
                    offset = self._offset(report, url)
                    continue
                raise UploadError(f"{entry.name}: HTTP {r.status_code} {r.text[:300]}")
        report.files[entry.name] = "complete"
        log.info("%s uploaded (%d bytes)", entry.name, entry.size)


CHUNK_MIB_MIN = 0.01
"""Smallest chunk (MiB, ~10 KiB): each chunk costs a request and a SHA-256 round trip."""
CHUNK_MIB_MAX = 1024.0
"""Largest chunk (MiB): held in memory twice (read + request body) on a Pi with 1–8 GiB."""


def ground_url(text: str, *, name: str | None = None) -> str:
    """The ground API's base URL: http:// or https:// with a host (ValueError in onboard.validate's words)."""
    label = f"{name} {text}" if name else text
    try:
        url = httpx.URL(text)
    except (httpx.InvalidURL, TypeError, ValueError):
        raise ValueError(f"{label}: must be an http:// or https:// URL") from None
    if url.scheme not in ("http", "https") or not url.host:
        raise ValueError(f"{label}: must be an http:// or https:// URL with a host, e.g. http://ground:8600")
    return text


def file_role(text: str, *, name: str | None = None) -> tuple[str, str]:
    """NAME=ROLE of `--role` (both non-empty)."""
    file_name, sep, role = text.partition("=")
    if not sep or not file_name.strip() or not role.strip():
        raise ValueError(f"{f'{name} ' if name else ''}{text}: must be NAME=ROLE, e.g. poses.csv=orientations")
    return file_name.strip(), role.strip()


def read_token(token_file: Path | None) -> str:
    """The API token from `token_file`, else $DIRECTGEO_TOKEN; ValueError when unreadable or empty."""
    if token_file is None:
        token = os.environ.get("DIRECTGEO_TOKEN", "")
        if not token.strip():
            raise ValueError("no token: give --token-file or set $DIRECTGEO_TOKEN")
        return token.strip()
    try:
        token = token_file.read_text(encoding="utf-8").strip()
    except (OSError, UnicodeDecodeError) as exc:
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise ValueError(f"--token-file {token_file}: cannot read it: {why}") from None
    if not token:
        raise ValueError(f"--token-file {token_file}: is empty")
    return token


def main(argv: list[str] | None = None) -> int:
    """`python -m onboard.upload`: upload one or more flight folders; exit 0 when all are complete, 1 when one
    could not be, 2 on a usage error."""
    from onboard.cmdline import EXIT_FAILURE, EXIT_USAGE, CommandParser, error_line, report_error
    from onboard.validate import arg_type, number

    p = CommandParser(
        prog="python -m onboard.upload", command="upload",
        description="Upload recorded flight folders to the ground app: resumable (a second run sends only what "
                    "the server lacks), every chunk and every file checked by SHA-256.",
        epilog="example: python -m onboard.upload --url http://ground:8600 --token-file /etc/directgeo/token "
               "/var/lib/directgeo/flight-20260501T101500Z")
    p.add_argument("--url", required=True, type=arg_type(ground_url), help="ground API base URL, e.g. http://ground:8600")
    p.add_argument("--token-file", type=Path, help="file holding the API token, the drone's own drone token "
                   "(`python -m ground token create --role drone` on the ground) (else $DIRECTGEO_TOKEN)")
    p.add_argument("--chunk-mib", type=arg_type(number, unit=" MiB", minimum=CHUNK_MIB_MIN, maximum=CHUNK_MIB_MAX),
                   default=4.0, metavar="MIB",
                   help=f"chunk size in MiB, {CHUNK_MIB_MIN:g}–{CHUNK_MIB_MAX:g} (default %(default)s; halved "
                        "while the server says a chunk is over its limit)")
    p.add_argument("--role", action="append", default=[], type=arg_type(file_role), metavar="NAME=ROLE",
                   help="role of a file, e.g. poses.csv=orientations (repeatable)")
    p.add_argument("flights", nargs="+", type=Path, help="flight folders (flight-YYYYmmddTHHMMSSZ)")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        token = read_token(args.token_file)
    except ValueError as exc:
        return report_error("upload", str(exc), EXIT_USAGE)
    roles = dict(args.role)
    up = Uploader(args.url, token, UploaderOptions(chunk_bytes=max(1024, int(args.chunk_mib * 1024 * 1024))))
    rc = 0
    try:
        for d in args.flights:
            try:
                rep = up.upload_flight(d, roles)
                print(f"{d}: flight {rep.flight_id} complete, {rep.bytes_sent} bytes sent, {rep.retries} retries")
            except (UploadError, InputError, OSError) as exc:
                print(error_line("upload", f"{d}: {exc}"), file=sys.stderr)
                rc = EXIT_FAILURE
    finally:
        up.close()
    return rc


if __name__ == "__main__":
    sys.exit(main())
