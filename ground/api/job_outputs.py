"""A job's output folder: where it lives, its listing, and its transfer from a worker as one tar archive.

A worker runs a job in its own scratch folder and posts the whole folder as one uncompressed tar; the server
unpacks it beside the final folder and renames it into place, so a reader sees either no outputs or all of
them (never a half-posted set), and a retried job that posts the same archive again leaves the same bytes.
The archive is packed deterministically (sorted names, zero times and owners), so equal folders give equal
archives and equal SHA-256.
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import tarfile
import uuid
from dataclasses import dataclass
from pathlib import Path

from onboard.errors import InputError
from onboard.formats.digest import sha256_file

OUTPUTS_DIR = "outputs"


@dataclass(frozen=True)
class OutputFile:
    """One output file: path relative to the job's folder (`/`-separated), size (bytes), SHA-256 (hex)."""

    name: str
    size: int
    sha256: str


def job_output_dir(data_dir: Path, flight_id: str, job_id: str) -> Path:
    """The server's output folder of a job: `<data_dir>/outputs/<flight>/<job>/`."""
    return data_dir / OUTPUTS_DIR / flight_id / job_id


def list_outputs(folder: Path) -> list[OutputFile]:
    """Every regular file under `folder` (sorted by relative name); empty when the folder is absent."""
    if not folder.is_dir():
        return []
    return [OutputFile(p.relative_to(folder).as_posix(), p.stat().st_size, sha256_file(p))
            for p in sorted(folder.rglob("*")) if p.is_file() and not p.is_symlink()]


def pack_outputs(folder: Path) -> bytes:
    """The folder's regular files as an uncompressed tar, deterministic (sorted, mtime/uid/gid 0, mode 0644)."""
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w", format=tarfile.PAX_FORMAT) as tar:
        for out in list_outputs(folder):
            info = tarfile.TarInfo(out.name)
            info.size, info.mtime, info.mode = out.size, 0, 0o644
            with open(folder / out.name, "rb") as fh:
                tar.addfile(info, fh)
    return buf.getvalue()


def staging_path(dest: Path, what: str) -> Path:
    """A hidden, unique name beside `dest` (never listed as a job folder: job ids do not start with a dot)."""
    return dest.with_name(f".{what}-{dest.name}-{uuid.uuid4().hex[:12]}")


def install_outputs(archive: Path, dest: Path) -> list[OutputFile]:
    """Unpack a worker's tar file beside `dest` and rename it over `dest` (the previous folder, if any, is removed
    after the swap). Only regular files with relative names stay inside; anything else is an InputError and
    `dest` is left as it was."""
    dest.parent.mkdir(parents=True, exist_ok=True)
    staging = staging_path(dest, "incoming")
    staging.mkdir()
    try:
        try:
            with tarfile.open(archive, mode="r:") as tar:
                members = tar.getmembers()
                bad = [m.name for m in members if not (m.isfile() or m.isdir())]
                if bad:
                    raise InputError(f"outputs archive: not a regular file: {', '.join(bad[:5])}")
                bad = [m.name for m in members if m.name.startswith("/") or any(
                    part in ("", "..") or part.startswith(".") for part in m.name.rstrip("/").split("/"))]
                if bad:
                    raise InputError(f"outputs archive: names outside the job's folder: {', '.join(bad[:5])}")
                # the "data" filter refuses absolute names, `..`, links out of the folder and device files
                tar.extractall(staging, members=members, filter="data")
        except (tarfile.TarError, EOFError) as exc:  # FilterError (a refused member) is a TarError
            raise InputError(f"outputs archive refused: {exc}") from None
        for p in staging.rglob("*"):
            if p.is_file():
                with open(p, "rb") as fh:
                    os.fsync(fh.fileno())
        listing = list_outputs(staging)
        old = staging_path(dest, "old")
        if dest.exists():
            os.replace(dest, old)
        os.replace(staging, dest)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    with contextlib.suppress(OSError):
        shutil.rmtree(old)
    return listing
