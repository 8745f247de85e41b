"""The flight's tlog: pymavlink's record format, fsync policy on the monotonic clock, a new file per run."""

from __future__ import annotations

import struct
from pathlib import Path

from onboard.autopilot.tlog import TlogWriter, next_tlog_path, tlog_record
from onboard.hw.fake import ManualClock
from onboard.logger.files import RecordingFileLayer


def test_record_is_big_endian_microseconds_then_the_packet() -> None:
    assert tlog_record(0x0102030405060708, b"\xfd\x09") == bytes(range(1, 9)) + b"\xfd\x09"


def test_fsync_every_interval_on_the_monotonic_clock(tmp_path: Path) -> None:
    clock = ManualClock()
    files = RecordingFileLayer()
    w = TlogWriter(tmp_path / "autopilot.tlog", clock, 0.5, files)
    w.append(b"abc", wall_ns=1_700_000_000_123_456_789)
    w.maybe_sync()
    assert files.synced_bytes.get(w.path, 0) == 0  # not yet due
    clock.step_wall_s(-3600)  # the wall clock stepping back (NTP on a Pi without RTC) changes nothing
    clock.advance_s(0.5)
    w.maybe_sync()
    assert files.synced_bytes[w.path] == 11
    w.append(b"de", wall_ns=1_700_000_001_000_000_000)
    w.close()
    assert files.synced_bytes[w.path] == 21  # closing syncs
    data = w.path.read_bytes()
    assert struct.unpack(">Q", data[:8])[0] == 1_700_000_000_123_456 and data[8:11] == b"abc"


def test_a_resumed_flight_gets_a_new_tlog(tmp_path: Path) -> None:
    assert next_tlog_path(tmp_path).name == "autopilot.tlog"
    (tmp_path / "autopilot.tlog").write_bytes(b"torn")
    assert next_tlog_path(tmp_path).name == "autopilot-2.tlog"
    (tmp_path / "autopilot-2.tlog").write_bytes(b"")
    assert next_tlog_path(tmp_path).name == "autopilot-3.tlog"
