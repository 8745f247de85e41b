"""The satellites of a simulated world: which systems, which broadcast ephemerides, which carrier, which biases.

Pure (no I/O beyond reading the navigation files handed in). The World (hil_sim.world) indexes every random
process by a *column* per satellite; `SatelliteLayout` fixes that layout:

- a GPS-only world ("G") has the 32 GPS PRNs as columns 0…31, exactly the layout the simulator always had
  (a GPS-only scenario reproduces bit for bit);
- any other world uses the fixed multi-system layout GPS 1–32, GLONASS slots 1–24, Galileo 1–36, QZSS 1–10,
  BeiDou 1–63 (165 columns), whatever subset the navigation files hold, so a satellite's random streams do
  not depend on which other satellites are in view.

Carriers (`carrier_hz`): GPS/QZSS L1 and Galileo E1 1575.42 MHz, BeiDou B1I 1561.098 MHz, GLONASS G1 FDMA
1602 + 0.5625·k MHz with the channel k of the satellite's broadcast ephemeris.

GLONASS inter-frequency biases (`glonass_ifb`): a receiver's FDMA signals pass its front end at different
frequencies, so its code and phase carry a channel-dependent delay. Per receiver *type* (`IFB_TYPES`): phase
IFB = slope_mm·k + a random per-channel part (σ `phase_random_mm`), code IFB = offset + slope_m·k + a random
per-channel part (σ `code_random_m`). The random parts are drawn per (scenario seed, type), never per
receiver: two receivers of the same type carry identical biases, which cancel in the between-receiver
difference; two types leave the difference of their biases in every GLONASS double difference. The numbers
are of the orders the literature reports for mixed-manufacturer GLONASS baselines (phase: millimetres per
channel step; code: decimetres to metres per channel); they are a model, not a measurement of any receiver.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from onboard.errors import InputError
from onboard.formats.rinex_nav import NavFile, read_rinex_nav
from onboard.gnsstime import GpsTime
from onboard.rtk.consts import DFREQ_G1_HZ, FREQ_B1I_HZ, FREQ_G1_HZ, FREQ_L1_HZ, GLO_FCN_MAX, GLO_FCN_MIN
from onboard.rtk.ephemeris import MAX_EPH_AGE_S
from onboard.rtk.gnss import SYSTEMS_BY_LETTER, system
from onboard.rtk.navstore import AnyEphemeris, is_healthy
from onboard.rtk.types import (
    GNSS_BEIDOU,
    GNSS_GALILEO,
    GNSS_GLONASS,
    GNSS_GPS,
    GNSS_QZSS,
    Ephemeris,
    GlonassEphemeris,
)

Vec = npt.NDArray[np.float64]

MULTI_ORDER = (GNSS_GPS, GNSS_GLONASS, GNSS_GALILEO, GNSS_QZSS, GNSS_BEIDOU)
"""Systems of the multi-system column layout, in column order."""
_INAV_SOURCES = 0x005
"""Galileo data-source bits of I/NAV (E1-B bit 0, E5b-I bit 2)."""
SIGNAL_CODE = {GNSS_GPS: "1C", GNSS_GLONASS: "1C", GNSS_GALILEO: "1C", GNSS_QZSS: "1C", GNSS_BEIDOU: "2I"}
"""RINEX 3 code of the L1-band signal simulated per system (what RXM-RAWX version 1 with sigId 0 decodes to)."""


def parse_systems(text: str) -> tuple[int, ...]:
    """u-blox gnssIds of a system string such as "GREJ" (RINEX letters; G R E J C), in MULTI_ORDER."""
    ids = set()
    for ch in text.upper():
        sysd = SYSTEMS_BY_LETTER.get(ch)
        if sysd is None or sysd.gnss_id not in MULTI_ORDER:
            raise ValueError(f"unknown system letter {ch!r} in {text!r} (expected G, R, E, J, C)")
        ids.add(sysd.gnss_id)
    if not ids:
        raise ValueError("no system selected")
    return tuple(g for g in MULTI_ORDER if g in ids)


@dataclass(frozen=True)
class SatelliteLayout:
    """Column of every possible satellite: `(gnss_id, sv_id) → column`, `n_cols` columns in all."""

    gps_only: bool

    @property
    def n_cols(self) -> int:
        return 32 if self.gps_only else sum(system(g).sv_max for g in MULTI_ORDER)

    def column(self, gnss_id: int, sv_id: int) -> int:
        """The column of a satellite; ValueError outside the layout."""
        off = 0
        for g in (GNSS_GPS,) if self.gps_only else MULTI_ORDER:
            n = system(g).sv_max
            if g == gnss_id:
                if not 1 <= sv_id <= n:
                    break
                return off + sv_id - 1
            off += n
        raise ValueError(f"satellite ({gnss_id}, {sv_id}) is not in the simulated layout")


def carrier_hz(eph: AnyEphemeris) -> float:
    """The L1-band carrier the simulated receiver tracks on this satellite (GLONASS: from its channel k)."""
    if isinstance(eph, GlonassEphemeris):
        if not GLO_FCN_MIN <= eph.channel <= GLO_FCN_MAX:
            raise ValueError(f"GLONASS slot {eph.slot}: channel {eph.channel} outside {GLO_FCN_MIN}…{GLO_FCN_MAX}")
        return FREQ_G1_HZ + eph.channel * DFREQ_G1_HZ
    return FREQ_B1I_HZ if eph.gnss_id == GNSS_BEIDOU else FREQ_L1_HZ


def sat_of(eph: AnyEphemeris) -> tuple[int, int]:
    """(gnssId, svId) of an ephemeris."""
    return (GNSS_GLONASS, eph.slot) if isinstance(eph, GlonassEphemeris) else (eph.gnss_id, eph.prn)


def _all_ephemerides(nav: NavFile) -> list[AnyEphemeris]:
    return [*nav.ephemerides, *nav.glonass, *nav.galileo, *nav.qzss, *nav.beidou]


def read_navigation(paths: Sequence[Path]) -> tuple[list[AnyEphemeris], tuple | None, tuple | None]:
    """Every ephemeris of the files, and the first Klobuchar α/β found (InputError for a missing file)."""
    ephs: list[AnyEphemeris] = []
    alpha = beta = None
    for p in paths:
        if not Path(p).is_file():
            raise InputError(f"navigation file {p} not found: the simulator needs real broadcast orbits")
        nav = read_rinex_nav(p)
        ephs += _all_ephemerides(nav)
        if alpha is None and nav.iono_alpha is not None:
            alpha, beta = nav.iono_alpha, nav.iono_beta
    return ephs, alpha, beta


def select_broadcast(ephs: Sequence[AnyEphemeris], systems: Sequence[int], mid: GpsTime, duration_s: float,
                     margin_s: float) -> dict[tuple[int, int], AnyEphemeris]:
    """One healthy ephemeris per satellite of `systems` (Galileo: I/NAV first), toe nearest the scenario middle, valid over the whole
    scenario (the truth orbit and what is broadcast). GPS keeps the simulator's historical rule (valid over
    the simulated margin too); the other systems need validity over the scenario only (GLONASS ephemerides
    live 30 min)."""
    best: dict[tuple[int, int], AnyEphemeris] = {}
    for eph in ephs:
        key = sat_of(eph)
        if key[0] not in systems or not is_healthy(eph):
            continue
        if key[0] == GNSS_GPS:
            if not 1 <= key[1] <= 32 or abs(mid.diff_s(eph.toe)) > MAX_EPH_AGE_S - duration_s / 2 - margin_s:
                continue
        elif abs(mid.diff_s(eph.toe)) > system(key[0]).max_eph_age_s - duration_s / 2:
            continue
        if isinstance(eph, GlonassEphemeris) and not GLO_FCN_MIN <= eph.channel <= GLO_FCN_MAX:
            continue
        if not isinstance(eph, GlonassEphemeris) and eph.gnss_id == GNSS_BEIDOU and not 1 <= eph.prn <= 63:
            continue
        old = best.get(key)
        if old is None or _rank(eph, mid) < _rank(old, mid):
            best[key] = eph
    return best


def _rank(eph: AnyEphemeris, mid: GpsTime) -> tuple[bool, float]:
    """Selection order: Galileo I/NAV before F/NAV (the E1 signal's clock), then toe nearest `mid`."""
    fnav = isinstance(eph, Ephemeris) and eph.gnss_id == GNSS_GALILEO and not eph.code_on_l2 & _INAV_SOURCES
    return fnav, abs(mid.diff_s(eph.toe))


@dataclass(frozen=True)
class IfbType:
    """GLONASS inter-frequency biases of one receiver type (see module docstring); metres."""

    name: str
    phase_slope_mm_per_k: float
    phase_random_mm: float
    code_offset_m: float
    code_slope_m_per_k: float
    code_random_m: float


IFB_TYPES: dict[str, IfbType] = {t.name: t for t in (
    IfbType("ublox-m8", phase_slope_mm_per_k=0.0, phase_random_mm=0.3, code_offset_m=0.0,
            code_slope_m_per_k=0.25, code_random_m=0.3),
    IfbType("other", phase_slope_mm_per_k=-4.0, phase_random_mm=0.5, code_offset_m=1.5,
            code_slope_m_per_k=-0.6, code_random_m=0.5),
)}
"""Receiver types: the u-blox M8 family (phase IFB close to zero, RTKLIB's and u-blox's own M8 baselines fix
GLONASS between two M8s) and "other" (a different manufacturer: 4 mm per channel step)."""


def glonass_ifb(type_name: str, channels: npt.ArrayLike, rng_key: Sequence[int]) -> tuple[Vec, Vec]:
    """(code IFB m, phase IFB m) of receiver type `type_name` for GLONASS channels `channels` (k −7…+6).

    The random per-channel parts come from `rng_key` + the type's index: the same (key, type) gives the same
    biases in any receiver, so they cancel between two receivers of one type."""
    if type_name not in IFB_TYPES:
        raise ValueError(f"unknown receiver IFB type {type_name!r} (expected one of {sorted(IFB_TYPES)})")
    t = IFB_TYPES[type_name]
    idx = sorted(IFB_TYPES).index(type_name)
    rng = np.random.default_rng([int(k) & 0xFFFFFFFF for k in (*rng_key, idx)])
    n_ch = GLO_FCN_MAX - GLO_FCN_MIN + 1
    code_rand = rng.standard_normal(n_ch) * t.code_random_m
    phase_rand = rng.standard_normal(n_ch) * t.phase_random_mm * 1e-3
    k = np.asarray(channels, dtype=int)
    code = t.code_offset_m + t.code_slope_m_per_k * k + code_rand[k - GLO_FCN_MIN]
    phase = t.phase_slope_mm_per_k * 1e-3 * k + phase_rand[k - GLO_FCN_MIN]
    return np.asarray(code, float), np.asarray(phase, float)

