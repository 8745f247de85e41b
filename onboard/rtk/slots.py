"""The RTK engine's satellite slots for a set of constellations, and satellite states on them (pure).

The engine keeps one state per slot (its single-difference ambiguity, its ionosphere); a slot is one satellite
of one constellation. GPS PRN 1–32 come first (slot = PRN − 1, the GPS-only engine's layout, unchanged), then
GLONASS slots 1–24, Galileo 1–36, BeiDou 1–63 and QZSS 1–10, for the constellations used
(RtkOptions.systems). Each constellation is one double-difference group: its satellites are differenced
against its own reference, so that no inter-system bias enters (the rover and base of a set need not be of
one receiver type).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from onboard.gnsstime import NS_PER_S
from onboard.rtk.consts import (
    CLIGHT_M_S,
    CN0_MAX_DBHZ,
    DOPPLER_MAX_HZ,
    LAMBDA_L1_M,
    PR_MAX_M,
    PR_MIN_M,
    l1_wavelength_m,
)
from onboard.rtk.ephemeris import EphemerisStore, SatState, satellite_states_batch, table_states
from onboard.rtk.gnss import SYSTEMS_BY_LETTER, sat_id, system
from onboard.rtk.navstore import BroadcastNavigation
from onboard.rtk.types import FCN_NONE, GNSS_GLONASS, GNSS_GPS, ObsEpoch

SYSTEM_ORDER = "GRECJ"
"""Order of the constellations' slot blocks (GPS first: its slots are those of the GPS-only engine)."""

Arr = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class SlotLayout:
    """Slots of the constellations `systems` (RINEX letters in SYSTEM_ORDER order).

    Arrays (n,), one entry per slot: `gnss_id` (u-blox gnssId), `sv_id` (svId within it), `group` the
    double-difference group (index of its constellation in `systems`), `lam_m` the carrier wavelength (m;
    NaN for GLONASS, whose wavelength follows its frequency channel: see wavelengths). `gps_only`: the layout
    of the GPS L1 engine (32 slots, PRN − 1)."""

    systems: str
    gnss_id: npt.NDArray[np.int8]
    sv_id: npt.NDArray[np.int16]
    group: npt.NDArray[np.int8]
    lam_m: Arr
    first_slot: dict[int, int]
    """gnssId → the slot of its svId sv_min."""

    @property
    def n(self) -> int:
        """Number of slots."""
        return int(self.sv_id.shape[0])

    @property
    def gps_only(self) -> bool:
        return self.systems == "G"

    def slots_of(self, gnss_id: npt.NDArray[np.int8], sv_id: npt.NDArray[np.int16]) -> npt.NDArray[np.int64]:
        """Slot of each (gnssId, svId) entry, −1 where the layout has none (another system, a number out of range)."""
        out = np.full(gnss_id.shape[0], -1, np.int64)
        for g, first in self.first_slot.items():
            sysd = system(g)
            m = (gnss_id == g) & (sv_id >= sysd.sv_min) & (sv_id <= sysd.sv_max)
            out[m] = first + sv_id[m].astype(np.int64) - sysd.sv_min
        return out

    def letter(self, slot: int) -> str:
        """RINEX id of a slot ("G05", "R07")."""
        return sat_id(int(self.gnss_id[slot]), int(self.sv_id[slot]))


@functools.lru_cache(maxsize=16)
def slot_layout(systems: str) -> SlotLayout:
    """The layout of constellations `systems` (any order of RINEX letters; GPS first in the slots)."""
    letters = "".join(c for c in SYSTEM_ORDER if c in systems)
    if not letters:
        raise ValueError(f"no constellation in {systems!r}")
    gid, sv, grp, lam = [], [], [], []
    first: dict[int, int] = {}
    for k, c in enumerate(letters):
        s = SYSTEMS_BY_LETTER[c]
        first[s.gnss_id] = len(sv)
        nums = list(range(s.sv_min, s.sv_max + 1))
        gid += [s.gnss_id] * len(nums)
        sv += nums
        grp += [k] * len(nums)
        w = l1_wavelength_m(s.gnss_id)
        lam += [np.nan if w is None else w] * len(nums)
    arrays = (np.array(gid, np.int8), np.array(sv, np.int16), np.array(grp, np.int8), np.array(lam, float))
    for a in arrays:
        a.flags.writeable = False
    return SlotLayout(letters, *arrays, first)


def wavelengths(layout: SlotLayout, epochs: list[ObsEpoch], nav: BroadcastNavigation | None) -> Arr:
    """Carrier wavelength (m) per slot for these epochs: the layout's, GLONASS from each satellite's frequency
    channel (the observations' glo_fcn, else the broadcast ephemeris'); NaN for a GLONASS slot whose channel
    is unknown (its phase cannot be used)."""
    lam = layout.lam_m.copy()
    if GNSS_GLONASS not in layout.first_slot:
        return lam
    channel: dict[int, int] = nav.glonass_channels() if nav is not None else {}
    for e in epochs:
        if e.glo_fcn.shape[0] != len(e):
            continue
        m = (e.gnss_id == GNSS_GLONASS) & (e.glo_fcn != FCN_NONE)
        channel.update(zip(e.sv_id[m].tolist(), e.glo_fcn[m].tolist(), strict=True))
    first = layout.first_slot[GNSS_GLONASS]
    for sv, k in channel.items():
        w = l1_wavelength_m(GNSS_GLONASS, k)
        if w is not None and 1 <= sv <= 24:
            lam[first + sv - 1] = w
    return lam


def slot_arrays(layout: SlotLayout, epochs: list[ObsEpoch]) -> tuple[Arr, Arr, Arr, npt.NDArray[np.uint8], Arr]:
    """The epochs' pseudoranges (m), phases (cycles), Dopplers (Hz) (NaN where absent), LLI bits (0 where
    absent) and C/N0 (dB-Hz, NaN where absent or unknown) on the layout's slots, one row per epoch."""
    shape = (len(epochs), layout.n)
    pr, cp, dop, cn0 = (np.full(shape, np.nan) for _ in range(4))
    lli = np.zeros(shape, np.uint8)
    if not epochs:
        return pr, cp, dop, lli, cn0
    # every epoch's entries in one scatter (each epoch's in its own order, as one scatter per epoch)
    s = layout.slots_of(np.concatenate([e.gnss_id for e in epochs]), np.concatenate([e.sv_id for e in epochs]))
    m = s >= 0
    at = (np.repeat(np.arange(len(epochs)), [len(e) for e in epochs])[m], s[m])
    pr[at] = np.concatenate([e.pr_m for e in epochs])[m]
    cp[at] = np.concatenate([e.cp_cyc for e in epochs])[m]
    dop[at] = np.concatenate([e.dop_hz for e in epochs])[m]
    lli[at] = np.concatenate([e.lli for e in epochs])[m]
    cn0[at] = np.concatenate([e.cn0_dbhz for e in epochs])[m]
    screen_observations(pr, cp, dop, cn0)
    return pr, cp, dop, lli, cn0


def screen_observations(pr_m: Arr, cp_cyc: Arr, dop_hz: Arr, cn0_dbhz: Arr) -> None:
    """Blank (NaN, in place) the values no receiver can measure: a pseudorange outside [PR_MIN_M, PR_MAX_M],
    a non-finite phase, a Doppler beyond ±DOPPLER_MAX_HZ, a C/N0 outside [0, CN0_MAX_DBHZ]. Why: such a value
    in a RINEX file or a damaged message is not an outlier of the models but no measurement at all, and one
    pseudorange of 0 m puts its satellite's transmission time (and position) a tenth of a second off."""
    with np.errstate(invalid="ignore"):  # NaN compares False: left as it is
        pr_m[(pr_m < PR_MIN_M) | (pr_m > PR_MAX_M)] = np.nan
        cp_cyc[np.isinf(cp_cyc)] = np.nan
        dop_hz[~(np.abs(dop_hz) <= DOPPLER_MAX_HZ)] = np.nan
        cn0_dbhz[(cn0_dbhz < 0.0) | (cn0_dbhz > CN0_MAX_DBHZ)] = np.nan


def satellite_states_layout(layout: SlotLayout, store: EphemerisStore, nav: BroadcastNavigation | None,
                            t_rx_ns: list[int], pr_m: Arr) -> list[SatState]:
    """Satellite states (at transmission: t_rx − pr/c − satellite clock, as RTKLIB satposs) on every slot of E
    epochs: receiver times `t_rx_ns` (E,) in ns since the GPS epoch, pseudoranges `pr_m` (E, n). GPS from the
    vectorised GPS store (the GPS-only engine's numbers), Galileo, BeiDou and QZSS from `nav`'s Keplerian table
    in one pass as well, GLONASS one satellite at a time (its orbits integrated on from epoch to epoch); not ok
    where no healthy ephemeris is held."""
    n_ep, n = pr_m.shape
    prns = layout.sv_id
    g0 = layout.first_slot.get(GNSS_GPS)
    gps = None
    if g0 is not None:
        gps = satellite_states_batch(store, prns[g0:g0 + 32], t_rx_ns, pr_m[:, g0:g0 + 32])
        if layout.gps_only:
            return gps
    pos = np.zeros((n_ep, n, 3))
    vel = np.zeros((n_ep, n, 3))
    clk = np.zeros((n_ep, n))
    drift = np.zeros((n_ep, n))
    var = np.zeros((n_ep, n))
    ok = np.zeros((n_ep, n), bool)
    if gps is not None:
        for k, s in enumerate(gps):
            pos[k, g0:g0 + 32], vel[k, g0:g0 + 32], clk[k, g0:g0 + 32] = s.pos_m, s.vel_m_s, s.clock_s
            drift[k, g0:g0 + 32], var[k, g0:g0 + 32], ok[k, g0:g0 + 32] = s.drift_s_s, s.var_m2, s.ok
    if nav is not None and len(nav):
        kep = (layout.gnss_id != GNSS_GPS) & (layout.gnss_id != GNSS_GLONASS)
        if kep.any():
            # Galileo, BeiDou, QZSS: every epoch and satellite in one pass, as GPS
            table, rows = nav.kepler_table()
            j = kep.nonzero()[0]
            row = np.array([rows.get((int(g), int(v)), 0) for g, v in zip(layout.gnss_id[j], prns[j])], np.int16)
            kpos, kvel, kclk, kdrift, kvar, kok = table_states(table, row, np.asarray(t_rx_ns, np.int64),
                                                               pr_m[:, j])
            pos[:, j], vel[:, j], clk[:, j], drift[:, j], var[:, j], ok[:, j] = kpos, kvel, kclk, kdrift, kvar, kok
        t_rx = np.asarray(t_rx_ns, np.int64)
        for j in np.flatnonzero(layout.gnss_id == GNSS_GLONASS).tolist():
            k = np.flatnonzero(np.isfinite(pr_m[:, j]))
            if not k.size:
                continue
            # t_rx − pr/c as GpsTime.add_s rounds it (half to even, as round())
            t0 = t_rx[k] + np.rint(-pr_m[k, j] / CLIGHT_M_S * NS_PER_S).astype(np.int64)
            out = (pos[k, j], vel[k, j], clk[k, j], drift[k, j], var[k, j])
            got = ok[k, j]
            nav.glonass_states(int(prns[j]), t0, out, got)
            pos[k, j], vel[k, j], clk[k, j], drift[k, j], var[k, j] = out
            ok[k, j] = got
    return [SatState(prns, pos[k], vel[k], clk[k], drift[k], var[k], ok[k]) for k in range(n_ep)]


def lambda_ratio_to_gps(lam_m: Arr) -> Arr:
    """λ / λ(GPS L1) per slot: turns a slot's cycles into GPS-L1-equivalent cycles (1.0 exactly for GPS)."""
    return lam_m / LAMBDA_L1_M
