"""Broadcast navigation of every constellation in one store, and one satellite-state evaluation for either
ephemeris kind (pure; what the multi-constellation engine will use; today's GPS engine keeps EphemerisStore).

`BroadcastNavigation` keys ephemerides by (u-blox gnssId, svId) and picks the one whose toe is nearest the
requested time within the system's largest age (onboard.rtk.gnss: GPS 2 h, Galileo 4 h, BeiDou 6 h, QZSS 2 h,
GLONASS 30 min). Galileo I/NAV ephemerides are preferred to F/NAV ones (the M8T tracks E1, whose clock is the
I/NAV E1/E5b one). `satellite_state` gives position, velocity, clock (relativity included, the L1-band group
delay removed), drift, variance and health at a transmission time.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from onboard.gnsstime import NS_PER_S, GpsTime
from onboard.rtk.ephemeris import EphTable, eph_position_velocity, l1_group_delay_s, sisa_sigma_m, ura_sigma_m
from onboard.rtk.glonass import ERR_EPH_GLO_M, GlonassOrbits, glonass_clock_at_s, glonass_position_velocity
from onboard.rtk.gnss import system
from onboard.rtk.types import GNSS_GALILEO, GNSS_GLONASS, Ephemeris, GlonassEphemeris

AnyEphemeris = Ephemeris | GlonassEphemeris

_INAV_SOURCES = 0x005
"""Galileo data-source bits of I/NAV (E1-B bit 0, E5b-I bit 2)."""


def sat_key(eph: AnyEphemeris) -> tuple[int, int]:
    """(gnssId, svId) of an ephemeris."""
    if isinstance(eph, GlonassEphemeris):
        return GNSS_GLONASS, eph.slot
    return eph.gnss_id, eph.prn


def is_healthy(eph: AnyEphemeris) -> bool:
    """The broadcast health allows use on the L1-band signal: GPS/QZSS SV health 0, BeiDou SatH1 0, GLONASS
    Bn MSB and ln 0, Galileo E1-B HS and DVS 0 (I/NAV) or E5a HS and DVS 0 (F/NAV: no E1 flags)."""
    if isinstance(eph, GlonassEphemeris):
        return eph.health == 0
    if eph.gnss_id == GNSS_GALILEO:
        mask = 0x007 if eph.code_on_l2 & _INAV_SOURCES else 0x038
        return eph.health & mask == 0
    return eph.health == 0


def ephemeris_sigma_m(eph: AnyEphemeris) -> float:
    """1-σ orbit + clock error (m) the broadcast accuracy index states (GLONASS: 5 m, RTKLIB's value)."""
    if isinstance(eph, GlonassEphemeris):
        return ERR_EPH_GLO_M
    if eph.gnss_id == GNSS_GALILEO:
        return sisa_sigma_m(eph.ura_index)
    return ura_sigma_m(eph.ura_index)


@dataclass(frozen=True)
class SatelliteState:
    """One satellite at a transmission time: `pos_m` (3,) ECEF (frame of that instant), `vel_m_s` (3,),
    `clock_s` bias incl. relativity and minus the L1-band group delay, `drift_s_s`, `var_m2` ephemeris variance,
    `healthy` the broadcast health verdict."""

    pos_m: npt.NDArray[np.float64]
    vel_m_s: npt.NDArray[np.float64]
    clock_s: float
    drift_s_s: float
    var_m2: float
    healthy: bool


def satellite_state(eph: AnyEphemeris, t_tx: GpsTime, orbits: GlonassOrbits | None = None) -> SatelliteState:
    """Position, velocity, clock and variance of `eph`'s satellite at GPS time `t_tx` (either ephemeris kind);
    `orbits` keeps GLONASS orbits integrated once per ephemeris and interpolated (BroadcastNavigation.state)."""
    if isinstance(eph, GlonassEphemeris):
        pos, vel, clk, drift = (glonass_position_velocity(eph, t_tx) if orbits is None
                                else orbits.position_velocity(eph, t_tx))
    else:
        pos, vel, clk, drift = eph_position_velocity(eph, t_tx)
        clk -= l1_group_delay_s(eph)
    return SatelliteState(pos, vel, float(clk), float(drift), ephemeris_sigma_m(eph) ** 2, is_healthy(eph))


class BroadcastNavigation:
    """Ephemerides of every constellation by (gnssId, svId); `select` the one nearest in toe."""

    def __init__(self, ephemerides: Iterable[AnyEphemeris] = ()) -> None:
        self._by_sat: dict[tuple[int, int], list[AnyEphemeris]] = {}
        self._orbits = GlonassOrbits()
        self._kepler: tuple[EphTable, dict[tuple[int, int], int]] | None = None
        for eph in ephemerides:
            self.add(eph)

    def add(self, eph: AnyEphemeris) -> bool:
        """Store `eph`; False when the same one is already held (a repeat); a changed set of the same toe and
        issue replaces the held one."""
        lst = self._by_sat.setdefault(sat_key(eph), [])
        for i, old in enumerate(lst):
            if old.toe == eph.toe and old.iode == eph.iode and _source(old) == _source(eph):
                if old == eph:
                    return False
                lst[i] = eph
                self._kepler = None
                return True
        lst.append(eph)
        lst.sort(key=lambda e: e.toe)
        self._kepler = None  # the batched evaluation's table is rebuilt on next use
        return True

    def __len__(self) -> int:
        return sum(len(v) for v in self._by_sat.values())

    def satellites(self) -> list[tuple[int, int]]:
        """(gnssId, svId) of every satellite with at least one ephemeris."""
        return sorted(self._by_sat)

    def select(self, gnss_id: int, sv_id: int, t: GpsTime) -> AnyEphemeris | None:
        """The ephemeris of the satellite whose toe is nearest `t` within the system's largest age (Galileo:
        I/NAV first), the later one on a tie; None when there is none."""
        candidates: list[AnyEphemeris] = self._by_sat.get((gnss_id, sv_id), [])
        if gnss_id == GNSS_GALILEO:
            inav: list[AnyEphemeris] = [e for e in candidates
                                        if isinstance(e, Ephemeris) and e.code_on_l2 & _INAV_SOURCES]
            candidates = inav or candidates
        best, best_dt = None, system(gnss_id).max_eph_age_s
        for eph in candidates:
            dt = abs(t.diff_s(eph.toe))
            if dt <= best_dt:
                best, best_dt = eph, dt
        return best

    def kepler_table(self) -> tuple[EphTable, dict[tuple[int, int], int]]:
        """The Keplerian ephemerides (every system but GLONASS) as one table for the batched evaluation
        (onboard.rtk.ephemeris.table_states), and each satellite's row in it by (gnssId, svId); the candidates
        `select` would weigh (Galileo: I/NAV only when the satellite has any), with its system's largest age."""
        if getattr(self, "_kepler", None) is None:  # (a store unpickled from an older version has none)
            rows: dict[tuple[int, int], int] = {}
            by_row: dict[int, list[Ephemeris]] = {}
            ages: dict[int, float] = {}
            for key in sorted(self._by_sat):
                if key[0] == GNSS_GLONASS:
                    continue
                ephs = [e for e in self._by_sat[key] if isinstance(e, Ephemeris)]
                if key[0] == GNSS_GALILEO:
                    ephs = [e for e in ephs if e.code_on_l2 & _INAV_SOURCES] or ephs
                if ephs:
                    rows[key] = row = len(rows) + 1
                    by_row[row], ages[row] = ephs, system(key[0]).max_eph_age_s
            self._kepler = (EphTable.of(by_row, ages, is_healthy, ephemeris_sigma_m), rows)
        assert self._kepler is not None
        return self._kepler

    def glonass_states(self, slot: int, t0_ns: npt.NDArray[np.int64], out: tuple[npt.NDArray[np.float64], ...],
                       ok: npt.NDArray[np.bool_]) -> None:
        """States of GLONASS `slot` at the instants `t0_ns` (m,) (ns since the GPS epoch; receiver time − pr/c),
        in any order, written into `out` = (position (m, 3) m, velocity (m, 3), clock (m,) s, drift
        (m,), variance (m,) m²) and `ok` (m,) where a healthy ephemeris is held: as select, the broadcast
        clock at that instant setting the transmission time (one fixed-point step is < 1 ns off), and state,
        for each instant, without their per-call objects: every instant of one ephemeris in one pass, the same
        numbers to the bit."""
        ephs = [e for e in self._by_sat.get((GNSS_GLONASS, slot), []) if isinstance(e, GlonassEphemeris)]
        if not ephs or not t0_ns.size:
            return
        toe = np.array([e.toe.total_ns for e in ephs], np.int64)
        dt = np.abs(t0_ns[:, None] - toe[None, :]) / NS_PER_S  # as select: |t − toe| in s
        last = len(ephs) - 1 - np.argmin(dt[:, ::-1], axis=1)  # the later of equally near toes
        near = dt[np.arange(t0_ns.size), last] <= system(GNSS_GLONASS).max_eph_age_s
        pos, vel, clk, drift, var = out
        for k in np.unique(last[near]).tolist():
            eph = ephs[k]
            at = np.flatnonzero((last == k) & near)
            if not at.size or eph.health != 0:
                continue
            toe_ns = eph.toe.total_ns
            t0 = t0_ns[at]
            # the transmission time as GpsTime.add_s rounds it (half to even, as round())
            t_tx = t0 + np.rint(-glonass_clock_at_s(eph, (t0 - toe_ns) / NS_PER_S) * NS_PER_S).astype(np.int64)
            dt_tx = (t_tx - toe_ns) / NS_PER_S
            pos[at], vel[at], clk[at], drift[at] = self._orbits.positions_velocities_at(eph, dt_tx)
            var[at] = ERR_EPH_GLO_M ** 2
            ok[at] = True

    def state(self, eph: AnyEphemeris, t_tx: GpsTime) -> SatelliteState:
        """satellite_state of one of this store's ephemerides, a GLONASS orbit integrated once per ephemeris and
        interpolated (GlonassOrbits)."""
        return satellite_state(eph, t_tx, self._orbits)

    def glonass_channels(self) -> dict[int, int]:
        """GLONASS slot → frequency channel k, from the latest ephemeris of each slot."""
        return {sv: lst[-1].channel for (g, sv), lst in self._by_sat.items()
                if g == GNSS_GLONASS and isinstance(lst[-1], GlonassEphemeris)}


def _source(eph: AnyEphemeris) -> int:
    return 0 if isinstance(eph, GlonassEphemeris) else eph.code_on_l2 if eph.gnss_id == GNSS_GALILEO else 0
