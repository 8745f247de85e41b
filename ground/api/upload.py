"""Pure rules of the resumable upload: file-name validation, manifest checks, chunk acceptance."""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass

_NAME_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9._+\-]{0,199}$")
_SHA_RE = re.compile(r"^[0-9a-f]{64}$")
EMPTY_SHA256 = hashlib.sha256(b"").hexdigest()
"""The SHA-256 of zero bytes: the only hash a file of size 0 can have."""


class UploadRejected(ValueError):
    """A request breaks an upload rule; `status` is the HTTP status to answer with."""

    def __init__(self, status: int, detail: str) -> None:
        self.status = status
        self.detail = detail
        super().__init__(detail)


def check_file_name(name: str) -> str:
    """A single path component of safe characters (a flight's name, an export's), or `UploadRejected(400)`.

    Refused: empty, `/` or `\\`, NUL or control characters, `.`/`..`, a leading dot (hidden, `..x`),
    absolute or drive paths, more than 200 characters.
    """
    if not name or "\x00" in name or "/" in name or "\\" in name or ":" in name:
        raise UploadRejected(400, f"invalid file name {name!r}: one path component without / \\ : or NUL")
    if name in (".", "..") or not _NAME_RE.match(name):
        raise UploadRejected(400, f"invalid file name {name!r}: letters, digits, . _ + - only, no leading dot")
    return name


MAX_PATH_DEPTH = 4
"""Most components of a flight file's path (`radio/000000.ubx` has 2)."""
MAX_PATH_CHARS = 255


def check_file_path(name: str) -> str:
    """A flight file's name: a relative path of at most `MAX_PATH_DEPTH` components separated by `/` (a
    sub-journal such as `radio/000000.ubx`), each one a `check_file_name` component; or `UploadRejected(400)`.

    Refused besides a bad component: an empty component (`a//b`, a leading or trailing `/`), so no absolute path,
    and `.`/`..` or hidden components, so nothing can climb out of the flight directory or reach `.partial`.
    """
    if not name or len(name) > MAX_PATH_CHARS:
        raise UploadRejected(400, f"invalid file name {name!r}: 1 to {MAX_PATH_CHARS} characters")
    parts = name.split("/")
    if len(parts) > MAX_PATH_DEPTH:
        raise UploadRejected(400, f"invalid file name {name!r}: more than {MAX_PATH_DEPTH} path components")
    for part in parts:
        try:
            check_file_name(part)
        except UploadRejected:
            raise UploadRejected(400, f"invalid file name {name!r}: component {part!r} is not letters, digits, "
                                      ". _ + - (no leading dot, no empty component, no \\ : or NUL)") from None
    return name


def check_name_layout(names: list[str]) -> None:
    """Names of one flight that can all exist at once: none is also a folder of another (`radio` and
    `radio/000000.ubx`), else `UploadRejected(400)`."""
    folders = {"/".join(n.split("/")[:k]) for n in names for k in range(1, n.count("/") + 1)}
    clash = sorted(folders.intersection(names))
    if clash:
        raise UploadRejected(400, f"file {clash[0]!r} is also the folder of other files of this flight")


def check_sha256(value: str) -> str:
    """A lower-case hex SHA-256 digest or `UploadRejected(400)`."""
    v = value.strip().lower()
    if not _SHA_RE.match(v):
        raise UploadRejected(400, f"invalid SHA-256 {value!r}: 64 hex digits expected")
    return v


@dataclass(frozen=True)
class Limits:
    """Size limits in bytes."""

    max_file_bytes: int
    max_flight_bytes: int
    max_chunk_bytes: int
    max_files_per_flight: int


def check_manifest_files(files: list[tuple[str, int, str]], limits: Limits) -> None:
    """Validate (name, size, sha256) triples of a new flight: names, duplicates, sizes; raise `UploadRejected`."""
    if not files:
        raise UploadRejected(400, "the manifest lists no file")
    if len(files) > limits.max_files_per_flight:
        raise UploadRejected(413, f"{len(files)} files > limit {limits.max_files_per_flight}")
    seen: set[str] = set()
    total = 0
    for name, size, sha in files:
        check_file_path(name)
        check_sha256(sha)
        if name in seen:
            raise UploadRejected(400, f"file {name!r} listed twice")
        seen.add(name)
        if size < 0:
            raise UploadRejected(400, f"file {name!r}: negative size")
        if size == 0 and sha.strip().lower() != EMPTY_SHA256:
            raise UploadRejected(422, f"file {name!r}: size 0 with SHA-256 {sha.strip().lower()[:16]}…, which is not "
                                      f"the hash of an empty file ({EMPTY_SHA256[:16]}…): it could never complete")
        if size > limits.max_file_bytes:
            raise UploadRejected(413, f"file {name!r}: {size} bytes > limit {limits.max_file_bytes}")
        total += size
    if total > limits.max_flight_bytes:
        raise UploadRejected(413, f"flight of {total} bytes > limit {limits.max_flight_bytes}")
    check_name_layout([name for name, _, _ in files])


def check_chunk(offset: int, received: int, chunk_len: int, size: int, limits: Limits) -> None:
    """Accept a chunk at `offset` of a file with `received` bytes of `size`, or raise `UploadRejected`.

    409 when the offset is not where the file ends (the client resumes from `received`), 413 for a chunk over
    the limit or one that would run past the promised size.
    """
    if chunk_len > limits.max_chunk_bytes:
        raise UploadRejected(413, f"chunk of {chunk_len} bytes > limit {limits.max_chunk_bytes}")
    if offset != received:
        raise UploadRejected(409, f"offset {offset} != received {received}: resume from {received}")
    if offset + chunk_len > size:
        raise UploadRejected(413, f"chunk ends at {offset + chunk_len}, past the promised size {size}")
