"""`python -m onboard convert INPUT... -o DIR`: UBX logs (plain or .gz) or flight journals -> RINEX 3.04.

For each input writes `DIR/<stem>.obs` (L1 code, phase, Doppler, C/N0 of every system present, LLI by RTKLIB's
u-blox rules, flag-5 event records for TIM-TM2 marks in GPS time) and `DIR/<stem>.nav` (GPS LNAV ephemerides
from RXM-SFRB/SFRBX subframes and AID-EPH replies), both atomically (a failure leaves the previous pair), and
prints what it wrote. What the input lacks is said on stderr: missing or truncated journal segments, regions
that hold no valid frame (with byte offsets), torn tails, a damaged gzip salvaged up to the damage. Exit codes:
0 written, 1 cannot write, 2 unusable arguments or input. Entry points for `onboard/__main__.py`:
`add_convert_parser(subparsers)` and `convert_main(argv)`.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import logging
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from onboard.cmdline import (
    EXIT_FAILURE,
    EXIT_OK,
    EXIT_USAGE,
    CommandParser,
    add_command,
    output_dir,
    report_error,
    warning_line,
)
from onboard.errors import InputError
from onboard.formats.atomic import atomic_output
from onboard.formats.rinex_write import ObsHeaderInfo, ObsWriteSummary, write_nav, write_obs
from onboard.postpro.inputs import input_chunks
from onboard.receiver.decode import (
    DecodeStats,
)
from onboard.receiver.ubx_collect import Collected, collect, describe_unframed

log = logging.getLogger(__name__)

COMMAND = "convert"
EXIT_INPUT_ERROR = EXIT_USAGE
EDGES = ("falling", "rising", "both")


@dataclass(frozen=True)
class ConvertOptions:
    """What `convert` writes: `mark_edges` which TIM-TM2 edges become event records ("falling" = flash from a
    hot-shoe, as RTKLIB), `marker_name` for the header (default: the input stem)."""

    mark_edges: str = "falling"
    marker_name: str | None = None


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


def convert_one(path: Path, out_dir: Path, options: ConvertOptions = ConvertOptions(),
                progress: Callable[[int], None] | None = None,
                now_utc: _dt.datetime | None = None, warn: Callable[[str], None] | None = None,
                stem: str | None = None) -> ConvertResult:
    """Convert one input to `<stem>.obs` and `<stem>.nav` in `out_dir` (stem: `output_stem(path)` by default).

    Both files are written atomically and renamed only once both are complete, so a failure (a full disk)
    leaves the previous pair. What the input lacks (gaps, corrupt regions, torn tails) goes to `warn`
    (default: logged warnings). Raises InputError on unusable input (nothing is written then), OSError when
    the output cannot be written."""
    report = warn if warn is not None else log.warning
    chunks, places = input_chunks(path, report)

    def counted() -> Iterator[bytes]:
        for chunk in chunks:
            if progress is not None:
                progress(len(chunk))
            yield chunk

    collected = collect(counted(), options.mark_edges)
    for message in describe_unframed(collected, places):
        report(message)
    if not collected.epochs and not collected.ephemerides:
        raise InputError(f"{path}: no raw observations or ephemerides found "
                         f"({collected.stats.frames} UBX frames, {collected.stats.failures} undecodable)")
    stem = stem or output_stem(path)
    when = now_utc or _dt.datetime.now(_dt.UTC)
    # the header is ASCII (RINEX): a stem with other characters is written with "?" in their place, 60 at most
    marker = options.marker_name or stem.encode("ascii", "replace").decode("ascii")[:60]
    info = header_info(collected, marker, when)
    out_dir.mkdir(parents=True, exist_ok=True)
    obs_path = out_dir / f"{stem}.obs"
    nav_path = out_dir / f"{stem}.nav"
    with atomic_output(obs_path, "w", encoding="ascii") as fo, atomic_output(nav_path, "w", encoding="ascii") as fn:
        summary = write_obs(fo, collected.epochs, collected.marks, info)
        n_eph = write_nav(fn, collected.ephemerides, program="directgeo convert",
                          date_utc=info.date_utc, leap_s=collected.leap_s)
        for f in (fo, fn):  # both complete on disk before either replaces its previous version
            f.flush()
            os.fsync(f.fileno())
    return ConvertResult(obs_path, nav_path, summary, n_eph, collected.stats)


DESCRIPTION = """\
Convert the receiver's raw UBX data (a flight's journal folder, or a UBX log, .gz accepted) to RINEX 3.04:
<stem>.obs with the L1 code (m), phase (cycles), Doppler (Hz) and C/N0 (dB-Hz) of every system present and
one event record (epoch flag 5, GPS time) per camera time mark, and <stem>.nav with the GPS ephemerides the
receiver decoded. Files appear under their names only once complete; what the input lacks (missing
segments, corrupt regions, torn tails, a damaged gzip kept up to the damage) is reported as a warning."""

EPILOG = """\
examples:
  python -m onboard convert /data/flights/flight-20260501T101500Z -o rinex/
  python -m onboard convert rover.ubx.gz base.ubx -o rinex/ --marks both

exit codes: 0 written, 1 cannot write (full disk, permissions), 2 bad arguments or an unusable input
(the other inputs are still converted)."""


def add_convert_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:  # type: ignore[type-arg]
    """Register `convert` on the `python -m onboard` sub-command parser; sets `func=convert_main_args`."""
    p = add_command(subparsers, COMMAND, summary="UBX logs or flight journals -> RINEX 3.04 .obs/.nav",
                    description=DESCRIPTION, epilog=EPILOG)
    _add_arguments(p)
    p.set_defaults(func=convert_main_args)
    return p


def _add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("inputs", nargs="+", type=Path, metavar="INPUT",
                   help="UBX log (.ubx/.log, .gz accepted) or flight journal directory (repeatable)")
    p.add_argument("-o", "--out-dir", type=output_dir, required=True, metavar="DIR",
                   help="output directory (created if missing); <stem>.obs/.nav of an input named <stem>")
    p.add_argument("--marks", choices=EDGES, default="falling",
                   help="TIM-TM2 edges written as event records: falling (default: the flash, as RTKLIB), "
                        "rising or both")
    p.add_argument("--marker", default=None, metavar="NAME", type=marker_name,
                   help="MARKER NAME in the observation header, up to 60 ASCII characters (default: the input's "
                        "stem)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar even on a terminal")


def marker_name(text: str) -> str:
    """argparse `type=` for a RINEX MARKER NAME: 1–60 printable ASCII characters (the header field is A60)."""
    if not 0 < len(text) <= 60 or not all(" " <= c <= "~" for c in text):
        raise argparse.ArgumentTypeError(f"{text!r}: must be 1–60 printable ASCII characters (RINEX MARKER NAME)")
    return text


def _stems(inputs: list[Path]) -> dict[Path, str] | str:
    """The output stem of each input, or the message refusing two inputs that would write the same files."""
    seen: dict[str, Path] = {}
    for path in inputs:
        stem = output_stem(path)
        if stem in seen and seen[stem].resolve() != path.resolve():
            return (f"{seen[stem]} and {path} would both write {stem}.obs/.nav: convert them into different "
                    f"-o directories (nothing written)")
        seen.setdefault(stem, path)
    return {path: output_stem(path) for path in inputs}


def convert_main_args(args: argparse.Namespace) -> int:
    """Run `convert` with parsed arguments; returns the exit code (2 when any input was unusable, 1 when an
    output could not be written)."""
    options = ConvertOptions(mark_edges=args.marks, marker_name=args.marker)
    stems = _stems(list(args.inputs))
    if isinstance(stems, str):
        return report_error(COMMAND, stems, EXIT_USAGE)
    code = EXIT_OK
    done: set[Path] = set()

    def warn(message: str) -> None:
        print(warning_line(COMMAND, message), file=sys.stderr)

    for path in args.inputs:
        if path.resolve() in done:
            continue  # the same input twice: converted once
        done.add(path.resolve())
        try:
            result = _run_one(path, args.out_dir, options, show_progress=not args.no_progress, warn=warn)
        except InputError as exc:
            code = report_error(COMMAND, str(exc), EXIT_INPUT_ERROR)
            continue
        except OSError as exc:
            if exc.filename and not _is_within(Path(exc.filename), Path(args.out_dir)):
                return report_error(COMMAND, f"cannot read {exc.filename}: {exc.strerror or exc}", EXIT_FAILURE)
            return report_error(COMMAND, f"cannot write {stems[path]}.obs/.nav in {args.out_dir}: "
                                f"{exc.strerror or exc} (the previous files, if any, are unchanged)", EXIT_FAILURE)
        s = result.obs
        systems = ", ".join(f"{k} {len(v)}" for k, v in sorted(s.satellites.items()))
        print(f"{result.obs_path}: {s.epochs} epochs, {s.satellite_count} satellites ({systems}), "
              f"{s.events} time marks")
        print(f"{result.nav_path}: {result.ephemerides} GPS ephemerides")
        st = result.stats
        if st.failures:
            warn(f"{path}: {st.failures} of {st.frames} UBX frames did not decode (skipped)")
    return code


def _is_within(path: Path, directory: Path) -> bool:
    """True when `path` is `directory` or inside it (an OSError there is a failure to write the output)."""
    p, d = path.resolve(), directory.resolve()
    return p == d or d in p.parents


def _run_one(path: Path, out_dir: Path, options: ConvertOptions, show_progress: bool,
             warn: Callable[[str], None]) -> ConvertResult:
    if not (show_progress and sys.stderr.isatty()) or path.is_dir():
        return convert_one(path, out_dir, options, warn=warn)
    from tqdm import tqdm

    total = path.stat().st_size if path.exists() else None
    gz = path.suffix.lower() == ".gz"
    with tqdm(total=None if gz else total, unit="B", unit_scale=True, desc=path.name, leave=False) as bar:
        return convert_one(path, out_dir, options, progress=bar.update, warn=warn)


def convert_main(argv: Sequence[str] | None = None) -> int:
    """`convert` as a standalone command line (argv without the program and sub-command names)."""
    parser = CommandParser(prog="python -m onboard convert", description=DESCRIPTION, epilog=EPILOG,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    _add_arguments(parser)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    return convert_main_args(args)


if __name__ == "__main__":
    logging.basicConfig(level=logging.WARNING)
    sys.exit(convert_main())
