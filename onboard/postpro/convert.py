"""`python -m onboard convert INPUT... -o DIR`: UBX logs (plain or .gz) or flight journals -> RINEX 3.04.

For each input writes `DIR/<stem>.obs` (L1 code, phase, Doppler, C/N0 of every system present, LLI by RTKLIB's
u-blox rules, flag-5 event records for TIM-TM2 marks in GPS time) and `DIR/<stem>.nav` (GPS LNAV ephemerides
from RXM-SFRB/SFRBX subframes and AID-EPH replies), and prints what it wrote. Unreadable input: a message on
stderr and exit code 2, no traceback. Entry points for `onboard/__main__.py`: `add_convert_parser(subparsers)`
and `convert_main(argv)`.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import logging
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from onboard.errors import InputError
from onboard.formats.rinex_write import ObsHeaderInfo, ObsWriteSummary, write_nav, write_obs
from onboard.receiver.decode import (
    DecodeStats,
    LockTracker,
    MonVer,
    NavFix,
    SubframeWords,
    TimeMarks,
    ephemeris_from_subframe,
    iter_decoded,
    iter_file_bytes,
)
from onboard.rtk.types import CameraMark, Ephemeris, ObsEpoch

log = logging.getLogger(__name__)

EXIT_OK = 0
EXIT_INPUT_ERROR = 2
EDGES = ("falling", "rising", "both")


@dataclass(frozen=True)
class ConvertOptions:
    """What `convert` writes: `mark_edges` which TIM-TM2 edges become event records ("falling" = flash from a
    hot-shoe, as RTKLIB), `marker_name` for the header (default: the input stem)."""

    mark_edges: str = "falling"
    marker_name: str | None = None


@dataclass
class Collected:
    """Everything one input contributed (pure data, filled by `collect`)."""

    epochs: list[ObsEpoch] = field(default_factory=list)
    marks: list[CameraMark] = field(default_factory=list)
    ephemerides: list[Ephemeris] = field(default_factory=list)
    mon_ver: MonVer | None = None
    fixes_ecef_m: list[tuple[float, float, float]] = field(default_factory=list)
    leap_s: int | None = None
    stats: DecodeStats = field(default_factory=DecodeStats)


def collect(chunks: Iterator[bytes], options: ConvertOptions = ConvertOptions()) -> Collected:
    """Decode a byte stream into what the RINEX writers need (epochs with RTKLIB's LLI, marks, ephemerides)."""
    from onboard.rtk.lnav import LnavAssembler

    out = Collected()
    tracker = LockTracker()
    assembler = LnavAssembler()
    edges = ("falling", "rising") if options.mark_edges == "both" else (options.mark_edges,)
    last_time = None
    for item in iter_decoded(chunks, out.stats):
        if isinstance(item, ObsEpoch):
            if last_time is not None and item.time <= last_time:
                log.warning("epoch %s not after %s: dropped", item.time, last_time)
                continue
            last_time = item.time
            out.epochs.append(tracker.update(item))
            if item.leap_s is not None:
                out.leap_s = item.leap_s
        elif isinstance(item, TimeMarks):
            out.marks += [m for m in item.marks if m.edge in edges]
        elif isinstance(item, SubframeWords):
            eph = ephemeris_from_subframe(assembler, item, out.stats.reference_week)
            if eph is not None:
                out.ephemerides.append(eph)
        elif isinstance(item, Ephemeris):
            out.ephemerides.append(item)
        elif isinstance(item, MonVer):
            out.mon_ver = item
        elif isinstance(item, NavFix) and (item.fix_type is None or item.fix_type >= 3):
            out.fixes_ecef_m.append(item.pos_ecef_m)
    return out


def header_info(collected: Collected, marker: str, when_utc: _dt.datetime) -> ObsHeaderInfo:
    """The observation header for what was collected (approx. position = median of the receiver's 3D fixes)."""
    pos = (0.0, 0.0, 0.0)
    if collected.fixes_ecef_m:
        med = np.median(np.array(collected.fixes_ecef_m), axis=0)
        pos = (float(med[0]), float(med[1]), float(med[2]))
    rec_type = rec_vers = ""
    if collected.mon_ver is not None:
        model = next((e.split("=", 1)[1] for e in collected.mon_ver.extensions if e.startswith("MOD=")), "")
        rec_type = f"U-BLOX {model}".strip()
        rec_vers = collected.mon_ver.sw
    return ObsHeaderInfo(
        marker_name=marker, receiver_type=rec_type, receiver_version=rec_vers, approx_pos_ecef_m=pos,
        program="directgeo convert", date_utc=when_utc.strftime("%Y%m%d %H%M%S UTC"),
        comments=("receiver time tags, not clock-corrected",
                  "event records (flag 5): TIM-TM2 time marks in GPS time"),
        glo_fcn=dict(collected.stats.glo_fcn),
    )


def output_stem(path: Path) -> str:
    """`rover.ubx.gz` -> `rover`; a flight directory -> its name."""
    name = path.name
    for suffix in (".gz", ".ubx", ".log", ".bin"):
        if name.lower().endswith(suffix):
            name = name[: -len(suffix)]
    return name or "out"


@dataclass(frozen=True)
class ConvertResult:
    """What one input became."""

    obs_path: Path
    nav_path: Path
    obs: ObsWriteSummary
    ephemerides: int
    stats: DecodeStats


def input_chunks(path: Path) -> Iterator[bytes]:
    """Bytes of an input: a flight journal directory (segments in order) or a UBX log (gzip accepted)."""
    if path.is_dir():
        from onboard.logger.journal import iter_journal_bytes, list_segments

        if not list_segments(path):
            raise InputError(f"{path}: no journal segments (*.ubx) in this directory")
        return iter(iter_journal_bytes(path))
    if not path.exists():
        raise InputError(f"{path}: no such file")
    return iter_file_bytes(path)


def convert_one(path: Path, out_dir: Path, options: ConvertOptions = ConvertOptions(),
                progress: Callable[[int], None] | None = None,
                now_utc: _dt.datetime | None = None) -> ConvertResult:
    """Convert one input to `<stem>.obs` and `<stem>.nav` in `out_dir`. Raises InputError on unusable input
    (nothing is written then)."""
    chunks = input_chunks(path)

    def counted() -> Iterator[bytes]:
        for chunk in chunks:
            if progress is not None:
                progress(len(chunk))
            yield chunk

    collected = collect(counted(), options)
    if not collected.epochs and not collected.ephemerides:
        raise InputError(f"{path}: no raw observations or ephemerides found "
                         f"({collected.stats.frames} UBX frames, {collected.stats.failures} undecodable)")
    stem = output_stem(path)
    when = now_utc or _dt.datetime.now(_dt.UTC)
    info = header_info(collected, options.marker_name or stem, when)
    out_dir.mkdir(parents=True, exist_ok=True)
    obs_path = out_dir / f"{stem}.obs"
    nav_path = out_dir / f"{stem}.nav"
    with open(obs_path, "w", encoding="ascii", newline="\n") as f:
        summary = write_obs(f, collected.epochs, collected.marks, info)
    with open(nav_path, "w", encoding="ascii", newline="\n") as f:
        n_eph = write_nav(f, collected.ephemerides, program="directgeo convert",
                          date_utc=info.date_utc, leap_s=collected.leap_s)
    return ConvertResult(obs_path, nav_path, summary, n_eph, collected.stats)


def add_convert_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:  # type: ignore[type-arg]
    """Register `convert` on the `python -m onboard` sub-command parser; sets `func=convert_main_args`."""
    p = subparsers.add_parser("convert", help="UBX logs or flight journals -> RINEX 3.04 .obs/.nav",
                              description=__doc__.split("\n\n")[0])
    _add_arguments(p)
    p.set_defaults(func=convert_main_args)
    return p


def _add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("inputs", nargs="+", type=Path, metavar="INPUT",
                   help="UBX log (.ubx/.log, .gz accepted) or flight journal directory")
    p.add_argument("-o", "--out-dir", type=Path, required=True, help="output directory")
    p.add_argument("--marks", choices=EDGES, default="falling",
                   help="TIM-TM2 edges written as event records (default: falling = flash)")
    p.add_argument("--marker", default=None, help="MARKER NAME (default: input stem)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar even on a terminal")


def convert_main_args(args: argparse.Namespace) -> int:
    """Run `convert` with parsed arguments; returns the exit code (2 when any input was unusable)."""
    options = ConvertOptions(mark_edges=args.marks, marker_name=args.marker)
    code = EXIT_OK
    for path in args.inputs:
        try:
            result = _run_one(path, args.out_dir, options, show_progress=not args.no_progress)
        except InputError as exc:
            print(f"convert: error: {exc}", file=sys.stderr)
            code = EXIT_INPUT_ERROR
            continue
        except OSError as exc:
            print(f"convert: error: cannot write to {args.out_dir}: {exc.strerror or exc}", file=sys.stderr)
            return EXIT_INPUT_ERROR
        s = result.obs
        systems = ", ".join(f"{k} {len(v)}" for k, v in sorted(s.satellites.items()))
        print(f"{result.obs_path}: {s.epochs} epochs, {s.satellite_count} satellites ({systems}), "
              f"{s.events} time marks")
        print(f"{result.nav_path}: {result.ephemerides} GPS ephemerides")
        st = result.stats
        if st.failures:
            print(f"{path}: {st.failures} of {st.frames} UBX frames did not decode (skipped)")
    return code


def _run_one(path: Path, out_dir: Path, options: ConvertOptions, show_progress: bool) -> ConvertResult:
    if not (show_progress and sys.stderr.isatty()) or path.is_dir():
        return convert_one(path, out_dir, options)
    from tqdm import tqdm

    total = path.stat().st_size if path.exists() else None
    gz = path.suffix.lower() == ".gz"
    with tqdm(total=None if gz else total, unit="B", unit_scale=True, desc=path.name, leave=False) as bar:
        return convert_one(path, out_dir, options, progress=bar.update)


def convert_main(argv: Sequence[str] | None = None) -> int:
    """`convert` as a standalone command line (argv without the program and sub-command names)."""
    parser = argparse.ArgumentParser(prog="python -m onboard convert", description=__doc__.split("\n\n")[0])
    _add_arguments(parser)
    return convert_main_args(parser.parse_args(argv))


if __name__ == "__main__":
    logging.basicConfig(level=logging.WARNING)
    sys.exit(convert_main())
