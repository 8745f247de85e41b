"""Satellite position, velocity and clock from Keplerian broadcast ephemerides (GPS LNAV; one evaluation for
Galileo, BeiDou and QZSS too, with their constants: eph_position).

Follows IS-GPS-200 20.3.3.4.3, the Galileo OS SIS ICD 5.1.1, the BeiDou B1I ICD 5.2.4 and RTKLIB ephemeris.c
eph2pos()/eph2clk()/satposs() (read to check constants). EphemerisStore holds GPS; the batched evaluation
(table_states over an EphTable) serves it and the other Keplerian systems of onboard.rtk.navstore alike.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from onboard.gnsstime import BDT_MINUS_GPST_S, NS_PER_S, GpsTime
from onboard.rtk.consts import (
    CLIGHT_M_S,
    F_REL_S_SQRT_M,
    MU_BDS_M3_S2,
    MU_GAL_M3_S2,
    MU_GPS_M3_S2,
    OMEGA_E_BDS_RAD_S,
    OMEGA_E_GAL_RAD_S,
    OMEGA_E_RAD_S,
)
from onboard.rtk.gnss import is_beidou_geo
from onboard.rtk.types import GNSS_BEIDOU, GNSS_GALILEO, GNSS_GPS, GNSS_QZSS, Ephemeris

MAX_EPH_AGE_S = 7200.0 + 60.0
"""Largest |t − toe| for which an ephemeris is used (RTKLIB MAXDTOE for GPS, s)."""

# URA index → σ (m), IS-GPS-200 20.3.3.3.1.3
_URA_M = (2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0, 1536.0, 3072.0, 6144.0)


def ura_sigma_m(ura_index: int) -> float:
    """User range accuracy σ (m) for a URA index (6144 m and beyond for 15 = no accuracy prediction)."""
    return _URA_M[ura_index] if 0 <= ura_index < len(_URA_M) else 6144.0


_SISA_STEPS = ((0.0, 0.01, 0, 50), (0.5, 0.02, 50, 75), (1.0, 0.04, 75, 100), (2.0, 0.16, 100, 126))
"""Galileo SISA index ranges (OS SIS ICD 5.1.12): (first value m, step m, first index, end index)."""
SISA_NAPA = 255
"""Galileo SISA index "no accuracy prediction available"."""


def sisa_sigma_m(index: int) -> float:
    """Galileo signal-in-space accuracy (m) of a SISA index; 6144 m (as an unusable URA) for NAPA/spare."""
    for base, step, first, end in _SISA_STEPS:
        if first <= index < end:
            return base + step * (index - first)
    return 6144.0


def sisa_index_from_m(sisa_m: float) -> int:
    """Galileo SISA index for an accuracy (m), the smallest that covers it (RINEX stores metres); NAPA (255)
    for a negative, NaN or too large value."""
    if sisa_m < 0.0 or math.isnan(sisa_m):
        return SISA_NAPA
    for base, step, first, end in _SISA_STEPS:
        k = first + math.ceil(round((sisa_m - base) / step, 6))
        if k < end:
            return max(k, first)
    return SISA_NAPA


def eph_clock_s(eph: Ephemeris, t: GpsTime) -> float:
    """Satellite clock bias (s) at GPS time `t` without relativity or TGD (RTKLIB eph2clk, one iteration)."""
    dt = t.diff_s(eph.toc)
    for _ in range(2):
        dt = dt - (eph.af0_s + eph.af1_s_s * dt + eph.af2_s_s2 * dt * dt)
    return eph.af0_s + eph.af1_s_s * dt + eph.af2_s_s2 * dt * dt


@dataclass(frozen=True)
class KeplerConstants:
    """What the Keplerian broadcast orbit needs per system: `mu_m3_s2` the gravitational constant,
    `omega_e_rad_s` the Earth rotation rate, `f_rel_s_sqrt_m` the relativistic clock constant −2√μ/c²."""

    mu_m3_s2: float
    omega_e_rad_s: float
    f_rel_s_sqrt_m: float


def _kepler_constants(mu_m3_s2: float, omega_e_rad_s: float) -> KeplerConstants:
    return KeplerConstants(mu_m3_s2, omega_e_rad_s, -2.0 * math.sqrt(mu_m3_s2) / (CLIGHT_M_S * CLIGHT_M_S))


KEPLER_GPS = KeplerConstants(MU_GPS_M3_S2, OMEGA_E_RAD_S, F_REL_S_SQRT_M)
"""GPS and QZSS (IS-GPS-200, IS-QZSS: WGS 84 values)."""
KEPLER_GALILEO = _kepler_constants(MU_GAL_M3_S2, OMEGA_E_GAL_RAD_S)
"""Galileo (OS SIS ICD 5.1.1: GTRF)."""
KEPLER_BEIDOU = _kepler_constants(MU_BDS_M3_S2, OMEGA_E_BDS_RAD_S)
"""BeiDou (B1I ICD 5.2.4.11: CGCS2000)."""
_KEPLER_BY_GNSS = {GNSS_GPS: KEPLER_GPS, GNSS_QZSS: KEPLER_GPS, GNSS_GALILEO: KEPLER_GALILEO,
                   GNSS_BEIDOU: KEPLER_BEIDOU}

_SIN_M5, _COS_M5 = math.sin(math.radians(-5.0)), math.cos(math.radians(-5.0))
"""The BeiDou GEO orbital frame is inclined by −5° about x against the CGCS2000 rotating frame."""


def kepler_constants(gnss_id: int) -> KeplerConstants:
    """The Keplerian constants of a system (u-blox gnssId); ValueError for GLONASS/SBAS (not Keplerian)."""
    try:
        return _KEPLER_BY_GNSS[gnss_id]
    except KeyError:
        raise ValueError(f"gnssId {gnss_id} has no Keplerian broadcast ephemeris") from None


def toe_system_tow_s(eph: Ephemeris) -> float:
    """toe in seconds of week of the ephemeris's own time system (BDT for BeiDou, else GPST = GST tow)."""
    if eph.gnss_id == GNSS_BEIDOU:
        return eph.toe.add_ns(BDT_MINUS_GPST_S * NS_PER_S).tow_s
    return eph.toe_s


def eph_position(eph: Ephemeris, t: GpsTime) -> tuple[npt.NDArray[np.float64], float]:
    """Satellite antenna position (ECEF m, at transmission time `t`, frame of `t`) and clock bias (s).

    Any Keplerian system (`eph.gnss_id`: GPS, QZSS, Galileo, BeiDou) with its own μ and Ω̇e; BeiDou GEO
    satellites (PRN 1–5, 59–63) are rotated from their −5° inclined frame (B1I ICD 5.2.4.12). The frame is
    the system's (WGS 84, GTRF, CGCS2000: equal at the centimetre level). The clock bias includes the
    relativistic eccentricity term, not the group delay (apply −TGD for L1 C/A: l1_group_delay_s).
    Scalar math (libm, as numpy's float64 loops here: the same numbers, measured to the bit): numpy's scalar
    calls cost a microsecond each, and this runs twice per satellite and epoch beside GPS's batch.
    """
    k = KEPLER_GPS if eph.gnss_id == GNSS_GPS else kepler_constants(eph.gnss_id)
    mu, omega_e = k.mu_m3_s2, k.omega_e_rad_s
    toe_s = eph.toe_s if eph.gnss_id == GNSS_GPS else toe_system_tow_s(eph)
    tk = t.diff_s(eph.toe)
    a = eph.sqrt_a * eph.sqrt_a
    n = math.sqrt(mu / (a * a * a)) + eph.delta_n_rad_s
    mk = eph.m0_rad + n * tk
    ek = mk
    for _ in range(30):
        e_next = mk + eph.e * math.sin(ek)
        if abs(e_next - ek) < 1e-14:
            ek = e_next
            break
        ek = e_next
    sin_e, cos_e = math.sin(ek), math.cos(ek)
    one_e2 = 1.0 - eph.e * eph.e
    # NaN for a nonsensical e ≥ 1 as np.sqrt gave (math.sqrt would raise)
    u = math.atan2((math.sqrt(one_e2) if one_e2 >= 0.0 else math.nan) * sin_e, cos_e - eph.e) + eph.omega_rad
    r = a * (1.0 - eph.e * cos_e)
    inc = eph.i0_rad + eph.idot_rad_s * tk
    sin2u, cos2u = math.sin(2.0 * u), math.cos(2.0 * u)
    u += eph.cus_rad * sin2u + eph.cuc_rad * cos2u
    r += eph.crs_m * sin2u + eph.crc_m * cos2u
    inc += eph.cis_rad * sin2u + eph.cic_rad * cos2u
    x, y = r * math.cos(u), r * math.sin(u)
    if eph.gnss_id == GNSS_BEIDOU and is_beidou_geo(eph.prn):
        # GEO: the node in inertial space (no −Ω̇e·tk), then the CGCS2000 rotation by Ω̇e·tk after the −5° tilt
        omega = eph.omega0_rad + eph.omega_dot_rad_s * tk - omega_e * toe_s
        cos_o, sin_o, cos_i = math.cos(omega), math.sin(omega), math.cos(inc)
        xg, yg, zg = x * cos_o - y * cos_i * sin_o, x * sin_o + y * cos_i * cos_o, y * math.sin(inc)
        sin_r, cos_r = math.sin(omega_e * tk), math.cos(omega_e * tk)
        pos = np.array([xg * cos_r + yg * sin_r * _COS_M5 + zg * sin_r * _SIN_M5,
                        -xg * sin_r + yg * cos_r * _COS_M5 + zg * cos_r * _SIN_M5,
                        -yg * _SIN_M5 + zg * _COS_M5])
    else:
        omega = eph.omega0_rad + (eph.omega_dot_rad_s - omega_e) * tk - omega_e * toe_s
        cos_o, sin_o, cos_i = math.cos(omega), math.sin(omega), math.cos(inc)
        pos = np.array([x * cos_o - y * cos_i * sin_o, x * sin_o + y * cos_i * cos_o, y * math.sin(inc)])
    dts = eph_clock_s(eph, t) + k.f_rel_s_sqrt_m * eph.e * eph.sqrt_a * sin_e
    return pos, float(dts)


def l1_group_delay_s(eph: Ephemeris) -> float:
    """The group delay (s) a single-frequency user subtracts from `eph`'s clock for the L1-band signal the M8T
    tracks: TGD for GPS/QZSS L1 C/A, BGD(E1,E5b) for Galileo E1 (I/NAV clocks are for the E1/E5b pair),
    TGD1 for BeiDou B1I."""
    return eph.tgd2_s if eph.gnss_id == GNSS_GALILEO else eph.tgd_s


def eph_position_velocity(
    eph: Ephemeris, t: GpsTime, dt_s: float = 1e-3
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], float, float]:
    """Position (ECEF m), velocity (m/s), clock bias (s) and clock drift (s/s) at transmission time `t`.

    Velocity and drift by a forward difference over `dt_s`, as RTKLIB satpos() does.
    """
    p0, c0 = eph_position(eph, t)
    p1, c1 = eph_position(eph, t.add_s(dt_s))
    return p0, (p1 - p0) / dt_s, c0, (c1 - c0) / dt_s


@dataclass
class SatState:
    """Satellite states for one epoch, arrays aligned with the requested PRNs.

    `pos_m` (n,3) ECEF at transmission time (not yet rotated for the signal travel time), `vel_m_s` (n,3),
    `clock_s` (n,) bias incl. relativity and −TGD (L1 C/A), `drift_s_s` (n,), `var_m2` (n,) URA variance,
    `ok` (n,) False where no usable ephemeris exists or the satellite is unhealthy.
    """

    prn: npt.NDArray[np.int16]
    pos_m: npt.NDArray[np.float64]
    vel_m_s: npt.NDArray[np.float64]
    clock_s: npt.NDArray[np.float64]
    drift_s_s: npt.NDArray[np.float64]
    var_m2: npt.NDArray[np.float64]
    ok: npt.NDArray[np.bool_]


class EphemerisStore:
    """Latest broadcast ephemerides per PRN; picks the one whose toe is closest to the requested time."""

    def __init__(self, ephemerides: Iterable[Ephemeris] = ()) -> None:
        self._by_prn: dict[int, list[Ephemeris]] = {}
        self._toe_ns: dict[int, list[int]] = {}  # toe (ns since the GPS epoch) of each _by_prn entry
        self._table: EphTable | None = None
        for eph in ephemerides:
            self.add(eph)

    def add(self, eph: Ephemeris) -> bool:
        """Store `eph`; returns False when an identical (prn, iode, toe) set is already held."""
        self._table = None  # the batched evaluation's parameter table is rebuilt on next use
        lst = self._by_prn.setdefault(eph.prn, [])
        for i, old in enumerate(lst):
            if old.toe == eph.toe and old.iode == eph.iode:
                if old == eph:
                    return False
                lst[i] = eph
                self._toe_ns[eph.prn] = [e.toe.total_ns for e in lst]
                return True
        lst.append(eph)
        lst.sort(key=lambda e: e.toe)
        self._toe_ns[eph.prn] = [e.toe.total_ns for e in lst]
        return True

    def __len__(self) -> int:
        return sum(len(v) for v in self._by_prn.values())

    def prns(self) -> list[int]:
        """PRNs for which at least one ephemeris is held."""
        return sorted(self._by_prn)

    def select(self, prn: int, t: GpsTime) -> Ephemeris | None:
        """The ephemeris of `prn` with toe nearest `t` within MAX_EPH_AGE_S, or None."""
        best, best_dt = None, MAX_EPH_AGE_S
        for eph in self._by_prn.get(prn, ()):
            dt = abs(t.diff_s(eph.toe))
            if dt <= best_dt:
                best, best_dt = eph, dt
        return best

    def select_ns(self, prn: int, t_total_ns: int) -> Ephemeris | None:
        """As select() for a time given in ns since the GPS epoch (the engine's per-satellite hot path)."""
        best, best_dt = None, MAX_EPH_AGE_S
        for eph, toe_ns in zip(self._by_prn.get(prn, ()), self._toe_ns.get(prn, ())):
            dt = abs(t_total_ns - toe_ns) / NS_PER_S
            if dt <= best_dt:
                best, best_dt = eph, dt
        return best

    def all(self) -> list[Ephemeris]:
        """Every held ephemeris, by PRN then toe."""
        return [e for prn in sorted(self._by_prn) for e in self._by_prn[prn]]

    def table(self) -> EphTable:
        """Every held ephemeris as parameter arrays for the batched evaluation (rebuilt after add())."""
        table = getattr(self, "_table", None)  # a store unpickled from an older version has none
        if table is None:
            table = self._table = EphTable.of(self._by_prn)
        return table


_EPH_FIELDS = ("sqrt_a", "e", "i0_rad", "omega0_rad", "omega_rad", "m0_rad", "delta_n_rad_s", "omega_dot_rad_s",
               "idot_rad_s", "cuc_rad", "cus_rad", "crc_m", "crs_m", "cic_rad", "cis_rad", "af0_s", "af1_s_s",
               "af2_s_s2", "tgd_s")


def _batch_position(p: npt.NDArray[np.float64], tk: npt.NDArray[np.float64], toe_s: npt.NDArray[np.float64],
                    k: _ColumnConstants, iterations: int = 12
                    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """eph_position() for many ephemerides at once (rows of `p` in _EPH_FIELDS order, `k` their systems'
    constants per column): ECEF positions (n,3) and the relativistic clock term (n,) (s). `iterations` of the
    fixed-point Kepler equation: the error shrinks by e per step (GPS e < 0.03: 12 give < 1e-18)."""
    (sqrt_a, ecc, i0, omega0, omega_arg, m0, dn, omega_dot, idot, cuc, cus, crc, crs, cic, cis) = p[:15]
    a = sqrt_a * sqrt_a
    n = np.sqrt(k.mu / (a * a * a)) + dn
    mk = m0 + n * tk
    ek = mk.copy()
    for _ in range(iterations):
        ek = mk + ecc * np.sin(ek)
    sin_e, cos_e = np.sin(ek), np.cos(ek)
    u = np.arctan2(np.sqrt(1.0 - ecc * ecc) * sin_e, cos_e - ecc) + omega_arg
    r = a * (1.0 - ecc * cos_e)
    inc = i0 + idot * tk
    sin2u, cos2u = np.sin(2.0 * u), np.cos(2.0 * u)
    u = u + cus * sin2u + cuc * cos2u
    r = r + crs * sin2u + crc * cos2u
    inc = inc + cis * sin2u + cic * cos2u
    x, y = r * np.cos(u), r * np.sin(u)
    omega_e = k.omega_e
    omega = omega0 + (omega_dot - omega_e) * tk - omega_e * toe_s
    cos_o, sin_o, cos_i = np.cos(omega), np.sin(omega), np.cos(inc)
    pos = np.stack([x * cos_o - y * cos_i * sin_o, x * sin_o + y * cos_i * cos_o, y * np.sin(inc)], axis=1)
    if k.geo is not None and k.geo.any():
        # BeiDou GEO (eph_position): the node in inertial space, then the CGCS2000 rotation after the −5° tilt
        g = k.geo
        om_e, tkg = np.broadcast_to(omega_e, tk.shape)[g], tk[g]
        omg = omega0[g] + omega_dot[g] * tkg - om_e * toe_s[g]
        cos_o, sin_o, cos_i, sin_i = np.cos(omg), np.sin(omg), np.cos(inc[g]), np.sin(inc[g])
        xk, yk = x[g], y[g]
        xg, yg, zg = xk * cos_o - yk * cos_i * sin_o, xk * sin_o + yk * cos_i * cos_o, yk * sin_i
        sin_r, cos_r = np.sin(om_e * tkg), np.cos(om_e * tkg)
        pos[g] = np.stack([xg * cos_r + yg * sin_r * _COS_M5 + zg * sin_r * _SIN_M5,
                           -xg * sin_r + yg * cos_r * _COS_M5 + zg * cos_r * _SIN_M5,
                           -yg * _SIN_M5 + zg * _COS_M5], axis=1)
    return pos, k.f_rel * ecc * sqrt_a * sin_e


@dataclass(frozen=True)
class _ColumnConstants:
    """Kepler constants per table column (arrays (N,), or scalars for a one-system table): `mu`, `omega_e`,
    `f_rel` as KeplerConstants; `geo` the BeiDou GEO columns (None: none)."""

    mu: npt.NDArray[np.float64] | float
    omega_e: npt.NDArray[np.float64] | float
    f_rel: npt.NDArray[np.float64] | float
    geo: npt.NDArray[np.bool_] | None = None

    def take(self, c: npt.NDArray[np.int64]) -> _ColumnConstants:
        """The constants of columns `c` (twice over for the two points of a forward difference: see callers)."""
        def pick(v: npt.NDArray[np.float64] | float) -> npt.NDArray[np.float64] | float:
            return v[c] if isinstance(v, np.ndarray) else v
        return _ColumnConstants(pick(self.mu), pick(self.omega_e), pick(self.f_rel),
                                None if self.geo is None else self.geo[c])


@dataclass
class EphTable:
    """Keplerian ephemerides as columns for the batched evaluation: `params` (19, N) parameter rows in
    _EPH_FIELDS order (the last: the group delay the L1-band user subtracts), `toe_s` (N,) toe seconds of week
    of the ephemeris's own time system, `toe_ns`/`toc_ns` (N,) toe/toc in ns since the GPS epoch, `var_m2` (N,)
    the accuracy index's variance, `healthy` (N,), `consts` the Kepler constants per column; per satellite row
    r (0 = none; a PRN for GPS), `by_prn_col[r]` its columns by toe, padded with −1, `by_prn_toe_ns[r]` their
    toe, padded with a time no epoch comes near, and `max_age_s[r]` the largest |t − toe| its system uses."""

    params: npt.NDArray[np.float64]
    toe_s: npt.NDArray[np.float64]
    toe_ns: npt.NDArray[np.int64]
    toc_ns: npt.NDArray[np.int64]
    var_m2: npt.NDArray[np.float64]
    healthy: npt.NDArray[np.bool_]
    consts: _ColumnConstants
    by_prn_col: npt.NDArray[np.int64]
    by_prn_toe_ns: npt.NDArray[np.int64]
    max_age_s: npt.NDArray[np.float64]
    kepler_iterations: int = 12

    @staticmethod
    def of(by_row: dict[int, list[Ephemeris]], max_age_s: dict[int, float] | None = None,
           healthy_if: Callable[[Ephemeris], bool] | None = None, sigma_m: Callable[[Ephemeris], float] | None = None
           ) -> EphTable:
        """The table of ephemerides by satellite row (each list by toe). GPS PRNs as rows (EphemerisStore): the
        GPS constants, URA, health 0, TGD, MAX_EPH_AGE_S. Otherwise (`max_age_s` per row given: any Keplerian
        system) each column's system's constants, the L1-band group delay, `healthy_if` and `sigma_m` of each
        ephemeris (onboard.rtk.navstore's), and the Kepler equation iterated until it converges for the QZSS
        IGSO orbits' e ≈ 0.08 too (20 steps)."""
        gps = max_age_s is None
        ephs: list[Ephemeris] = []
        width = max((len(v) for v in by_row.values()), default=0) or 1
        top = max(max(by_row, default=0), 32) + 1
        cols = np.full((top, width), -1, np.int64)
        toes = np.full((top, width), _FAR_NS, np.int64)
        ages = np.full(top, MAX_EPH_AGE_S)
        for row in sorted(by_row):
            k = len(by_row[row])
            cols[row, :k] = np.arange(len(ephs), len(ephs) + k)
            toes[row, :k] = [e.toe.total_ns for e in by_row[row]]
            if max_age_s is not None:
                ages[row] = max_age_s[row]
            ephs.extend(by_row[row])
        params = np.array([[getattr(e, f) for e in ephs] for f in _EPH_FIELDS[:-1]]
                          + [[e.tgd_s if gps else l1_group_delay_s(e) for e in ephs]]).reshape(len(_EPH_FIELDS), -1)
        if gps:
            consts = _ColumnConstants(MU_GPS_M3_S2, OMEGA_E_RAD_S, F_REL_S_SQRT_M)
            var = np.array([ura_sigma_m(e.ura_index) ** 2 for e in ephs], float)
            healthy = np.array([e.health == 0 for e in ephs], bool)
            toe_s = np.array([e.toe_s for e in ephs], float)
        else:
            ks = [kepler_constants(e.gnss_id) for e in ephs]
            consts = _ColumnConstants(np.array([k.mu_m3_s2 for k in ks], float),
                                      np.array([k.omega_e_rad_s for k in ks], float),
                                      np.array([k.f_rel_s_sqrt_m for k in ks], float),
                                      np.array([e.gnss_id == GNSS_BEIDOU and is_beidou_geo(e.prn) for e in ephs],
                                               bool))
            if healthy_if is None or sigma_m is None:
                raise ValueError("a table of several systems needs each ephemeris' health and accuracy")
            var = np.array([sigma_m(e) ** 2 for e in ephs], float)
            healthy = np.array([healthy_if(e) for e in ephs], bool)
            toe_s = np.array([toe_system_tow_s(e) for e in ephs], float)
        return EphTable(params, toe_s, np.array([e.toe.total_ns for e in ephs], np.int64),
                        np.array([e.toc.total_ns for e in ephs], np.int64), var, healthy, consts, cols, toes, ages,
                        12 if gps else 20)


_FAR_NS = 2**62
"""A toe (ns) no receiver time comes within MAX_EPH_AGE_S of (year ~2100 + 100; the difference stays in int64)."""


def _select_columns(table: EphTable, rows: npt.NDArray[np.int16], t_ns: npt.NDArray[np.int64],
                    have: npt.NDArray[np.bool_]) -> npt.NDArray[np.int64]:
    """EphemerisStore.select_ns for every (epoch, satellite) at once: the table column of the ephemeris whose
    toe is nearest `t_ns` (E, n) within its system's largest age, the later one on a tie; −1 where none or not
    `have`. `rows` (n,): each satellite's table row (a PRN for GPS)."""
    col = np.full(t_ns.shape, -1, np.int64)
    ep, sat = have.nonzero()
    prn = rows[sat].astype(np.int64)
    known = (prn >= 0) & (prn < table.by_prn_col.shape[0])
    ep, sat, prn = ep[known], sat[known], prn[known]
    # |t − toe| in s as select_ns computes it (ns difference, then ÷ 1e9: exact below 2^53 ns)
    dt = np.abs(t_ns[ep, sat][:, None] - table.by_prn_toe_ns[prn]) / NS_PER_S
    last = dt.shape[1] - 1 - np.argmin(dt[:, ::-1], axis=1)  # the later of equally near toes
    near = dt[np.arange(ep.size), last] <= table.max_age_s[prn]
    col[ep[near], sat[near]] = table.by_prn_col[prn[near], last[near]]
    return col


def satellite_states_batch(store: EphemerisStore, prns: npt.ArrayLike, t_rx_ns: npt.ArrayLike,
                           pr_m: npt.ArrayLike) -> list[SatState]:
    """satellite_states() of E epochs at once: receiver times `t_rx_ns` (E,) in ns since the GPS epoch,
    pseudoranges `pr_m` (E, n) (m, NaN where absent) for the same `prns` (n,). One vectorised pass over every
    (epoch, satellite) pair; the same formulas, element by element, as the one-epoch call (which is this one
    with E = 1), so post-processing can compute every epoch's satellites before the filter runs."""
    prn_arr = np.asarray(prns, dtype=np.int16)
    t_rx = np.asarray(t_rx_ns, dtype=np.int64)
    pr = np.asarray(pr_m, dtype=float).reshape(t_rx.shape[0], prn_arr.shape[0])
    pos, vel, clk, drift, var, ok = table_states(store.table() if len(store) else None, prn_arr, t_rx, pr)
    return [SatState(prn_arr, pos[k], vel[k], clk[k], drift[k], var[k], ok[k]) for k in range(pr.shape[0])]


def table_states(table: EphTable | None, rows: npt.NDArray[np.int16], t_rx: npt.NDArray[np.int64],
                 pr: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], ...]:
    """Satellite states at transmission (t_rx − pr/c − satellite clock, as RTKLIB satposs) of the satellites
    of table `rows` (n,) at E epochs: receiver times `t_rx` (E,) ns since the GPS epoch, pseudoranges `pr`
    (E, n) m. Arrays (position (E, n, 3) m, velocity (E, n, 3) m/s, clock (E, n) s incl. relativity and minus
    the group delay, drift (E, n) s/s, ephemeris variance (E, n) m², ok (E, n)); not ok where no healthy
    ephemeris is held (everywhere with no table)."""
    n_ep, n = pr.shape
    pos = np.zeros((n_ep, n, 3))
    vel = np.zeros((n_ep, n, 3))
    clk = np.zeros((n_ep, n))
    drift = np.zeros((n_ep, n))
    var = np.zeros((n_ep, n))
    ok = np.zeros((n_ep, n), dtype=bool)
    have = np.isfinite(pr)
    if table is None or not have.any():
        return pos, vel, clk, drift, var, ok
    # ephemeris choice at t_rx − pr/c (GpsTime.add_s's rounding to the ns: half to even, as round())
    t_tx_ns = t_rx[:, None] + np.rint(np.where(have, -pr, 0.0) / CLIGHT_M_S * NS_PER_S).astype(np.int64)
    col = _select_columns(table, rows, t_tx_ns, have)
    use = col >= 0
    use[use] = table.healthy[col[use]]
    ep, sat = use.nonzero()
    if not ep.size:
        return pos, vel, clk, drift, var, ok
    c = col[ep, sat]
    m = c.size
    p = table.params[:, c]
    af0, af1, af2, tgd = p[15], p[16], p[17], p[18]
    t_ep = t_rx[ep]
    rx_toe = (t_ep - table.toe_ns[c]) / 1e9
    rx_toc = (t_ep - table.toc_ns[c]) / 1e9
    tau = pr[ep, sat] / CLIGHT_M_S

    def clock(dt: npt.NDArray[np.float64], k: int) -> npt.NDArray[np.float64]:
        a0, a1, a2 = af0[:k], af1[:k], af2[:k]
        for _ in range(2):  # as eph_clock_s: the polynomial evaluated at t − dts
            dt = dt - (a0 + a1 * dt + a2 * dt * dt)
        return a0 + a1 * dt + a2 * dt * dt

    off = -tau - clock(rx_toc - tau, m)  # t_tx − t_rx (s)
    step = 1e-3
    # both points of the velocity/drift difference in one vectorised pass (columns m.. are t + step)
    c2 = np.concatenate([c, c])
    p2 = table.params[:, c2]
    af0, af1, af2 = p2[15], p2[16], p2[17]
    tk0 = rx_toe + off
    toe_s = table.toe_s[c2]
    p01, rel01 = _batch_position(p2, np.concatenate([tk0, tk0 + step]), toe_s, table.consts.take(c2),
                                 table.kepler_iterations)
    t0 = rx_toc + off
    c01 = clock(np.concatenate([t0, t0 + step]), 2 * m) + rel01
    p0, p1 = p01[:m], p01[m:]
    c0, c1 = c01[:m], c01[m:]
    pos[ep, sat] = p0
    vel[ep, sat] = (p1 - p0) / step
    clk[ep, sat] = c0 - tgd
    drift[ep, sat] = (c1 - c0) / step
    var[ep, sat] = table.var_m2[c]
    ok[ep, sat] = True
    return pos, vel, clk, drift, var, ok


def satellite_states(
    store: EphemerisStore, prns: npt.ArrayLike, t_rx: GpsTime, pr_m: npt.ArrayLike
) -> SatState:
    """Satellite states at signal transmission for receiver time `t_rx` and pseudoranges `pr_m` (m).

    Transmission time = t_rx − pr/c − satellite clock (RTKLIB satposs()); the result is in the ECEF frame
    of the transmission instant (the caller rotates for Earth rotation during travel, see geometric_range).
    Vectorised over satellites (satellite_states_batch with one epoch): the same formulas as eph_position /
    eph_position_velocity.
    """
    pr = np.asarray(pr_m, dtype=float)
    return satellite_states_batch(store, prns, [t_rx.total_ns], pr.reshape(1, -1))[0]


def geometric_range(
    sat_pos_m: npt.NDArray[np.float64], rcv_pos_m: npt.NDArray[np.float64]
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Range (m) with the Sagnac correction and unit line-of-sight vectors (receiver → satellite).

    `sat_pos_m` (n,3) (or (k,n,3): k epochs seen from the same receiver position), `rcv_pos_m` (3,), both
    ECEF; follows RTKLIB geodist().
    """
    d = sat_pos_m - rcv_pos_m
    r = np.sqrt(np.add.reduce(d * d, axis=-1))  # np.linalg.norm(d, axis=-1) without its dispatch overhead
    e = d / r[..., None]
    sagnac = OMEGA_E_RAD_S * (sat_pos_m[..., 0] * rcv_pos_m[1] - sat_pos_m[..., 1] * rcv_pos_m[0]) / CLIGHT_M_S
    return r + sagnac, e
