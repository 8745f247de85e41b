"""Small noise-free GPS L1 observation simulator for the RTK tests (real broadcast orbits, known truth).

Observables follow the engine's own physics (range with Sagnac, satellite clock incl. relativity and TGD,
Saastamoinen troposphere, no ionosphere, RINEX signs: phase follows range, Doppler = −range rate/λ), so a
correct engine must reproduce the truth to the millimetre.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from onboard.gnsstime import GpsTime
from onboard.rtk.consts import CLIGHT_M_S, LAMBDA_L1_M, OMEGA_E_RAD_S
from onboard.rtk.ephemeris import EphemerisStore, geometric_range, satellite_states
from onboard.rtk.geodesy import azimuth_elevation, ecef_to_llh
from onboard.rtk.models import saastamoinen_m
from onboard.rtk.types import GNSS_GPS, ObsEpoch

BASE_ECEF_M = np.array([-3869302.2, 3436557.8, 3717357.2])
"""A site near Tokyo (the LEA-4T capture's approximate position)."""
T0 = GpsTime.from_week_tow_s(1590, 4 * 86400 + 3 * 3600)  # 2010-07-01 03:00 GPST, inside brdc1820.10n


@dataclass
class SimReceiver:
    """A receiver: clock bias (s) and drift (s/s), integer ambiguity per PRN, cumulative slips per PRN."""

    clock_s: float = 0.0
    drift_s_s: float = 0.0
    ambiguity_cyc: dict[int, int] = field(default_factory=dict)
    seed: int = 0

    def amb(self, prn: int) -> int:
        if prn not in self.ambiguity_cyc:
            rng = np.random.default_rng(self.seed * 100 + prn)
            self.ambiguity_cyc[prn] = int(rng.integers(-10**6, 10**6))
        return self.ambiguity_cyc[prn]


def observe(store: EphemerisStore, rcv: SimReceiver, pos_ecef_m: np.ndarray, vel_ecef_m_s: np.ndarray,
            t_true: GpsTime, elmask_deg: float = 10.0, prns: list[int] | None = None,
            lli: dict[int, int] | None = None) -> ObsEpoch:
    """Noise-free L1 observations of every satellite above `elmask_deg` (or of `prns`) at true time `t_true`.

    The epoch is tagged with receiver time t_true + clock bias, as a real receiver does.
    """
    t_rx = t_true.add_s(rcv.clock_s)
    cand = prns if prns is not None else store.prns()
    rows = []
    lat, _, h = ecef_to_llh(pos_ecef_m)
    for prn in cand:
        pr = 2.2e7
        sat = None
        for _ in range(4):  # make pr consistent with the transmit time it implies
            sat = satellite_states(store, [prn], t_rx, [pr])
            if not sat.ok[0]:
                break
            rho, _e = geometric_range(sat.pos_m, pos_ecef_m)
            _az, el = azimuth_elevation(pos_ecef_m, sat.pos_m)
            trop = saastamoinen_m(lat, h, el)
            pr = float(rho[0] + CLIGHT_M_S * (rcv.clock_s - sat.clock_s[0]) + trop[0])
        if sat is None or not sat.ok[0] or np.degrees(el[0]) < elmask_deg:
            continue
        rho, e = geometric_range(sat.pos_m, pos_ecef_m)
        vs = sat.vel_m_s[0]
        sag_rate = OMEGA_E_RAD_S / CLIGHT_M_S * (vs[1] * pos_ecef_m[0] - vs[0] * pos_ecef_m[1])
        rate = float(e[0] @ (vs - vel_ecef_m_s) + sag_rate + CLIGHT_M_S * (rcv.drift_s_s - sat.drift_s_s[0]))
        cp = pr / LAMBDA_L1_M + rcv.amb(prn)
        rows.append((prn, pr, cp, -rate / LAMBDA_L1_M, (lli or {}).get(prn, 0)))
    n = len(rows)
    arr = np.array([r[1:4] for r in rows]).reshape(n, 3)
    return ObsEpoch(
        time=t_rx, gnss_id=np.full(n, GNSS_GPS, np.int8), sv_id=np.array([r[0] for r in rows], np.int16),
        pr_m=arr[:, 0].copy(), cp_cyc=arr[:, 1].copy(), dop_hz=arr[:, 2].copy(), cn0_dbhz=np.full(n, 45.0),
        lock_ms=np.full(n, np.nan), lli=np.array([r[4] for r in rows], np.uint8),
        half_cyc_sub=np.zeros(n, np.uint8), pr_std_m=np.full(n, np.nan), cp_std_cyc=np.full(n, np.nan),
    )


def add_noise(obs: ObsEpoch, rng: np.random.Generator, pr_sigma_m: float = 0.3,
              cp_sigma_cyc: float = 0.01, dop_sigma_hz: float = 0.05) -> ObsEpoch:
    """The same epoch with white Gaussian noise on code, phase and Doppler."""
    n = len(obs)
    return ObsEpoch(
        time=obs.time, gnss_id=obs.gnss_id, sv_id=obs.sv_id, pr_m=obs.pr_m + rng.normal(0, pr_sigma_m, n),
        cp_cyc=obs.cp_cyc + rng.normal(0, cp_sigma_cyc, n), dop_hz=obs.dop_hz + rng.normal(0, dop_sigma_hz, n),
        cn0_dbhz=obs.cn0_dbhz, lock_ms=obs.lock_ms, lli=obs.lli, half_cyc_sub=obs.half_cyc_sub,
        pr_std_m=obs.pr_std_m, cp_std_cyc=obs.cp_std_cyc,
    )
