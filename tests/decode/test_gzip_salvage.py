"""`iter_file_bytes` on gzip logs: members in sequence, a cut or damaged file salvaged up to the damage."""

from __future__ import annotations

import gzip
import random
from pathlib import Path

import pytest

from onboard.errors import InputError
from onboard.receiver.decode import iter_file_bytes


def _payload(n: int, seed: int = 1) -> bytes:
    rng = random.Random(seed)
    return bytes(rng.getrandbits(8) if rng.random() < 0.3 else 0x55 for _ in range(n))


def _read(path: Path) -> tuple[bytes, list[str]]:
    warnings: list[str] = []
    data = b"".join(iter_file_bytes(path, warn=warnings.append))
    return data, warnings


def test_several_members_and_zero_padding_read_whole(tmp_path: Path) -> None:
    a, b = _payload(100_000, 1), _payload(70_000, 2)
    path = tmp_path / "two.gz"
    path.write_bytes(gzip.compress(a) + gzip.compress(b) + bytes(512))
    assert _read(path) == (a + b, [])


def test_cut_file_keeps_what_decompressed(tmp_path: Path) -> None:
    data = _payload(300_000)
    blob = gzip.compress(data)
    path = tmp_path / "cut.gz"
    path.write_bytes(blob[: len(blob) // 2])
    got, warnings = _read(path)
    assert 0.4 * len(data) < len(got) < 0.6 * len(data) and data.startswith(got)
    assert warnings == [(f"{path}: gzip data is cut short at compressed byte {len(blob) // 2}: kept the "
                         f"{len(got)} bytes decompressed before the end")]


def test_damaged_block_is_salvaged_up_to_where_deflate_notices(tmp_path: Path) -> None:
    data = _payload(300_000)
    blob = bytearray(gzip.compress(data))
    at = len(blob) // 3
    blob[at : at + 40] = bytes(40)  # a run of zeros: an invalid block a little after `at`
    path = tmp_path / "bad.gz"
    path.write_bytes(bytes(blob))
    got, warnings = _read(path)
    assert len(warnings) == 1 and "gzip data is corrupt" in warnings[0]
    noticed = int(warnings[0].split("noticed at compressed byte ")[1].split(":")[0])
    assert noticed >= at
    good = next(i for i in range(len(got)) if got[i] != data[i]) if got != data[: len(got)] else len(got)
    assert good >= 0.25 * len(data)  # everything before the damage came back intact


def test_nothing_decompressing_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "junk.gz"
    path.write_bytes(b"\x1f\x8b\x08\x00" + bytes(range(256)) * 4)
    with pytest.raises(InputError, match="gzip data is corrupt from compressed byte"):
        _read(path)
