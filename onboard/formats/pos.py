"""RTKLIB-compatible `.pos` solution files: writer (xyz or llh, week/tow or calendar GPST, optional
velocity columns) and a reader for the same variants (used by `onboard rtk` and the ground app).

Layout follows RTKLIB solution.c outsols()/outsolheads(): `%` header lines, a column-title line starting
`%  GPST`, then one line per epoch; standard deviations are √var, cross terms sign(c)·√|c| (RTKLIB sqvar).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np
import numpy.typing as npt

from onboard.errors import InputError
from onboard.formats.atomic import atomic_output
from onboard.gnsstime import GpsTime, gpst_from_calendar
from onboard.rtk.geodesy import ecef_to_llh, enu_rotation, llh_to_ecef
from onboard.rtk.types import Q_NONE, Solution

_XYZ_TITLES = ("x-ecef(m)", "y-ecef(m)", "z-ecef(m)", "Q", "ns", "sdx(m)", "sdy(m)", "sdz(m)", "sdxy(m)",
               "sdyz(m)", "sdzx(m)", "age(s)", "ratio")
_LLH_TITLES = ("latitude(deg)", "longitude(deg)", "height(m)", "Q", "ns", "sdn(m)", "sde(m)", "sdu(m)",
               "sdne(m)", "sdeu(m)", "sdun(m)", "age(s)", "ratio")
_VEL_XYZ = ("vx(m/s)", "vy(m/s)", "vz(m/s)", "sdvx", "sdvy", "sdvz", "sdvxy", "sdvyz", "sdvzx")
_VEL_ENU = ("vn(m/s)", "ve(m/s)", "vu(m/s)", "sdvn", "sdve", "sdvu", "sdvne", "sdveu", "sdvun")


def _sqvar(c: float) -> float:
    """RTKLIB sqvar(): sign-preserving square root of a (co)variance."""
    return math.copysign(math.sqrt(abs(c)), c) if math.isfinite(c) else 0.0


def _cov_terms(cov: npt.NDArray[np.float64], order: tuple[int, int, int]) -> list[float]:
    """sd1 sd2 sd3 sd12 sd23 sd31 from a 3×3 covariance in the given axis order."""
    a, b, c = order
    m = cov.tolist()  # Python floats: the same values, without a numpy scalar per entry and test (per line)
    return [_sqvar(m[a][a]), _sqvar(m[b][b]), _sqvar(m[c][c]), _sqvar(m[a][b]), _sqvar(m[b][c]), _sqvar(m[c][a])]


def format_time(t: GpsTime, calendar: bool) -> str:
    """Time column(s): `week tow` (RTKLIB timeform tow) or `yyyy/mm/dd hh:mm:ss.sss` GPST."""
    if not calendar:
        return f"{t.week:4d} {t.tow_ns / 1e9:10.3f}"
    ms = round(t.total_ns / 1e6)
    d = GpsTime.from_total_ns(ms * 1_000_000).to_gpst_datetime()
    return f"{d:%Y/%m/%d %H:%M:%S}.{d.microsecond // 1000:03d}"


def pos_header_lines(llh: bool = False, velocity: bool = False, calendar: bool = False,
                     info: Sequence[str] = ()) -> list[str]:
    """The `%` header: free information lines, then the column-title line."""
    lines = [f"% {s}" for s in info]
    titles: tuple[str, ...] = _LLH_TITLES if llh else _XYZ_TITLES
    if velocity:
        titles = titles + (_VEL_ENU if llh else _VEL_XYZ)
    time_title = "%  GPST                 " if calendar else "%  GPST          "
    lines.append(time_title + " ".join(f"{t:>14s}" if i < 3 else f"{t:>8s}" for i, t in enumerate(titles)))
    return lines


def format_solution(sol: Solution, llh: bool = False, velocity: bool = False, calendar: bool = False) -> str:
    """One .pos data line for `sol`."""
    parts = [format_time(sol.time, calendar)]
    if llh:
        lat, lon, h = ecef_to_llh(sol.pos_ecef_m)
        rot = enu_rotation(lat, lon)
        cov_enu = rot @ sol.cov_pos_m2 @ rot.T
        parts.append(f"{math.degrees(lat):14.9f} {math.degrees(lon):14.9f} {h:10.4f}")
        sds = _cov_terms(cov_enu, (1, 0, 2))  # n, e, u
    else:
        x, y, z = sol.pos_ecef_m.tolist()
        parts.append(f"{x:14.4f} {y:14.4f} {z:14.4f}")
        sds = _cov_terms(sol.cov_pos_m2, (0, 1, 2))
    parts.append(f"{sol.q:3d} {sol.ns:3d}")
    parts.append(" ".join(f"{v:8.4f}" for v in sds))
    parts.append(f"{sol.age_s:6.2f} {sol.ratio:6.1f}")
    if velocity:
        vel = np.nan_to_num(sol.vel_ecef_m_s)
        cov_v = np.nan_to_num(sol.cov_vel_m2_s2)
        if llh:
            lat, lon, _ = ecef_to_llh(sol.pos_ecef_m)
            rot = enu_rotation(lat, lon)
            venu = rot @ vel
            cv = rot @ cov_v @ rot.T
            parts.append(f"{venu[1]:10.5f} {venu[0]:10.5f} {venu[2]:10.5f}")
            parts.append(" ".join(f"{v:9.5f}" for v in _cov_terms(cv, (1, 0, 2))))
        else:
            parts.append(f"{vel[0]:10.5f} {vel[1]:10.5f} {vel[2]:10.5f}")
            parts.append(" ".join(f"{v:9.5f}" for v in _cov_terms(cov_v, (0, 1, 2))))
    return " ".join(parts)


def write_pos(out: str | Path | IO[str], solutions: Iterable[Solution], header: Sequence[str] = (),
              llh: bool = False, velocity: bool = False, calendar: bool = False) -> int:
    """Write solutions as an RTKLIB .pos file (path or open text file); returns the number of lines written.

    A path is written atomically (`onboard.formats.atomic`: a failure leaves the previous file as it was).
    Raises ValueError for a solution that is no position (Q_NONE, or a coordinate not finite): a row that a
    reader would take for an antenna position must be one (nothing is written under the path then).
    """
    if isinstance(out, (str, Path)):
        with atomic_output(out, "w", encoding="ascii") as f:
            return write_pos(f, solutions, header, llh, velocity, calendar)
    for line in pos_header_lines(llh, velocity, calendar, header):
        out.write(line + "\n")
    n = 0
    for sol in solutions:
        if not is_position(sol):
            raise ValueError(f"solution at {sol.time} (Q={sol.q}) has no position: not written to a .pos file")
        out.write(format_solution(sol, llh, velocity, calendar) + "\n")
        n += 1
    return n


def is_position(sol: Solution) -> bool:
    """True when `sol` carries a position (Q is not Q_NONE and every ECEF coordinate is finite)."""
    x, y, z = sol.pos_ecef_m.tolist()
    return sol.q != Q_NONE and math.isfinite(x) and math.isfinite(y) and math.isfinite(z)


@dataclass
class PosTrack:
    """Contents of a .pos file, one row per epoch.

    `time` GPS times; `pos_ecef_m` (n,3) (converted from llh when the file is llh); `q`, `ns` (n,);
    `sd_m` (n,6) the six standard-deviation columns as written (x,y,z,xy,yz,zx or n,e,u,ne,eu,un);
    `age_s`, `ratio` (n,); `vel_m_s` (n,3) as written (ECEF, or n,e,u for llh files) or None.
    """

    time: list[GpsTime]
    pos_ecef_m: npt.NDArray[np.float64]
    q: npt.NDArray[np.int64]
    ns: npt.NDArray[np.int64]
    sd_m: npt.NDArray[np.float64]
    age_s: npt.NDArray[np.float64]
    ratio: npt.NDArray[np.float64]
    vel_m_s: npt.NDArray[np.float64] | None
    llh: bool

    @property
    def tow_s(self) -> npt.NDArray[np.float64]:
        """Seconds of week of each row."""
        return np.array([t.tow_s for t in self.time])


def read_pos(path: str | Path) -> PosTrack:
    """Read an RTKLIB .pos file (xyz or llh, week/tow or calendar GPST, with or without velocity columns)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="ascii", errors="replace")
    except OSError as exc:
        raise InputError(f"cannot read solution file {path}: {exc}") from exc
    llh: bool | None = None
    times: list[GpsTime] = []
    rows: list[list[float]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if line.startswith("%"):
            if "x-ecef" in line:
                llh = False
            elif "latitude" in line:
                llh = True
            if "UTC" in line.split()[1:2]:
                raise InputError(f"{path}:{lineno}: UTC time tags are not supported, write GPST")
            continue
        tokens = line.split()
        if not tokens:
            continue
        try:
            if "/" in tokens[0]:
                y, mo, d = (int(v) for v in tokens[0].split("/"))
                hh, mi, ss = tokens[1].split(":")
                t = gpst_from_calendar(y, mo, d, int(hh), int(mi), round(float(ss) * 1e9))
            else:
                t = GpsTime.from_week_tow_s(int(tokens[0]), float(tokens[1]))
            values = [float(v) for v in tokens[2:]]
        except ValueError as exc:
            raise InputError(f"{path}:{lineno}: malformed solution line: {exc}") from exc
        if len(values) not in (13, 22):
            raise InputError(f"{path}:{lineno}: expected 13 or 22 value columns, found {len(values)}")
        if rows and len(values) != len(rows[0]):
            raise InputError(f"{path}:{lineno}: column count changed from {len(rows[0])} to {len(values)}")
        times.append(t)
        rows.append(values)
    if llh is None:
        raise InputError(f"{path}: no column-title line (%  GPST ... x-ecef / latitude) found")
    arr = np.array(rows, dtype=float).reshape(len(rows), -1) if rows else np.zeros((0, 13))
    pos = arr[:, 0:3].copy()
    if llh and len(pos):
        pos = np.array([llh_to_ecef(math.radians(a), math.radians(b), h) for a, b, h in pos])
    return PosTrack(
        time=times, pos_ecef_m=pos, q=arr[:, 3].astype(np.int64), ns=arr[:, 4].astype(np.int64),
        sd_m=arr[:, 5:11], age_s=arr[:, 11], ratio=arr[:, 12],
        vel_m_s=arr[:, 13:16] if arr.shape[1] >= 22 else None, llh=llh,
    )
