"""`convert` against RTKLIB's conversion of the same logs, complete conversion of a truncated log, clear errors."""

from __future__ import annotations

import gzip
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from onboard.formats.rinex_nav import read_rinex_nav
from onboard.formats.rinex_obs import read_rinex_obs
from onboard.gnsstime import GpsTime
from onboard.postpro.convert import convert_main, convert_one
from tests.conftest import PROJECT_ROOT, shared_file

M8P = "gnss/ublox-m8p-galway-2018"


def _body(path: Path) -> list[str]:
    text = gzip.decompress(path.read_bytes()).decode() if path.suffix == ".gz" else path.read_text()
    return text.split("END OF HEADER", 1)[1].splitlines()[1:]


@pytest.fixture(scope="module")
def m8p_converted(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("m8p")
    convert_one(shared_file(f"{M8P}/raw/rover-20181004-1237.ubx.gz"), out)
    return out


@pytest.mark.slow
def test_m8p_gps_observations_equal_rtklib(m8p_converted: Path) -> None:
    """Same epochs, satellites, values (to RINEX rounding) and LLI as RTKLIB convbin on the same log."""
    ours = read_rinex_obs(m8p_converted / "rover-20181004-1237.obs").epochs
    ref = read_rinex_obs(shared_file(f"{M8P}/rinex/rover-20181004-1237.obs.gz")).epochs
    assert len(ours) == len(ref) == 1205
    for a, b in zip(ours, ref):
        a, b = a.gps_only(), b.gps_only()
        assert a.time == b.time
        assert a.sv_id.tolist() == b.sv_id.tolist()
        for name in ("pr_m", "cp_cyc", "dop_hz", "cn0_dbhz"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=f"{name} at {a.time}")
        assert a.lli.tolist() == b.lli.tolist(), f"LLI at {a.time}"
    # RTKLIB's LLI here has slips and half-cycle flags: the comparison above covers both
    all_lli = np.concatenate([e.gps_only().lli for e in ref])
    assert (all_lli & 1).any() and (all_lli & 2).any()


@pytest.mark.slow
def test_m8p_observation_records_are_byte_identical_to_rtklib(m8p_converted: Path) -> None:
    """Every observation line (GPS and GLONASS) matches RTKLIB's text; only event records sit elsewhere."""
    ours = [line for line in _body(m8p_converted / "rover-20181004-1237.obs") if " 5  0" not in line[29:]]
    ref = [line for line in _body(shared_file(f"{M8P}/rinex/rover-20181004-1237.obs.gz")) if " 5  0" not in line[29:]]
    assert ours == ref


def test_m8p_event_records(m8p_converted: Path) -> None:
    """4 falling-edge marks, as RTKLIB; we place each before the first epoch at or after it (time order),
    RTKLIB before the epoch after the one the TIM-TM2 message followed (one epoch later)."""
    ours = [line for line in _body(m8p_converted / "rover-20181004-1237.obs") if line.startswith(">")]
    ref = [line for line in _body(shared_file(f"{M8P}/rinex/rover-20181004-1237.obs.gz")) if line.startswith(">")]
    events = [line for line in ours if line[31:35] == "5  0"]
    assert events == [line for line in ref if line[31:35] == "5  0"]
    assert events[0] == "> 2018 10 04 12 39 25.1415356  5  0"
    idx = ours.index(events[0])
    assert ours[idx - 1].startswith("> 2018 10 04 12 39 24.991") and ours[idx + 1].startswith("> 2018 10 04 12 39 25.991")


def test_m8p_header(m8p_converted: Path) -> None:
    text = (m8p_converted / "rover-20181004-1237.obs").read_text()
    header = text.split("END OF HEADER", 1)[0].splitlines()[:-1]
    assert all(len(line) == 80 for line in header)
    assert header[0] == "     3.04           OBSERVATION DATA    M: Mixed            RINEX VERSION / TYPE"
    assert "G    4 C1C L1C D1C S1C                                      SYS / # / OBS TYPES " in header
    assert "  2018    10    04    12    38   08.9910000     GPS         TIME OF FIRST OBS   " in header
    assert "     1.000                                                  INTERVAL            " in header
    ref = gzip.decompress(shared_file(f"{M8P}/rinex/rover-20181004-1237.obs.gz").read_bytes()).decode()
    glo = next(line for line in ref.splitlines() if "GLONASS SLOT" in line)
    assert glo in header  # FCNs from RXM-RAWX freqId, as RTKLIB
    pos = read_rinex_obs(m8p_converted / "rover-20181004-1237.obs").header.approx_pos_ecef_m
    assert np.linalg.norm(pos - np.array([3774088.9931, -601661.8217, 5089321.3853])) < 10.0


def test_m8p_navigation_equals_rtklib(m8p_converted: Path) -> None:
    ours = read_rinex_nav(m8p_converted / "rover-20181004-1237.nav")
    ref = read_rinex_nav(shared_file(f"{M8P}/rinex/rover-20181004-1237.nav.gz"))
    key = lambda e: (e.prn, e.toe, e.iode)
    assert sorted(map(key, ours.ephemerides)) == sorted(map(key, ref.ephemerides))
    assert len(ours.ephemerides) == 14 and ours.leap_s == 18
    refs = {key(e): e for e in ref.ephemerides}
    for e in ours.ephemerides:
        r = refs[key(e)]
        for name in ("sqrt_a", "e", "m0_rad", "omega0_rad", "af0_s", "af1_s_s", "tgd_s", "idot_rad_s", "crs_m"):
            assert getattr(e, name) == pytest.approx(getattr(r, name), rel=1e-11, abs=1e-22), name
        assert (e.toc, e.iodc, e.health, e.ura_index) == (r.toc, r.iodc, r.health, r.ura_index)


def test_rxm_raw_log_with_truncated_last_frame_converts_completely(tmp_path: Path) -> None:
    src = shared_file("ubx/rtklib_ubx_20080526.ubx")
    result = convert_one(src, tmp_path)
    assert result.obs.epochs == 242 and result.stats.by_message["RXM-RAW"] == 242
    obs = read_rinex_obs(result.obs_path)
    assert len(obs.epochs) == 242
    assert obs.epochs[0].time == GpsTime(1481, 107_964_999_000_000)
    assert obs.epochs[-1].time == GpsTime(1481, 108_205_999_000_000)
    assert set(result.obs.satellites) == {"G", "S"}  # SBAS PRN 129/137 as S29/S37
    assert result.ephemerides > 0 and result.nav_path.stat().st_size > 0


def test_journal_directory_converts_like_the_log(tmp_path: Path) -> None:
    """A flight journal split into segments mid-frame converts to the same observations as the whole log."""
    data = shared_file("ubx/gpsd_ublox-neo-m8t.log").read_bytes()
    flight = tmp_path / "flight-20180101T000000Z"
    flight.mkdir()
    cut = len(data) // 2 + 7
    (flight / "000001.ubx").write_bytes(data[:cut])
    (flight / "000002.ubx").write_bytes(data[cut:])
    whole = convert_one(shared_file("ubx/gpsd_ublox-neo-m8t.log"), tmp_path / "a")
    split = convert_one(flight, tmp_path / "b")
    assert split.obs_path.name == "flight-20180101T000000Z.obs"
    assert split.obs.epochs == whole.obs.epochs == 39
    assert _body(split.obs_path) == _body(whole.obs_path)


def test_cli_prints_what_it_wrote(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = convert_main([str(shared_file("ubx/gpsd_ublox-neo-m8t.log")), "-o", str(tmp_path), "--no-progress"])
    out = capsys.readouterr().out
    assert code == 0
    assert f"{tmp_path / 'gpsd_ublox-neo-m8t.obs'}: 39 epochs, 13 satellites (G 10, S 3), 0 time marks" in out
    assert f"{tmp_path / 'gpsd_ublox-neo-m8t.nav'}: 0 GPS ephemerides" in out
    assert (tmp_path / "gpsd_ublox-neo-m8t.obs").exists() and (tmp_path / "gpsd_ublox-neo-m8t.nav").exists()


# ----------------------------------------------------------------------------------------------- failure paths

@pytest.mark.slow
def test_truncated_gzip_is_salvaged_with_a_warning(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A gzip log cut short converts up to the cut; the warning names the compressed offset (was: refused)."""
    src = shared_file(f"{M8P}/raw/rover-20181004-1237.ubx.gz")
    blob = src.read_bytes()
    cut = tmp_path / "cut.ubx.gz"
    cut.write_bytes(blob[: len(blob) // 2])
    whole = convert_one(src, tmp_path / "whole")
    capsys.readouterr()
    code = convert_main([str(cut), "-o", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 0
    assert f"directgeo: convert: warning: {cut}: gzip data is cut short at compressed byte {len(blob) // 2}" in err
    obs = read_rinex_obs(tmp_path / "out" / "cut.obs")
    assert 0.3 * whole.obs.epochs < len(obs.epochs) < whole.obs.epochs


@pytest.mark.slow
def test_corrupt_gzip_is_salvaged_up_to_the_damage(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = shared_file(f"{M8P}/raw/rover-20181004-1237.ubx.gz")
    blob = bytearray(src.read_bytes())
    damage = len(blob) // 3
    for k in range(damage, damage + 200):
        blob[k] ^= 0x5A
    bad = tmp_path / "bad.ubx.gz"
    bad.write_bytes(bytes(blob))
    whole = convert_one(src, tmp_path / "whole")
    capsys.readouterr()
    code = convert_main([str(bad), "-o", str(tmp_path), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 0
    line = next(ln for ln in err.splitlines() if "gzip data is corrupt" in ln)
    assert line.startswith(f"directgeo: convert: warning: {bad}: gzip data is corrupt")
    at = int(line.split("noticed at compressed byte ")[1].split(":")[0])
    assert at >= damage  # deflate notices the damage at or after it (here only at the end, by the CRC)
    corrupt = next(ln for ln in err.splitlines() if "hold no valid frame (corrupt, skipped)" in ln)
    first = int(corrupt.split(f"{bad} byte ")[1].split()[0])  # decompressed offset of the first garbage
    assert 0.25 * 2549319 < first < 0.45 * 2549319
    obs = read_rinex_obs(tmp_path / "bad.obs")
    assert 0.25 * whole.obs.epochs < len(obs.epochs) < 0.45 * whole.obs.epochs


def test_gzip_damaged_from_the_start_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.ubx.gz"
    bad.write_bytes(b"\x1f\x8b\x08\x00" + bytes(range(256)) * 8)
    code = convert_main([str(bad), "-o", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and "bad.ubx.gz: gzip data is corrupt" in err and "nothing decompressed" in err
    assert not (tmp_path / "out" / "bad.obs").exists()


def test_missing_empty_and_foreign_inputs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "empty.ubx").write_bytes(b"")
    (tmp_path / "text.ubx").write_text("hello\n" * 100)
    (tmp_path / "nodata").mkdir()
    args = [str(tmp_path / n) for n in ("missing.ubx", "empty.ubx", "text.ubx", "nodata")]
    code = convert_main(args + ["-o", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert "missing.ubx: no such file" in err
    assert "empty.ubx: no raw observations or ephemerides found" in err
    assert "text.ubx: no raw observations" in err
    assert "nodata: no journal segments" in err


def test_one_bad_input_does_not_stop_the_others(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = convert_main([str(tmp_path / "missing.ubx"), str(shared_file("ubx/gpsd_ublox-neo-m8t.log")),
                         "-o", str(tmp_path), "--no-progress"])
    assert code == 2 and (tmp_path / "gpsd_ublox-neo-m8t.obs").exists()


def test_command_line_exit_code_without_traceback(tmp_path: Path) -> None:
    env = dict(os.environ, PYTHONPATH=str(PROJECT_ROOT))
    proc = subprocess.run([sys.executable, "-m", "onboard.postpro.convert", str(tmp_path / "nope.ubx.gz"), "-o",
                           str(tmp_path)], check=False, capture_output=True, text=True, env=env, timeout=60)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "nope.ubx.gz: no such file" in proc.stderr


@pytest.mark.slow
def test_progress_bar_on_a_terminal_only(tmp_path: Path) -> None:
    """With stderr on a real pseudo-terminal the command draws a tqdm bar; piped, it prints none."""
    import fcntl
    import struct
    import termios

    src = str(shared_file("ubx/rtklib_ubx_20080526.ubx"))
    env = dict(os.environ, PYTHONPATH=str(PROJECT_ROOT))
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # a terminal has a size
    try:
        proc = subprocess.run([sys.executable, "-m", "onboard.postpro.convert", src, "-o", str(tmp_path / "tty")],
                              check=False, stdout=subprocess.PIPE, stderr=slave, env=env, timeout=120)
        os.set_blocking(master, False)
        chunks = []
        while True:
            try:
                chunk = os.read(master, 65536)
            except (BlockingIOError, OSError):
                break
            if not chunk:
                break
            chunks.append(chunk)
    finally:
        os.close(master)
        os.close(slave)
    on_tty = b"".join(chunks).decode(errors="replace")
    assert proc.returncode == 0 and "rtklib_ubx_20080526.ubx" in on_tty and "B/s" in on_tty
    piped = subprocess.run([sys.executable, "-m", "onboard.postpro.convert", src, "-o", str(tmp_path / "pipe")],
                           check=False, capture_output=True, text=True, env=env, timeout=120)
    assert piped.returncode == 0 and "B/s" not in piped.stderr
    assert (tmp_path / "tty" / "rtklib_ubx_20080526.obs").read_text().split("END OF HEADER")[1] == \
        (tmp_path / "pipe" / "rtklib_ubx_20080526.obs").read_text().split("END OF HEADER")[1]


def test_header_names_the_receiver_from_mon_ver() -> None:
    import datetime as dt

    from onboard.postpro.convert import header_info
    from onboard.receiver.decode import MonVer
    from onboard.receiver.ubx_collect import Collected

    col = Collected(mon_ver=MonVer("ROM CORE 3.01 (107888)", "00080000", ("FWVER=TIM 1.10", "MOD=NEO-M8T")),
                    fixes_ecef_m=[(1.0, 2.0, 3.0), (1.2, 2.0, 3.0), (50.0, 2.0, 3.0)])
    info = header_info(col, "DRONE", dt.datetime(2024, 5, 1, 12, 0, 0, tzinfo=dt.UTC))
    assert info.receiver_type == "U-BLOX NEO-M8T" and info.receiver_version == "ROM CORE 3.01 (107888)"
    assert info.approx_pos_ecef_m == (1.2, 2.0, 3.0)  # median: one wild fix does not move it
    assert info.marker_name == "DRONE" and info.date_utc == "20240501 120000 UTC"


# ----------------------------------------------------------------------------------------------- what was skipped

def _flight_from_log(log: Path, flight: Path, segment_bytes: int) -> None:
    """A recorded flight (journal, index, manifest) holding the bytes of `log`, in segments of ~segment_bytes."""
    from onboard.hw.fake import ManualClock
    from onboard.logger.journal import Journal, JournalOptions

    data = gzip.decompress(log.read_bytes()) if log.suffix == ".gz" else log.read_bytes()
    clock = ManualClock()
    journal = Journal(flight, clock, JournalOptions(segment_max_bytes=segment_bytes))
    for k in range(0, len(data), 4096):
        journal.append(data[k : k + 4096], clock.monotonic_ns(), clock.wall_ns())
        clock.advance_s(0.1)
    journal.close()


@pytest.mark.slow
def test_journal_with_a_middle_segment_deleted_says_so(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 14 case 7: 374 of 554 epochs came back with exit 0 and no word."""
    flight = tmp_path / "flight-20181004T123700Z"
    _flight_from_log(shared_file(f"{M8P}/raw/rover-20181004-1237.ubx.gz"), flight, 600_000)
    assert [p.name for p in sorted(flight.glob("*.ubx"))] == [f"00000{k}.ubx" for k in range(5)]
    (flight / "000002.ubx").unlink()
    code = convert_main([str(flight), "-o", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 0
    assert (f"directgeo: convert: warning: {flight}: segment 000002.ubx missing between 000001.ubx and "
            "000003.ubx") in err
    assert "hold no valid frame (corrupt, skipped): at " + str(flight / "000001.ubx") + " byte " in err
    assert len(read_rinex_obs(tmp_path / "out" / f"{flight.name}.obs").epochs) < 1000


def _frames_only(log: Path) -> bytes:
    """The valid frames of a capture, without its text header and torn tail: a clean stream."""
    from onboard.receiver.framing import iter_frames

    return b"".join(f.raw for f in iter_frames(log.read_bytes()))


def test_corrupted_region_is_reported_with_its_offset(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = bytearray(_frames_only(shared_file("ubx/gpsd_ublox-neo-m8t.log")))
    data[5000:5400] = bytes(range(100, 200)) * 4
    bad = tmp_path / "damaged.ubx"
    bad.write_bytes(bytes(data))
    code = convert_main([str(bad), "-o", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 0
    line = next(ln for ln in err.splitlines() if "hold no valid frame" in ln)
    assert line.startswith("directgeo: convert: warning: ")
    start = int(line.split(f"{bad} byte ")[1].split()[0])
    length = int(line.split(f"{bad} byte {start} (")[1].split(" B)")[0])
    assert start <= 5000 and start + length >= 5400 and length < 5400 - 5000 + 2 * 1100


def test_clean_input_reports_nothing_and_a_real_capture_its_header_and_torn_tail(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = shared_file("ubx/gpsd_ublox-neo-m8t.log")
    clean = tmp_path / "clean.ubx"
    clean.write_bytes(_frames_only(log))
    assert convert_main([str(clean), "-o", str(tmp_path), "--no-progress"]) == 0
    assert capsys.readouterr().err == ""
    assert convert_main([str(log), "-o", str(tmp_path), "--no-progress"]) == 0
    assert capsys.readouterr().err.splitlines() == [  # gpsd's 314-byte comment header, a frame cut at the end
        f"directgeo: convert: warning: torn tail: 314 bytes at {log} byte 25904 are not a complete frame (skipped)",
        (f"directgeo: convert: warning: 314 bytes in 1 region hold no valid frame (corrupt, skipped): at {log} "
         "byte 0 (314 B)")]


def test_two_inputs_of_one_stem_are_refused_before_writing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 14 case 6: the second silently overwrote the first."""
    log = shared_file("ubx/gpsd_ublox-neo-m8t.log").read_bytes()
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        (tmp_path / d / "rover.ubx").write_bytes(log)
    code = convert_main([str(tmp_path / "a" / "rover.ubx"), str(tmp_path / "b" / "rover.ubx"),
                         "-o", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.strip() == (f"directgeo: convert: error: {tmp_path / 'a' / 'rover.ubx'} and "
                           f"{tmp_path / 'b' / 'rover.ubx'} would both write rover.obs/.nav: convert them into "
                           "different -o directories (nothing written)")
    assert not (tmp_path / "out").exists()
