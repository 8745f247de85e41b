"""`python -m onboard` as a user meets it: help written for users, one error format, exit codes 0/1/2/3.

In-process through `onboard.__main__.main(argv)` (stderr captured); the RTK engine is replaced where only the
shell's rules are under test (what it writes for Q_NONE rows, what it does with the engine's ValueError).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

from onboard.__main__ import build_parser, main
from onboard.formats.pos import read_pos, write_pos
from onboard.gnsstime import GpsTime
from onboard.postpro import rtk_cli
from onboard.rtk.types import Q_FIX, Q_NONE, Solution
from tests.conftest import shared_file

GEONET = "gnss/geonet-0759-3040-20050402/"
BASE_3040 = "-3978241.958,3382840.234,3649900.853"
ROVER_0759 = np.array([-3976219.1873, 3382371.6051, 3652511.1423])


def _geonet() -> list[str]:
    return ["--rover", str(shared_file(GEONET + "07590920.05o.gz")),
            "--base", str(shared_file(GEONET + "30400920.05o.gz")),
            "--nav", str(shared_file(GEONET + "07590920.05n.gz"))]


def _last_err(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.startswith("directgeo: ")]
    assert lines, err
    return lines[-1]


# ----------------------------------------------------------------------------------------------- help texts

def _command_parser(command: str) -> argparse.ArgumentParser:
    parser = build_parser([command])
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[command]


@pytest.mark.parametrize("command", ["run", "check", "convert", "rtk", "base", "web"])
def test_every_option_is_described(command: str) -> None:
    parser = _command_parser(command)
    bare = [a.dest for a in parser._actions if not a.help or a.help == argparse.SUPPRESS]
    assert bare == []
    assert "Register with" not in parser.format_help()


@pytest.mark.parametrize("command", ["check", "convert", "rtk"])
def test_help_says_what_with_an_example(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([command, "--help"]) == 0
    text = capsys.readouterr().out
    assert f"python -m onboard {command} " in text.split("examples:")[1]
    assert "exit codes:" in text


def test_top_level_help_lists_every_command_with_examples(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--help"]) == 0
    text = capsys.readouterr().out
    for name in ("run", "check", "convert", "rtk", "base", "web"):
        assert f"    {name}" in text
    assert "examples:" in text


# ----------------------------------------------------------------------------------------------- usage errors

def test_unknown_command_and_argparse_errors_use_the_common_format(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fly"]) == 2
    assert _last_err(capsys).startswith("directgeo: onboard: error: argument COMMAND: invalid choice: 'fly'")
    assert main(["rtk", "--rover", "r", "--base", "b", "-o", "x.pos", "--direction", "sideways"]) == 2
    assert _last_err(capsys).startswith("directgeo: rtk: error: argument --direction: invalid choice: 'sideways'")
    assert main(["convert"]) == 2
    assert _last_err(capsys) == ("directgeo: convert: error: the following arguments are required: INPUT, "
                                 "-o/--out-dir")


@pytest.mark.parametrize("value", ["nan,nan,nan", "inf,0,0", "1,2,3", "-3978241.958,3382840.234"])
@pytest.mark.parametrize("option", ["--base-pos", "--init-pos"])
def test_non_finite_or_impossible_positions_are_refused(option: str, value: str, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 14 case 3: `--base-pos=nan,nan,nan` wrote 194 nan rows with exit 0."""
    out = tmp_path / "x.pos"
    assert main(["rtk", "--rover", "r", "--base", "b", f"{option}={value}", "-o", str(out)]) == 2
    line = _last_err(capsys)
    assert line.startswith(f"directgeo: rtk: error: {option} {value}: must be ")
    assert not out.exists()


def test_elmask_out_of_range(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["rtk", "--rover", "r", "--base", "b", "-o", "x.pos", "--elmask", "95"]) == 2
    assert _last_err(capsys) == "directgeo: rtk: error: --elmask 95: must be 0–90°"


def test_output_that_is_a_directory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["rtk", "--rover", "r", "--base", "b", "-o", str(tmp_path)]) == 2
    assert _last_err(capsys) == f"directgeo: rtk: error: --output {tmp_path}: must be a file path, not a directory"
    (tmp_path / "file").write_text("x")
    assert main(["convert", "in.ubx", "-o", str(tmp_path / "file")]) == 2
    assert _last_err(capsys) == f"directgeo: convert: error: --out-dir {tmp_path / 'file'}: must be a directory, not a file"


def test_web_port_out_of_range(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["web", "--port", "99999"]) == 2
    assert _last_err(capsys) == "directgeo: web: error: --port 99999: must be 1–65535"


def test_output_may_not_be_an_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rover = tmp_path / "rover.obs"
    rover.write_text("precious\n")
    assert main(["rtk", "--rover", str(rover), "--base", "b", "-o", str(rover)]) == 2
    assert "is one of the inputs" in _last_err(capsys)
    assert rover.read_text() == "precious\n"


# ----------------------------------------------------------------------------------------------- positions

def test_negative_x_works_as_one_word_and_as_three(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`--base-pos -3978241.958,...` was 'expected at least one argument' (nargs="+" took -3978… for an option)."""
    a, b, c = tmp_path / "a.pos", tmp_path / "b.pos", tmp_path / "c.pos"
    assert main(["rtk", *_geonet(), "--base-pos", BASE_3040, "-o", str(a)]) == 0
    assert main(["rtk", *_geonet(), "--base-pos", *BASE_3040.split(","), "-o", str(b)]) == 0
    assert main(["rtk", *_geonet(), "--base-pos", BASE_3040.replace(",", " "), "-o", str(c)]) == 0
    assert a.read_bytes() == b.read_bytes() == c.read_bytes()
    track = read_pos(a)
    assert np.linalg.norm(track.pos_ecef_m[track.q == Q_FIX] - ROVER_0759, axis=1).max() < 0.05


# ----------------------------------------------------------------------------------------------- data rules

def test_nav_file_of_another_day_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 14 case 4: a nav file of the wrong day wrote 203 rows of 0,0,0 Q=0 with exit 0."""
    args = _geonet()
    args[args.index("--nav") + 1] = str(shared_file("gnss/ublox-m8p-galway-2018/rinex/rover-20181004-1237.nav.gz"))
    out = tmp_path / "x.pos"
    assert main(["rtk", *args, f"--base-pos={BASE_3040}", "-o", str(out)]) == 3
    line = _last_err(capsys)
    assert line.startswith("directgeo: rtk: error: no GPS ephemeris valid at the observations' time "
                           "(2005-04-02 00:00 to 00:59 GPST;")
    assert "is the navigation file of another day?" in line
    assert not out.exists()


def _solution(k: int, q: int, pos: np.ndarray) -> Solution:
    cov = np.eye(3) * 1e-4
    return Solution(GpsTime.from_week_tow_s(1316, 518400.0 + 30 * k), pos, np.zeros(3), q, 8 if q else 0, cov,
                    cov, 0.5, 3.0)


def test_rows_without_a_solution_are_never_written(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    sols = [_solution(0, Q_FIX, ROVER_0759), _solution(1, Q_NONE, np.zeros(3)),
            _solution(2, Q_NONE, np.full(3, np.nan)), _solution(3, Q_FIX, np.array([np.nan, 1.0, 2.0])),
            _solution(4, Q_FIX, ROVER_0759)]
    monkeypatch.setattr(rtk_cli, "postprocess", lambda *a, **k: (sols, []))
    out = tmp_path / "x.pos"
    assert main(["rtk", *_geonet(), f"--base-pos={BASE_3040}", "-o", str(out)]) == 0
    assert "3 of 5 epochs have no solution: not written" in capsys.readouterr().err
    track = read_pos(out)
    assert list(track.q) == [Q_FIX, Q_FIX] and np.all(np.isfinite(track.pos_ecef_m))


def test_no_epoch_with_a_solution_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    sols = [_solution(k, Q_NONE, np.full(3, np.nan)) for k in range(5)]
    monkeypatch.setattr(rtk_cli, "postprocess", lambda *a, **k: (sols, []))
    out = tmp_path / "x.pos"
    out.write_text("previous\n")
    assert main(["rtk", *_geonet(), f"--base-pos={BASE_3040}", "-o", str(out)]) == 3
    assert _last_err(capsys).startswith("directgeo: rtk: error: no epoch has a solution (5 rover epochs)")
    assert out.read_text() == "previous\n"


def test_a_value_error_of_the_engine_is_a_refusal(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """The engine's data rules (BasePositionRejected(ValueError) for a base its own data contradicts) -> exit 3."""
    def reject(*args: object, **kwargs: object) -> None:
        raise ValueError("base position 100.0 m from the base's own single-point solution (bound 30 m)")

    monkeypatch.setattr(rtk_cli, "postprocess", reject)
    assert main(["rtk", *_geonet(), f"--base-pos={BASE_3040}", "-o", str(tmp_path / "x.pos")]) == 3
    assert _last_err(capsys) == ("directgeo: rtk: error: base position 100.0 m from the base's own single-point "
                                 "solution (bound 30 m)")


def test_pos_writer_refuses_rows_without_a_position(tmp_path: Path) -> None:
    out = tmp_path / "x.pos"
    out.write_text("previous\n")
    for bad in (_solution(1, Q_NONE, ROVER_0759), _solution(1, Q_FIX, np.array([np.inf, 0.0, 0.0]))):
        with pytest.raises(ValueError, match="has no position: not written"):
            write_pos(out, [_solution(0, Q_FIX, ROVER_0759), bad])
        assert out.read_text() == "previous\n"


# ----------------------------------------------------------------------------------------------- bugs

def test_a_bug_is_one_line_and_exit_1(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    def broken(args: object) -> int:
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(rtk_cli, "rtk_main", broken)
    monkeypatch.setattr(rtk_cli, "_run", broken)
    from onboard.postpro import check_cli

    monkeypatch.setattr(check_cli, "_check", broken)
    assert main(["check", "somewhere"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.strip() == ("directgeo: check: error: unexpected ZeroDivisionError: division by zero (a bug; run "
                           "with -v for the traceback)")
