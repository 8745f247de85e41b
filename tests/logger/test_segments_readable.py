"""Journal segments are plain receiver byte streams that other tools read directly: a real RXM-RAW capture
recorded through the Journal (random read sizes, size rotation) is read back by RTKLIB's own UBX decoder
(pyrtklib `input_ubx`, what convbin runs) over the segments in name order, and by pyubx2 segment by segment."""

from __future__ import annotations

import random
from pathlib import Path

import pytest

from onboard.hw.fake import ManualClock
from onboard.logger.journal import Journal, JournalOptions, iter_journal_bytes, list_segments
from tests.conftest import shared_file

CAPTURE = "ubx/rtklib_ubx_20080526.ubx"  # LEA-4T RXM-RAW, 242 epochs, truncated last frame


def _record(tmp_path: Path, data: bytes) -> Path:
    """Record `data` as the daemon would: reads of 1–700 bytes, 20 ms apart, segments of ≤ 40 kB."""
    rng = random.Random(7)
    clock = ManualClock()
    flight = tmp_path / "flight-20080526T000000Z"
    journal = Journal(flight, clock, JournalOptions(segment_max_bytes=40_000, segment_max_s=0))
    pos = 0
    while pos < len(data):
        n = rng.randint(1, 700)
        journal.append(data[pos : pos + n], clock.monotonic_ns(), clock.wall_ns())
        pos += n
        clock.advance_s(0.02)
        journal.maybe_sync()
    journal.close("test")
    return flight


def _rtklib_epochs(chunks: list[bytes]) -> list[tuple[float, int]]:
    """(receiver time s, satellites) of every observation epoch RTKLIB's UBX decoder finds in the byte stream."""
    rtk = pytest.importorskip("pyrtklib", reason="pyrtklib (RTKLIB bindings, bench extra) is not installed")
    raw = rtk.raw_t()
    assert rtk.init_raw(raw, rtk.STRFMT_UBX) == 1
    epochs = []
    try:
        for chunk in chunks:
            for byte in chunk:
                if rtk.input_ubx(raw, byte) == 1:
                    epochs.append((raw.time.time + raw.time.sec, raw.obs.n))
    finally:
        rtk.free_raw(raw)
    return epochs


def test_rtklib_reads_the_segments_like_the_original_capture(tmp_path: Path) -> None:
    data = shared_file(CAPTURE).read_bytes()
    flight = _record(tmp_path, data)
    segments = list_segments(flight)
    assert len(segments) >= 5 and all(p.suffix == ".ubx" for p in segments)
    assert b"".join(p.read_bytes() for p in segments) == data  # no header, no framing of our own
    assert b"".join(iter_journal_bytes(flight)) == data
    ours = _rtklib_epochs([p.read_bytes() for p in segments])  # `cat flight/*.ubx | convbin`
    ref = _rtklib_epochs([data])
    assert len(ref) == 242 and ours == ref


def test_pyubx2_reads_each_segment_on_its_own(tmp_path: Path) -> None:
    """Each segment alone is a UBX stream: pyubx2 parses it without error; only the frames cut by a segment
    boundary are missing when segments are read one by one."""
    from pyubx2 import UBX_PROTOCOL, UBXReader

    data = shared_file(CAPTURE).read_bytes()
    flight = _record(tmp_path, data)
    segments = list_segments(flight)
    raw_epochs = 0
    for seg in segments:
        with seg.open("rb") as stream:
            reader = UBXReader(stream, protfilter=UBX_PROTOCOL, quitonerror=0)
            names = [parsed.identity for _raw, parsed in reader]
        assert names, seg.name
        raw_epochs += names.count("RXM-RAW")
    assert 242 - (len(segments) - 1) <= raw_epochs <= 242
