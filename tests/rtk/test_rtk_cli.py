"""`onboard rtk` end to end on real data (short slices) and its errors for unusable inputs."""

from __future__ import annotations

import argparse
import gzip

import numpy as np
import pytest

from onboard.formats.pos import read_pos
from onboard.postpro.rtk_cli import add_rtk_parser, main
from tests.conftest import shared_file

GEONET = "gnss/geonet-0759-3040-20050402/"
BASE_3040 = "-3978241.958,3382840.234,3649900.853"


def _slice_rinex_v3(src, dst, n_epochs: int) -> None:
    """Write the header and the first n epochs of a RINEX 3 file (a short test input, made on the fly)."""
    out = []
    count = 0
    for line in gzip.decompress(src.read_bytes()).decode().splitlines():
        if line.startswith(">"):
            count += 1
            if count > n_epochs:
                break
        out.append(line)
    dst.write_text("\n".join(out) + "\n")


def test_parser_registers_the_documented_options():
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    add_rtk_parser(sub)
    args = parser.parse_args(["rtk", "--rover", "r", "--base", "b", "--nav", "n1", "--nav", "n2",
                              f"--base-pos={BASE_3040}", "--direction", "combined", "--velocity", "-o", "o.pos"])
    assert args.nav == ["n1", "n2"] and args.direction == "combined" and args.velocity
    assert args.ar_mode == "fix-and-hold" and args.elmask == 15.0


def test_geonet_end_to_end_writes_an_rtklib_pos(tmp_path, capsys):
    out = tmp_path / "g.pos"
    rc = main(["rtk", "--rover", str(shared_file(GEONET + "07590920.05o.gz")),
               "--base", str(shared_file(GEONET + "30400920.05o.gz")),
               "--nav", str(shared_file(GEONET + "07590920.05n.gz")),
               "--base-pos", *BASE_3040.split(","), "-o", str(out)])
    assert rc == 0
    assert "120 epochs" in capsys.readouterr().out
    text = out.read_text().splitlines()
    title = next(ln for ln in text if ln.startswith("%  GPST"))
    assert "x-ecef(m)" in title and "ratio" in title
    data = [ln.split() for ln in text if not ln.startswith("%")]
    assert len(data) == 120 and all(len(t) == 15 for t in data)
    track = read_pos(out)
    assert set(track.q) <= {1, 2, 5}
    assert np.mean(track.q == 1) >= 0.75
    ref = np.array([-3976219.1873, 3382371.6051, 3652511.1423])
    err = np.linalg.norm(track.pos_ecef_m[track.q == 1] - ref, axis=1)
    assert err.max() < 0.05
    assert track.time[0].week == 1316 and track.time[0].tow_s == pytest.approx(518400.0, abs=1e-3)


def test_m8p_slice_with_header_base_position_llh_and_velocity(tmp_path):
    d = "gnss/ublox-m8p-galway-2018/rinex/"
    rover = tmp_path / "rover.obs"
    _slice_rinex_v3(shared_file(d + "rover-20181004-1237.obs.gz"), rover, 90)
    out = tmp_path / "m.pos"
    rc = main(["rtk", "--rover", str(rover), "--base", str(shared_file(d + "base-20181004-1236.rtcm.obs.gz")),
               "--nav", str(shared_file(d + "rover-20181004-1237.nav.gz")), "--llh", "--velocity", "-o", str(out)])
    assert rc == 0
    track = read_pos(out)
    assert track.llh and track.vel_m_s is not None
    assert 80 <= len(track.q) <= 90  # the slice also counted a few event (TIM-TM2) records
    assert np.sum(track.q == 1) >= 30
    ref = np.array([3774088.9931, -601661.8217, 5089321.3853])
    err = np.linalg.norm(track.pos_ecef_m[track.q == 1] - ref, axis=1)
    assert err.max() < 0.05
    assert np.all(np.abs(track.vel_m_s[-10:]) < 0.05)  # static rover: n/e/u velocity ≈ 0
    # solution time = receiver tag (…08.991) minus the clock bias: on the whole GPS second, as RTKLIB
    assert all(abs(t.tow_s - round(t.tow_s)) < 1e-3 for t in track.time)


@pytest.mark.slow
def test_combined_says_how_many_fixes_the_two_passes_dispute(tmp_path, capsys):
    """The M8P walk under trees, GPS+GLONASS, combined: the fixes written as float because the forward and
    backward passes disagree are counted on stderr (4 + 4 when measured), and the .pos has them as float."""
    d = "gnss/ublox-m8p-galway-2018/rinex/"
    rc = main(["rtk", "--rover", str(shared_file(d + "rover-20181004-1532.obs.gz")),
               "--base", str(shared_file(d + "base-20181004-1452.rawx.obs.gz")),
               "--nav", str(shared_file(d + "rover-20181004-1532.nav.gz")),
               "--base-pos", "3774085.6456,-601662.5769,5089316.3970", "--systems", "GR", "--direction", "combined",
               "--no-progress", "-o", str(tmp_path / "walk.pos")])
    assert rc == 0
    err = capsys.readouterr().err
    line = [x for x in err.splitlines() if x.startswith("fixes the two passes dispute, written as float: ")]
    assert len(line) == 1
    forward, backward = (int(w) for w in line[0].split(": ")[1].replace(",", "").split()[0:3:2])
    assert forward > 0 and backward > 0


def _run_err(capsys, argv) -> str:
    assert main(argv) == 2
    return capsys.readouterr().err


def test_missing_navigation_is_a_clear_error(tmp_path, capsys):
    err = _run_err(capsys, ["rtk", "--rover", str(shared_file(GEONET + "07590920.05o.gz")),
                            "--base", str(shared_file(GEONET + "30400920.05o.gz")), "-o", str(tmp_path / "x.pos")])
    assert "no GPS ephemeris" in err and not (tmp_path / "x.pos").exists()


def test_no_common_epochs_is_a_clear_error(tmp_path, capsys):
    d = "gnss/ublox-m8p-galway-2018/rinex/"
    err = _run_err(capsys, ["rtk", "--rover", str(shared_file(GEONET + "07590920.05o.gz")),
                            "--base", str(shared_file(d + "base-20181004-1236.rtcm.obs.gz")),
                            "--nav", str(shared_file(GEONET + "07590920.05n.gz")), "-o", str(tmp_path / "x.pos")])
    assert "no common epochs" in err


def test_base_without_position_is_a_clear_error(tmp_path, capsys):
    src = gzip.decompress(shared_file(GEONET + "30400920.05o.gz").read_bytes()).decode().splitlines()
    base = tmp_path / "nopos.05o"
    base.write_text("\n".join(ln for ln in src if "APPROX POSITION" not in ln) + "\n")
    err = _run_err(capsys, ["rtk", "--rover", str(shared_file(GEONET + "07590920.05o.gz")), "--base", str(base),
                            "--nav", str(shared_file(GEONET + "07590920.05n.gz")), "-o", str(tmp_path / "x.pos")])
    assert "no base position" in err and "--base-pos" in err


def test_unreadable_rover_and_bad_coordinates(tmp_path, capsys):
    bad = tmp_path / "junk.obs"
    bad.write_bytes(b"\x00\x01 not a log")
    err = _run_err(capsys, ["rtk", "--rover", str(bad), "--base", str(shared_file(GEONET + "30400920.05o.gz")),
                            "-o", str(tmp_path / "x.pos")])
    assert "junk.obs" in err
    err = _run_err(capsys, ["rtk", "--rover", "a", "--base", "b", "--base-pos", "1,2", "-o", "x"])
    assert "X,Y,Z" in err
    err = _run_err(capsys, ["rtk", "--rover", str(tmp_path / "missing.obs"), "--base", "b", "-o", "x"])
    assert "no such file" in err


def test_one_xyz_check_behind_the_positions_of_the_command_lines(capsys):
    """`onboard rtk --base-pos/--init-pos` and `onboard base --position` check X,Y,Z with
    onboard.validate.ecef_position_m: commas or spaces, negative values first, a bad triple a usage error."""
    from onboard.__main__ import build_parser

    rtk = build_parser(["rtk"])
    args = rtk.parse_args(["rtk", "--rover", "r", "--base", "b", "-o", "x.pos",
                           "--base-pos", "3774085.6456,-601662.5769,5089316.3970",
                           "--init-pos", "-3976219.1", "3382371.6", "3652511.1"])
    assert args.base_pos == (3774085.6456, -601662.5769, 5089316.397)
    assert args.init_pos == (-3976219.1, 3382371.6, 3652511.1)
    base = build_parser(["base"])
    for text in ("3774085.6 -601662.5  5089316.3", "3774085.6,-601662.5,5089316.3"):
        args = base.parse_args(["base", "--port", "p", "--radio", "r", "--position", text])
        assert args.position == (3774085.6, -601662.5, 5089316.3)
    args = base.parse_args(["base", "--port", "p", "--radio", "r", "--position", "-3976219.1,3382371.6,3652511.1"])
    assert args.position == (-3976219.1, 3382371.6, 3652511.1)
    for bad in ("1 2", "1,2,3,4", "a,b,c", "1;2;3", "nan,0,0"):
        with pytest.raises(SystemExit) as exc:
            base.parse_args(["base", "--port", "p", "--radio", "r", f"--position={bad}"])
        assert exc.value.code == 2
        assert capsys.readouterr().err.startswith(f"directgeo: base: error: --position {bad}: must be ")


@pytest.mark.slow
def test_ubx_rover_log_with_its_own_ephemerides(tmp_path, capsys):
    """The raw M8P rover log (RXM-RAWX + RXM-SFRBX, gzip) needs no --nav: ephemerides come from the log."""
    d = "gnss/ublox-m8p-galway-2018/"
    out = tmp_path / "u.pos"
    rc = main(["rtk", "--rover", str(shared_file(d + "raw/rover-20181004-1237.ubx.gz")),
               "--base", str(shared_file(d + "rinex/base-20181004-1236.rtcm.obs.gz")), "-o", str(out)])
    assert rc == 0, capsys.readouterr().err
    track = read_pos(out)
    assert len(track.q) == 1205
    assert np.mean(track.q == 1) >= 0.9
    ref = np.array([3774088.9931, -601661.8217, 5089321.3853])
    assert np.linalg.norm(track.pos_ecef_m[track.q == 1] - ref, axis=1).max() < 0.10


def test_rinex_run_imports_only_what_rinex_needs(tmp_path):
    """`python -m onboard rtk` on RINEX inputs loads neither the UBX/RTCM decoders nor the other commands'
    modules (start-up is part of the whole-command CPU time the RTKLIB driver is compared with)."""
    import subprocess
    import sys
    from pathlib import Path

    project = Path(__file__).resolve().parents[2]
    args = ["rtk", "--rover", str(shared_file(GEONET + "07590920.05o.gz")),
            "--base", str(shared_file(GEONET + "30400920.05o.gz")),
            "--nav", str(shared_file(GEONET + "07590920.05n.gz")), f"--base-pos={BASE_3040}", "--no-progress",
            "-o", str(tmp_path / "g.pos")]
    code = ("import sys\nfrom onboard.__main__ import main\nrc = main(sys.argv[1:])\n"
            "print('MODULES', *sorted(m for m in sys.modules if '.' not in m or m.startswith('onboard.')))\n"
            "sys.exit(rc)")
    out = subprocess.run([sys.executable, "-c", code, *args], cwd=project, capture_output=True, text=True,
                         timeout=120, check=False)
    assert out.returncode == 0, out.stderr
    assert "120 epochs" in out.stdout
    loaded = set(next(ln for ln in out.stdout.splitlines() if ln.startswith("MODULES")).split()[1:])
    assert "onboard.rtk.rtkpos" in loaded and "onboard.formats.rinex_obs" in loaded
    unneeded = {"pyubx2", "pyrtcm", "scipy", "pyproj", "tqdm", "fastapi", "serial", "tomllib", "onboard.recorder.settings",
                "onboard.postpro.convert", "onboard.receiver.decode", "onboard.base.cli", "onboard.web", "onboard.recorder.daemon"}
    assert not loaded & unneeded, sorted(loaded & unneeded)


def test_rtk_says_what_its_ubx_reader_skipped(tmp_path, caplog):
    """A corrupted region of a UBX rover log is reported with its byte offset (it was skipped without a word)."""
    data = bytearray(shared_file("ubx/gpsd_ublox-neo-m8t.log").read_bytes())
    data[5000:5400] = bytes(400)
    rover = tmp_path / "damaged.ubx"
    rover.write_bytes(bytes(data))
    with caplog.at_level("WARNING"):
        main(["rtk", "--rover", str(rover), "--base", str(rover), "-o", str(tmp_path / "x.pos")])
    corrupt = [r.getMessage() for r in caplog.records if "hold no valid frame" in r.getMessage()]
    assert corrupt and f"{rover} byte 4996 (492 B)" in corrupt[0]


M8P = "gnss/ublox-m8p-galway-2018/rinex/"


def test_systems_option_letters(capsys):
    parser = argparse.ArgumentParser()
    add_rtk_parser(parser.add_subparsers())
    base = ["rtk", "--rover", "r", "--base", "b", "-o", "o.pos"]
    assert parser.parse_args(base).systems == "G"
    assert parser.parse_args([*base, "--systems", "grG"]).systems == "GR"
    with pytest.raises(SystemExit):
        parser.parse_args([*base, "--systems", "GX"])
    assert "letters of G, R, E, C, J" in capsys.readouterr().err


def test_other_systems_observations_and_ephemerides_are_read_when_asked_for(tmp_path):
    from onboard.postpro.inputs import read_navigation, read_observations
    from onboard.rtk.types import GNSS_GLONASS, GNSS_GPS

    nav_file = shared_file(M8P + "rover-20181004-1237.nav.gz")
    gps_only = read_navigation([nav_file])
    both = read_navigation([nav_file], systems="GR")
    assert gps_only.broadcast is None
    assert both.broadcast is not None and len(both.broadcast) > 0
    assert {g for g, _ in both.broadcast.satellites()} == {GNSS_GLONASS}
    assert len(both.store) == len(gps_only.store) > 0
    obs = tmp_path / "rover.obs"
    _slice_rinex_v3(shared_file(M8P + "rover-20181004-1237.obs.gz"), obs, 3)
    assert {int(g) for e in read_observations(obs).epochs for g in e.gnss_id} == {GNSS_GPS}
    assert {int(g) for e in read_observations(obs, "GR").epochs for g in e.gnss_id} == {GNSS_GPS, GNSS_GLONASS}
