"""Journal durability, rotation, manifest and recovery, with a file layer that models power loss."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from onboard.hw.fake import ManualClock
from onboard.logger.events import EventLog, read_events
from onboard.logger.files import RecordingFileLayer
from onboard.logger.journal import (
    INDEX_RECORD,
    Journal,
    JournalOptions,
    flight_name,
    iter_journal_bytes,
    iter_journal_frames,
    list_segments,
    locate_offset,
    read_index,
    read_manifest,
    write_atomic,
)
from onboard.receiver.framing import ubx_frame


def numbered_frame(n: int) -> bytes:
    """A UBX frame (RXM-RAW class/id, dummy body) carrying its sequence number in the first 4 bytes."""
    return ubx_frame(0x02, 0x10, n.to_bytes(4, "little") + bytes(20))


def frame_numbers(flight: Path) -> list[int]:
    return [int.from_bytes(f.payload[:4], "little") for f in iter_journal_frames(flight)]


def test_bytes_index_and_manifest_roundtrip(tmp_path: Path) -> None:
    clock = ManualClock()
    j = Journal(tmp_path / "f", clock, JournalOptions(segment_max_bytes=1000, segment_max_s=0))
    sent = b""
    for n in range(100):
        data = numbered_frame(n)
        j.append(data, clock.monotonic_ns(), clock.wall_ns())
        sent += data
        clock.advance_s(0.01)
        j.maybe_sync()
    j.close("test done")
    assert b"".join(iter_journal_bytes(tmp_path / "f")) == sent
    assert frame_numbers(tmp_path / "f") == list(range(100))
    segs = list_segments(tmp_path / "f")
    assert len(segs) >= 3 and [p.name for p in segs] == sorted(p.name for p in segs)
    assert all(p.stat().st_size <= 1000 + len(numbered_frame(0)) for p in segs)
    m = read_manifest(tmp_path / "f")
    assert m is not None and m.closed and m.close_reason == "test done"
    assert [s.name for s in m.segments] == [p.name for p in segs]
    for s, p in zip(m.segments, segs):
        assert s.bytes == p.stat().st_size
        assert s.sha256 == hashlib.sha256(p.read_bytes()).hexdigest()
        assert not s.recovered
    # the index maps every append's offset to its host times
    recs = read_index(segs[0].with_suffix(".idx"))
    assert recs[0].offset == 0 and recs[1].offset == len(numbered_frame(0))
    assert recs[1].monotonic_ns - recs[0].monotonic_ns == 10_000_000
    assert recs[0].wall_ns - recs[0].monotonic_ns == clock.wall_ns() - clock.monotonic_ns()
    assert locate_offset(recs, len(numbered_frame(0)) + 3) == recs[1]


def test_rotation_by_time(tmp_path: Path) -> None:
    clock = ManualClock()
    j = Journal(tmp_path / "f", clock, JournalOptions(segment_max_bytes=0, segment_max_s=10))
    for n in range(30):
        j.append(numbered_frame(n), clock.monotonic_ns(), clock.wall_ns())
        clock.advance_s(1.0)
    j.close()
    assert len(list_segments(tmp_path / "f")) == 3
    assert frame_numbers(tmp_path / "f") == list(range(30))


def test_sync_policy_interval_and_sync_now(tmp_path: Path) -> None:
    clock = ManualClock()
    files = RecordingFileLayer()
    j = Journal(tmp_path / "f", clock, JournalOptions(sync_interval_s=0.5), files=files)
    seg = j.current_segment
    assert seg is not None
    j.append(b"a" * 10, clock.monotonic_ns(), clock.wall_ns())
    clock.advance_s(0.3)
    assert not j.maybe_sync()  # too early: nothing synced yet
    assert files.synced_bytes.get(seg, 0) == 0
    clock.advance_s(0.3)
    assert j.maybe_sync()
    assert files.synced_bytes[seg] == 10
    assert files.synced_bytes[seg.with_suffix(".idx")] == INDEX_RECORD.size
    j.append(b"b" * 5, clock.monotonic_ns(), clock.wall_ns())
    j.sync_now()  # a time mark: synced immediately, whatever the interval
    assert files.synced_bytes[seg] == 15
    assert not j.maybe_sync()  # nothing dirty


def test_power_cut_keeps_synced_data_and_recovery_lists_torn_segment(tmp_path: Path) -> None:
    """Cut every file back to its last fsync: data older than the sync interval survives, the rest may not;
    a restart starts a new segment and the manifest lists the torn one with its true size and hash."""
    clock = ManualClock()
    files = RecordingFileLayer()
    flight = tmp_path / "f"
    j = Journal(flight, clock, JournalOptions(sync_interval_s=0.5), files=files)
    for n in range(50):
        j.append(numbered_frame(n), clock.monotonic_ns(), clock.wall_ns())
        clock.advance_s(0.1)
        j.maybe_sync()
    # half a frame arrives, then power fails (no close)
    j.append(numbered_frame(50)[:10], clock.monotonic_ns(), clock.wall_ns())
    cut_mono = clock.monotonic_ns()
    files.cut_to_sync_points()
    survived = frame_numbers(flight)
    # everything received more than sync_interval before the cut survives, in order
    recs = read_index(list_segments(flight)[0].with_suffix(".idx"))
    assert survived == list(range(len(survived)))
    assert len(survived) >= 50 - 6
    assert all(r.monotonic_ns < cut_mono for r in recs)

    clock.advance_s(5)
    j2 = Journal(flight, clock, JournalOptions(sync_interval_s=0.5), files=files)
    assert j2.current_segment is not None and j2.current_segment.name == "000001.ubx"
    m = read_manifest(flight)
    assert m is not None and m.restarts == 1 and not m.closed
    torn = m.segments[0]
    assert torn.name == "000000.ubx" and torn.recovered
    assert torn.bytes == (flight / "000000.ubx").stat().st_size
    assert torn.sha256 == hashlib.sha256((flight / "000000.ubx").read_bytes()).hexdigest()
    for n in range(51, 60):
        j2.append(numbered_frame(n), clock.monotonic_ns(), clock.wall_ns())
    j2.close()
    assert frame_numbers(flight) == survived + list(range(51, 60))
    m = read_manifest(flight)
    assert m is not None and m.closed and [s.name for s in m.segments] == ["000000.ubx", "000001.ubx"]


def test_readers_accept_torn_index_and_segment(tmp_path: Path) -> None:
    clock = ManualClock()
    j = Journal(tmp_path / "f", clock)
    for n in range(5):
        j.append(numbered_frame(n), clock.monotonic_ns(), clock.wall_ns())
    j.close()
    seg = list_segments(tmp_path / "f")[0]
    idx = seg.with_suffix(".idx")
    idx.write_bytes(idx.read_bytes()[:-7])  # torn last record
    seg.write_bytes(seg.read_bytes()[:-5])  # torn last frame
    assert len(read_index(idx)) == 4
    assert frame_numbers(tmp_path / "f") == [0, 1, 2, 3]
    # and with junk between frames the reader resynchronises
    seg.write_bytes(numbered_frame(7) + b"\xb5\x62\x02\x10\xff\xff garbage" + numbered_frame(8))
    assert frame_numbers(tmp_path / "f") == [7, 8]


def test_atomic_manifest_survives_cut_during_rewrite(tmp_path: Path) -> None:
    files = RecordingFileLayer()
    target = tmp_path / "manifest.json"
    write_atomic(files, target, b'{"v": 1}\n')
    # a second write whose temp file is created and partly written but never fsynced/renamed
    tmp = target.with_name("manifest.json.tmp")
    h = files.create(tmp)
    h.append(b'{"v": 2, "partial')
    files.cut_to_sync_points()
    assert json.loads(target.read_bytes()) == {"v": 1}
    assert tmp.read_bytes() == b""


def test_manifest_unreadable_is_rebuilt_from_segments(tmp_path: Path) -> None:
    clock = ManualClock()
    flight = tmp_path / "f"
    j = Journal(flight, clock)
    j.append(b"abc", clock.monotonic_ns(), clock.wall_ns())
    j.close()
    (flight / "manifest.json").write_bytes(b'{"format": "directgeo-fl')  # corrupt
    j2 = Journal(flight, clock)
    j2.close()
    m = read_manifest(flight)
    assert m is not None and [s.name for s in m.segments] == ["000000.ubx", "000001.ubx"]
    assert m.segments[0].bytes == 3 and m.segments[0].recovered


def test_append_after_close_is_an_error(tmp_path: Path) -> None:
    clock = ManualClock()
    j = Journal(tmp_path / "f", clock)
    j.close()
    with pytest.raises(ValueError):
        j.append(b"x", 0, 0)


def test_flight_name_sorts_by_time() -> None:
    assert flight_name(1_700_000_000 * 10**9) == "flight-20231114T221320Z"
    assert flight_name(1_700_000_001 * 10**9) > flight_name(1_700_000_000 * 10**9)


def test_event_log_torn_line_is_skipped_and_next_record_intact(tmp_path: Path) -> None:
    clock = ManualClock()
    files = RecordingFileLayer()
    path = tmp_path / "events.jsonl"
    ev = EventLog(path, clock, 0.5, files)
    ev.append({"type": "mark", "count": 1})
    ev.sync_now()
    ev.append({"type": "mark", "count": 2})
    files.cut_to_sync_points()
    with open(path, "ab") as f:  # model a torn write that did reach the disk
        f.write(b'{"type":"mark","cou')
    ev2 = EventLog(path, clock, 0.5, files)
    ev2.append({"type": "mark", "count": 3})
    ev2.close()
    got = read_events(path)
    assert [r["count"] for r in got.records] == [1, 3]
    assert got.skipped_lines == 1
    assert read_events(tmp_path / "absent.jsonl").records == []
