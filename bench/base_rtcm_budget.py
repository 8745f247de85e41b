"""Base-station RTCM budget on real u-blox logs: bytes/s per message type for MSM4/5/7, vs a real u-blox base.

    PYTHONPATH=. python bench/base_rtcm_budget.py [--budget 1000] [--log NAME ...]

Runs `onboard.base.station.BaseCore` (the MSM path of `python -m onboard base`) on the RXM-RAWX and RXM-SFRBX of
the u-blox M8P logs in ../shared/data/gnss/ublox-m8p-galway-2018/raw (GPS + GLONASS + QZSS L1; the base log has
RAWX only every ~3–4 s, so the 1 Hz rover log of the same place stands in for a 1 Hz base too) and on the 75 s
u-blox F9 log of ../shared/data/ubx (GPS + GLONASS + Galileo + BeiDou; its L1-band signals only, as an M8T
would track: the MSM encoder keeps one L1 signal per satellite), once per MSM kind
with the byte budget enforced and once with no limit (what the messages would take). Prints per message type the
bytes per second (mean over the seconds of the run, 99th percentile, maximum), the total against the budget, what
was deferred, and how long it took to send every satellite's ephemeris once (from the first epoch with
corrections). The "peer" rows: the RTCM3 that the M8P base itself sent (its rtcm3/ folder: 1005, 1077, 1087,
1230), per second of the MSM epochs it carries.
"""

from __future__ import annotations

import argparse
import collections
import math
import sys
from pathlib import Path

import numpy as np

from onboard.base.station import BaseCore, BaseOptions
from onboard.gnsstime import GpsTime
from onboard.receiver.decode import DecodeError, decode_rxm_rawx, iter_file_bytes
from onboard.receiver.framing import Frame, Protocol, StreamFramer, iter_frames
from onboard.receiver.rtcm import RtcmDecoder
from onboard.receiver.rtcm_nav import decode_nav_message
from onboard.receiver.sfrbx import iter_navigation
from onboard.rtk.navstore import sat_key

SHARED = Path(__file__).resolve().parents[1].parent / "shared/data"
M8P = SHARED / "gnss/ublox-m8p-galway-2018"
LOGS = {"rover-20181004-1237": (M8P / "raw/rover-20181004-1237.ubx.gz", (3774089.2120, -601661.6157, 5089321.2474)),
        "base-20181004-1236": (M8P / "raw/base-20181004-1236.ubx.gz", (3774089.2120, -601661.6157, 5089321.2474)),
        "f9-testobsnavdata": (SHARED / "ubx/pygnssutils_pygpsdata_testobsnavdata.log", (0.0, 0.0, 6_356_752.0))}
"""Log → (path, base position ECEF m): the M8P base's RTCM 1005 of the session; for the F9 log, which carries no
position, a stand-in (the size of 1006, all this bench measures, does not depend on it)."""
EPH_MESSAGES = (1019, 1020, 1042, 1044, 1046)


def message_number(frame: bytes) -> int:
    """DF002 of an RTCM3 frame."""
    return (frame[3] << 4) | (frame[4] >> 4)


def ubx_frames(path: Path) -> list[Frame]:
    """The UBX frames of a (gzipped) log."""
    framer = StreamFramer(frozenset({Protocol.UBX}))
    out: list[Frame] = []
    for chunk in iter_file_bytes(path):
        out.extend(framer.feed(chunk))
    return out


def run_base(frames: list[Frame], options: BaseOptions, preload: list | None = None
             ) -> tuple[BaseCore, list[tuple[float, int, bytes]], set[tuple[int, int]]]:
    """The base core over a log's frames (after `preload` ephemerides, if any): (GPS s, message number, frame)
    of every frame it sent, and the satellites (gnssId, svId) of the first epoch it sent."""
    core = BaseCore(options)
    for eph in preload or ():
        core.on_item(eph)
    sent: list[tuple[float, int, bytes]] = []
    first_sats: set[tuple[int, int]] = set()
    for f in frames:
        key = (f.msg_class, f.msg_id)
        if key == (0x02, 0x15):
            try:
                epoch = decode_rxm_rawx(f.payload)
            except DecodeError:
                continue
            if epoch is None:
                continue
            t_s = epoch.time.total_ns / 1e9
            out = core.on_item(epoch)
            if out and not sent:
                first_sats = {(int(g), int(v)) for g, v in zip(epoch.gnss_id, epoch.sv_id) if g in (0, 2, 3, 5, 6)}
            sent += [(t_s, message_number(raw), raw) for _, raw in out]
        else:
            core.on_frame(f, 0.0)
    return core, sent, first_sats


def per_second(sent: list[tuple[float, int, bytes]]) -> tuple[int, dict[int, np.ndarray]]:
    """Number of seconds spanned and, per message number, the bytes in each second (zeros included)."""
    if not sent:
        return 0, {}
    t0 = math.floor(sent[0][0])
    n = math.floor(sent[-1][0]) - t0 + 1
    out: dict[int, np.ndarray] = collections.defaultdict(lambda: np.zeros(n))
    for t_s, num, raw in sent:
        out[num][math.floor(t_s) - t0] += len(raw)
    return n, dict(out)


def ephemeris_first_sent_s(sent: list[tuple[float, int, bytes]]) -> dict[tuple[int, int], float]:
    """(gnssId, svId) → s from the first frame sent until that satellite's ephemeris first went out."""
    if not sent:
        return {}
    t0 = sent[0][0]
    ref = GpsTime.from_total_ns(round(t0 * 1e9))
    rtcm = RtcmDecoder()
    first: dict[tuple[int, int], float] = {}
    for t_s, num, raw in sent:
        if num not in EPH_MESSAGES:
            continue
        frame = iter_frames(raw)[0]
        eph = rtcm.decode(frame, ref) if num == 1019 else decode_nav_message(frame, ref, 18)
        assert eph is not None
        first.setdefault(sat_key(eph), t_s - t0)  # type: ignore[arg-type]
    return first


def stats_rows(label: str, n_s: int, by_type: dict[int, np.ndarray]) -> list[str]:
    rows = []
    total = np.zeros(n_s)
    for num in sorted(by_type):
        v = by_type[num]
        total += v
        rows.append(f"| {label} | {num} | {v.mean():.0f} | {np.percentile(v, 99):.0f} | {v.max():.0f} |")
    rows.append(f"| {label} | **total** | {total.mean():.0f} | {np.percentile(total, 99):.0f} | {total.max():.0f} |")
    return rows


def peer_rows(name: str) -> list[str]:
    """Bytes/s of the M8P base's own RTCM3, each frame in the second of the latest MSM epoch before it."""
    import gzip

    with gzip.open(M8P / "rtcm3" / f"{name}.rtcm3.gz") as fh:
        data = fh.read()
    rtcm = RtcmDecoder()
    ref = GpsTime.from_week_tow_s(2021, 4 * 86400 + 12 * 3600)  # 2018-10-04 12:00 GPST
    sent: list[tuple[float, int, bytes]] = []
    t_s: float | None = None
    for f in iter_frames(data, frozenset({Protocol.RTCM3})):
        if f.msg_id in (1077, 1087):
            rtcm.decode(f, ref)
            if rtcm.last_obs_info is not None:
                t_s = rtcm.last_obs_info.time.total_ns / 1e9
        if t_s is not None:
            sent.append((t_s, f.msg_id, f.raw))
    sent.sort(key=lambda r: r[0])
    n_s, by_type = per_second(sent)
    return stats_rows(f"peer: M8P base {name}", n_s, by_type)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=float, default=BaseOptions.radio_budget_bytes_s, help="B/s")
    ap.add_argument("--log", action="append", choices=sorted(LOGS), help="default: all")
    args = ap.parse_args(argv)
    if not M8P.is_dir():
        print(f"no data set at {M8P}", file=sys.stderr)
        return 1
    logs = args.log or list(LOGS)
    print(f"budget {args.budget:.0f} B/s; bytes per second: mean | p99 | max\n")
    print("| run | message | mean B/s | p99 B/s | max B/s |\n|---|---|---|---|---|")
    notes = []
    for name in logs:
        path, position = LOGS[name]
        frames = ubx_frames(path)
        ephemerides = list(iter_navigation(frames))
        for kind in (4, 5, 7):
            for budget in (args.budget, 1e9):
                opts = BaseOptions(station_id=1, obs_message=f"msm{kind}", position_ecef_m=position,
                                   radio_budget_bytes_s=budget, receiver_descriptor="u-blox NEO-M8P")
                core, sent, _ = run_base(frames, opts)
                n_s, by_type = per_second(sent)
                label = f"{name} MSM{kind} " + (f"{budget:.0f} B/s" if budget < 1e9 else "unlimited")
                for row in stats_rows(label, n_s, by_type):
                    print(row)
                c = core.counts()
                # warm start: every ephemerides of the log known before the first epoch (a base running for a
                # while when the rover's radio comes up): how long until the first epoch's satellites all had one
                _, warm, sats = run_base(frames[: max(len(frames) // 10, 3000)], opts, ephemerides)
                first = ephemeris_first_sent_s(warm)
                missing = sats - set(first)
                t_all = max((first[k] for k in sats if k in first), default=math.nan)
                notes.append(f"{label}: {n_s} s; deferred {c['deferred']}; seconds over budget {c['over_budget_s']}; "
                             f"MSM downgraded {c['obs_downgraded']}; warm start: the {len(sats) - len(missing)} "
                             f"satellites of the first epoch with an ephemeris all sent within {t_all:.0f} s "
                             f"({len(missing)} without a sendable ephemeris)")
    for name in ("base-20181004-1236", "base-20181004-1452"):
        for row in peer_rows(name):
            print(row)
    print()
    for line in notes:
        print("-", line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
