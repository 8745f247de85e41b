"""Property-based tests of the onboard command lines: drawn argument values never reach a user as a traceback.

Each test runs `onboard.__main__.main(argv)` in-process (stderr captured) with values drawn by hypothesis:
non-finite, huge, negative, empty and unicode numbers, coordinates in every form, and paths that are
directories, files, missing, nested in a file, unicode. It asserts an exit code of the convention (0 done,
1 failure, 2 usage, 3 refused), an error line `directgeo: <command>: error: ...` for every non-zero code, no
traceback, and no partial file (no temporary file left; an output exists only after exit 0, or is the previous
one). Examples per test: see `max_examples` below (rtk 60, convert 40, check 40, base 60, web 40).
`base` and `web` are fuzzed up to their parsed arguments (running them would open serial ports or a server).
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, event, given, settings
from hypothesis import strategies as st

from onboard.__main__ import build_parser, main
from onboard.gnsstime import GpsTime
from onboard.postpro import rtk_cli
from onboard.rtk.types import Q_FIX, Q_FLOAT, Q_NONE, Q_SINGLE, Solution
from onboard.validate import EARTH_RADIUS_MAX_M, EARTH_RADIUS_MIN_M
from tests.conftest import shared_file

FUZZ = settings(deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
                phases=(Phase.explicit, Phase.reuse, Phase.generate, Phase.shrink))
GEONET = "gnss/geonet-0759-3040-20050402/"
ROVER_0759 = np.array([-3976219.1873, 3382371.6051, 3652511.1423])

# -- values ---------------------------------------------------------------------------------------------------
_text = st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"), max_size=12)
NUMBERS = st.one_of(
    st.sampled_from(["nan", "NaN", "inf", "-inf", "1e309", "-1e309", "0", "-0", "", " ", "1e-320", "95", "90",
                     "-5", "15", "abc", "٣", "１２", "0x10", "1_000", "+7", "3.5.1"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-10**22, 10**22).map(str),
    _text,
)
_COORD = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr),
                   st.sampled_from(["-3976219.1873", "3382371.6051", "3652511.1423", "nan", "", "x"]))
COORDINATES = st.one_of(
    st.lists(_COORD, min_size=0, max_size=4).flatmap(lambda xs: st.sampled_from([",", " ", ", "]).map(
        lambda sep: sep.join(xs))),
    st.sampled_from(["-3978241.958,3382840.234,3649900.853", "-3978241.958 3382840.234 3649900.853",
                     "0,0,0", "1,2,3", "6378137,0,0", "nan,nan,nan", "inf,0,0"]),
    _text,
)
GOOD_NUMBERS = st.sampled_from(["15", "0", "90", "1", "2.5", "600", "1004"])
GOOD_POSITIONS = st.sampled_from(["-3978241.958,3382840.234,3649900.853", "-3978241.958 3382840.234 3649900.853"])


def _mostly(good: st.SearchStrategy[str], bad: st.SearchStrategy[str]) -> st.SearchStrategy[str | None]:
    """The option left out or a good value 4 times in 5, a drawn bad value otherwise (so that several options
    are good together often enough for the command to run past its parsing)."""
    return st.tuples(st.integers(0, 9), st.none() | good, bad).map(lambda t: t[1] if t[0] < 8 else t[2])


PATH_KINDS = ("dir", "file", "missing", "in_missing_dir", "in_file", "unicode", "empty", "dot")


@contextmanager
def _sandbox() -> Iterator[Path]:
    """A fresh directory holding `dir/` and a non-log `file`, also the working directory ("." paths land here)."""
    cwd = Path.cwd()
    with tempfile.TemporaryDirectory(prefix="fuzz-") as d:
        root = Path(d)
        (root / "dir").mkdir()
        (root / "file").write_bytes(b"\x00\x01 not a log\n" * 10)
        os.chdir(root)
        try:
            yield root
        finally:
            os.chdir(cwd)


def _path(root: Path, kind: str, name: str = "out.pos") -> str:
    return {"dir": str(root / "dir"), "file": str(root / "file"), "missing": str(root / name),
            "in_missing_dir": str(root / "no" / "such" / name), "in_file": str(root / "file" / name),
            "unicode": str(root / f"é✓ {name}"), "empty": "", "dot": "."}[kind]


def _assert_clean(code: int, err: str, command: str) -> None:
    event(f"exit {code}")
    assert code in (0, 1, 2, 3), code
    assert "Traceback" not in err and "unexpected" not in err, err
    if code:
        assert f"directgeo: {command}: error: " in err or "directgeo: onboard: error: " in err, err


def _no_temporary_files(root: Path) -> None:
    assert not [p for p in root.rglob("*") if p.name.endswith(".tmp")]


# -- rtk --------------------------------------------------------------------------------------------------------
def _solutions(qs: list[int], finite: list[bool]) -> list[Solution]:
    cov = np.eye(3) * 1e-4
    out = []
    for k, (q, ok) in enumerate(zip(qs, finite, strict=False)):
        pos = ROVER_0759 if ok else np.array([np.nan, 0.0, 0.0])
        out.append(Solution(GpsTime.from_week_tow_s(1316, 518400.0 + 30 * k), pos, np.zeros(3), q, 7, cov, cov,
                            0.5, 2.0))
    return out


@settings(FUZZ, max_examples=60)
@given(elmask=_mostly(GOOD_NUMBERS, NUMBERS), base_pos=_mostly(GOOD_POSITIONS, COORDINATES),
       init_pos=_mostly(GOOD_POSITIONS, COORDINATES),
       direction=_mostly(st.sampled_from(["forward", "backward", "combined"]), st.sampled_from(["sideways", ""])),
       rover=_mostly(st.just("real"), st.sampled_from(["dir", "file", "missing", "unicode"])),
       out_kind=_mostly(st.sampled_from(["missing", "unicode"]), st.sampled_from(PATH_KINDS)).map(
           lambda k: k or "missing"), previous=st.booleans(),
       qs=st.lists(st.sampled_from([Q_FIX, Q_FLOAT, Q_SINGLE, Q_NONE]), max_size=6),
       finite=st.lists(st.booleans(), min_size=6, max_size=6), equals=st.booleans())
@pytest.mark.slow
def test_rtk_arguments(elmask: str | None, base_pos: str | None, init_pos: str | None, direction: str | None,
                       rover: str, out_kind: str, previous: bool, qs: list[int], finite: list[bool], equals: bool,
                       capsys: pytest.CaptureFixture[str]) -> None:
    real = {"rover": str(shared_file(GEONET + "07590920.05o.gz")),
            "base": str(shared_file(GEONET + "30400920.05o.gz")), "nav": str(shared_file(GEONET + "07590920.05n.gz"))}
    with _sandbox() as root:
        out = _path(root, out_kind)
        argv = ["rtk", "--rover", real["rover"] if rover in ("real", None) else _path(root, rover, "rover.obs"),
                "--base", real["base"], "--nav", real["nav"], "-o", out, "--no-progress"]
        for option, value in (("--elmask", elmask), ("--base-pos", base_pos), ("--init-pos", init_pos),
                              ("--direction", direction)):
            if value is not None:
                argv += [f"{option}={value}"] if equals else [option, value]
        target = Path(out) if out else None
        if previous and target is not None and out_kind in ("missing", "unicode"):
            target.write_text("previous\n")
        before = target.read_bytes() if target is not None and target.is_file() else None
        with mock.patch.object(rtk_cli, "postprocess", lambda *a, **k: (_solutions(qs, finite), [])):
            code = main(argv)
        err = capsys.readouterr().err
        _assert_clean(code, err, "rtk")
        _no_temporary_files(root)
        if code == 0:
            assert target is not None
            rows = [ln.split() for ln in target.read_text().splitlines() if not ln.startswith("%")]
            assert rows and all(int(r[5]) != Q_NONE and all(math.isfinite(float(v)) for v in r[2:5]) for r in rows)
        elif target is not None and target.is_file():
            assert target.read_bytes() == before  # the previous output (or an input) is untouched


# -- convert ----------------------------------------------------------------------------------------------------
@settings(FUZZ, max_examples=40)
@given(inputs=st.lists(st.sampled_from(["log", "gz_garbage", "dir", "file", "missing", "unicode", "journal",
                                        "same_stem"]), min_size=1, max_size=3),
       out_kind=st.sampled_from(PATH_KINDS), marks=st.none() | st.sampled_from(["falling", "both", "up", ""]),
       marker=st.none() | _text)
def test_convert_arguments(inputs: list[str], out_kind: str, marks: str | None, marker: str | None,
                           capsys: pytest.CaptureFixture[str]) -> None:
    log = shared_file("ubx/gpsd_ublox-neo-m8t.log").read_bytes()
    with _sandbox() as root:
        paths = []
        for k, kind in enumerate(inputs):
            if kind == "log":
                p = root / f"log{k}.ubx"
                p.write_bytes(log[: len(log) // (k + 1)])
            elif kind == "gz_garbage":
                p = root / f"g{k}.ubx.gz"
                p.write_bytes(b"\x1f\x8b\x08\x00" + bytes(range(256)))
            elif kind == "journal":
                p = root / f"flight-{k}"
                p.mkdir()
                (p / "000000.ubx").write_bytes(log[:9000])
                (p / "000002.ubx").write_bytes(log[9000:])
            elif kind == "same_stem":
                (root / f"s{k}").mkdir()
                p = root / f"s{k}" / "log0.ubx"
                p.write_bytes(log)
            else:
                p = Path(_path(root, kind, f"in{k}.ubx"))
                if kind == "unicode":
                    p.write_bytes(log)
            paths.append(str(p))
        out = _path(root, out_kind, "rinex")
        argv = ["convert", *paths, "-o", out, "--no-progress"]
        if marks is not None:
            argv += ["--marks", marks]
        if marker is not None:
            argv += [f"--marker={marker}"]
        code = main(argv)
        err = capsys.readouterr().err
        _assert_clean(code, err, "convert")
        _no_temporary_files(root)
        for line in err.splitlines():
            assert line.startswith(("directgeo: convert: ", "(usage: ")), line


# -- check ------------------------------------------------------------------------------------------------------
DAMAGE = st.sampled_from(["none", "delete_events", "garbage_events", "truncate_events", "delete_idx",
                          "garbage_idx", "delete_segment", "garbage_segment", "delete_manifest", "garbage_manifest",
                          "empty_dir"])


@settings(FUZZ, max_examples=40)
@given(damages=st.lists(DAMAGE, min_size=1, max_size=3), extra=st.lists(st.sampled_from(PATH_KINDS), max_size=2),
       junk=st.binary(max_size=64), as_json=st.booleans())
@pytest.mark.slow
def test_check_arguments(damages: list[str], extra: list[str], junk: bytes, as_json: bool,
                         capsys: pytest.CaptureFixture[str]) -> None:
    from tests.logger.test_check import make_flight

    with _sandbox() as root:
        flight = root / "flight"
        make_flight(flight, n=30, segment_max_bytes=400)
        for damage in damages:
            what, _, name = damage.partition("_")
            target = {"events": flight / "events.jsonl", "idx": flight / "000001.idx",
                      "segment": flight / "000001.ubx", "manifest": flight / "manifest.json"}.get(name)
            if damage == "empty_dir":
                (root / "empty").mkdir(exist_ok=True)
                continue
            if target is None or not target.exists():
                continue
            if what == "delete":
                target.unlink()
            elif what == "garbage":
                target.write_bytes(target.read_bytes() + junk)
            elif what == "truncate":
                data = target.read_bytes()
                target.write_bytes(data[: len(data) // 2] + junk)
        argv = ["check", str(flight), *(_path(root, k, "f") for k in extra)]
        if as_json:
            argv.append("--json")
        code = main(argv)
        captured = capsys.readouterr()
        _assert_clean(code, captured.err, "check")
        if "none" in damages and len(set(damages)) == 1 and not extra:
            assert code == 0, captured.out
        if {"delete_events", "delete_idx", "delete_segment"} & set(damages):
            assert code != 0


# -- base and web: their argument parsing ------------------------------------------------------------------------
def _parse(command: str, argv: list[str], capsys: pytest.CaptureFixture[str]) -> object | None:
    """Parsed arguments, or None after asserting a clean usage error."""
    parser = build_parser([command])
    try:
        args = parser.parse_args([command, *argv])
        event("parsed")
        return args
    except SystemExit as exc:
        event("usage error")
        err = capsys.readouterr().err
        assert exc.code == 2 and "Traceback" not in err
        assert err.startswith(f"directgeo: {command}: error: "), err
        return None


def _near_earth(xyz: tuple[float, float, float]) -> bool:
    return EARTH_RADIUS_MIN_M <= math.hypot(*xyz) <= EARTH_RADIUS_MAX_M


@settings(FUZZ, max_examples=60)
@given(position=_mostly(GOOD_POSITIONS, COORDINATES), survey=_mostly(GOOD_NUMBERS, NUMBERS),
       height=_mostly(GOOD_NUMBERS, NUMBERS), station=_mostly(GOOD_NUMBERS, NUMBERS),
       budget=_mostly(GOOD_NUMBERS, NUMBERS), interval=_mostly(GOOD_NUMBERS, NUMBERS),
       baud=_mostly(st.sampled_from(["57600", "1200"]), NUMBERS))
def test_base_arguments(position: str | None, survey: str | None, height: str | None, station: str | None,
                        budget: str | None, interval: str | None, baud: str | None,
                        capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["--port", "/dev/ttyS9", "--radio", "/dev/ttyS8"]
    for option, value in (("--position", position), ("--survey-in", survey), ("--antenna-height", height),
                          ("--station-id", station), ("--budget", budget), ("--obs-interval", interval),
                          ("--radio-baud", baud)):
        if value is not None:
            argv.append(f"{option}={value}")
    args = _parse("base", argv, capsys)
    if args is None:
        return
    assert (args.position is None) != (args.survey_in is None)
    if args.position is not None:
        assert _near_earth(args.position)
    else:
        assert 0 < args.survey_in <= 86400
    assert 0 <= args.antenna_height <= 100 and 0 <= args.station_id <= 4095
    # (not given: None, the [base] settings' value then applies)
    assert args.budget is None or (math.isfinite(args.budget) and args.budget > 0)
    assert args.obs_interval is None or 0 < args.obs_interval <= 3600
    assert 1200 <= args.radio_baud <= 4_000_000


@settings(FUZZ, max_examples=40)
@given(port=_mostly(st.sampled_from(["8080", "1", "65535"]), NUMBERS), host=st.none() | _text, status=st.none() | st.sampled_from(PATH_KINDS))
def test_web_arguments(port: str | None, host: str | None, status: str | None,
                       capsys: pytest.CaptureFixture[str]) -> None:
    argv = []
    if port is not None:
        argv.append(f"--port={port}")
    if host is not None:
        argv.append(f"--host={host}")
    if status is not None:
        argv.append(f"--status={_path(Path('/tmp'), status, 'status.json')}")
    args = _parse("web", argv, capsys)
    if args is not None:
        assert isinstance(args.port, int) and 1 <= args.port <= 65535
