"""hil_sim flights through the real byte paths into our RTK engine, scored against the World's truth.

The pipeline of `bench/rtk_sim.py` (the issue-3 scenario matrix) and of its tests:
- rover: `World.observe("rover")` each second → `hil_sim.ubx_encode` RXM-RAW (LEA-6T) / RXM-RAWX (M8T) bytes →
  our UBX decoder with RTKLIB's lock rules (`onboard.postpro.convert.collect`, as `onboard rtk` reads a rover journal);
- base: `World.observe("base")` → RXM-RAW(X) bytes → the same decoder → `BaseCore` (what `onboard base` sends:
  RTCM3 1004 + 1006 + 1019 within its radio budget) → the radio (bytes of dropout windows lost) →
  `onboard.postpro.inputs.collect_rtcm` (as `onboard rtk --base` reads a radio journal);
- the engine forward (`postprocess`), ephemerides from the 1019 messages, Klobuchar from the World (the rover's
  own subframes carry them).

Multi-constellation cases (`SimCase.systems` other than "G", a world of hil_sim.scenario.MULTI_WORLDS): the
M8T rover's RXM-RAWX carries every system (gnssId/svId/freqId); the base's decoded epochs go out as RTCM3 MSM7
per constellation (MsmEncoder; 1077 GPS, 1087 GLONASS, 1097 Galileo, 1117 QZSS, 1127 BeiDou, as a u-blox base
sends) + 1006 every 10 s + the GPS 1019s, without BaseCore's radio budget; the engine gets
RtkOptions(systems=case.systems) and Nav(store, iono, broadcast=the World's broadcast set). This runner encodes
raw measurements only (as the GPS path, whose ephemerides reach BaseCore from the World): the navigation data
go to the engine as a RINEX navigation file would. The receiver emulator (hil_sim.receiver, `python -m hil_sim`)
does send RXM-SFRBX for GPS, GLONASS (strings 1–5), QZSS (LNAV) and Galileo (I/NAV types 1–5). `SimCase.harsh` puts the rover under trees
(hil_sim.scenario.HARSH) and `radio_loss` drops base seconds with a Gilbert chain (HARSH_RADIO_LOSS: the real
M8P base stream).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from onboard.gnsstime import GpsTime
from onboard.rtk.ephemeris import EphemerisStore
from onboard.rtk.options import RtkOptions
from onboard.rtk.postpro import postprocess
from onboard.rtk.rtkpos import Nav
from onboard.rtk.types import Q_FIX, ObsEpoch

STALE_S = 30.0
"""Base data older than this may not be fixed (issue 3): such epochs are excluded from the airborne ratio."""


HARSH_RADIO_LOSS = (0.50, 0.56)
"""Gilbert loss model of the base stream, (P(second lost | previous received), P(lost | previous lost)): the
Galway M8P base's RTCM3 MSM7 1077 epochs (base-20181004-1452, 1 Hz: 53 % of seconds missing, nearly
memoryless; bench/error_stats.py --harsh). A radio worse than most: the base's serial port was overloaded."""


def radio_drops(n_s: int, p_loss_after_ok: float, p_loss_after_loss: float, seed: int) -> np.ndarray:
    """Which of `n_s` seconds the radio loses (bool), a two-state Markov chain started in the received state."""
    draw = np.random.default_rng([seed & 0xFFFFFFFF, 0x52AD10]).random(n_s)
    lost = np.zeros(n_s, bool)
    prev = False
    for k in range(n_s):
        prev = bool(draw[k] < (p_loss_after_loss if prev else p_loss_after_ok))
        lost[k] = prev
    return lost


@dataclass(frozen=True)
class SimCase:
    """One scenario of the matrix (times in s after the scenario start)."""

    name: str
    target: str
    duration_s: float = 600.0
    gaps_s: tuple[tuple[float, float], ...] = ()
    """Radio dropouts [start, end): the base's RTCM frames of these seconds never reach the rover."""
    baseline_m: float | None = None
    undetected_slips_per_h: float | None = None
    """Per satellite and receiver (ErrorModel.slip_undetected_rate_per_h; default 0.02); with `harsh` also the
    rover environment's slips without LLI (RoverEnvironment.unflagged_slips_per_h; HARSH 2.6)."""
    max_sats: int | None = None
    known_start: bool = False
    seed: int = 1
    start_hour: float | None = None
    """Start at this hour (GPST) of the broadcast orbits' day (2010-07-01 for GPS; the world's day otherwise),
    for another sky; None: the Scenario's default start (13:00; a multi world's own hour)."""
    systems: str = "G"
    """Constellations (RINEX letters): "G" the historical GPS world; anything else a multi-constellation
    `world` and the engine with RtkOptions(systems=...)."""
    world: str = "gr-2012"
    """hil_sim.scenario.MULTI_WORLDS entry used when `systems` is not "G"."""
    harsh: bool = False
    """The rover under trees (RoverEnvironment HARSH)."""
    radio_loss: tuple[float, float] | None = None
    """Gilbert loss of base seconds (P(loss | received before), P(loss | lost before)), on top of `gaps_s`."""

    @property
    def multi(self) -> bool:
        return self.systems.upper() != "G"


@dataclass
class SimData:
    """Decoded inputs of one simulated flight and its truth."""

    rover: list[ObsEpoch]
    base: list[ObsEpoch]
    nav: Nav
    base_pos_ecef_m: np.ndarray
    truth: Callable[[GpsTime], dict[str, Any]]
    init_pos_ecef_m: np.ndarray | None
    rtcm_bytes: int
    lost_bytes: int


def scenario_for(case: SimCase, model: str) -> Any:
    """The hil_sim Scenario of `case` with both receivers of `model`."""
    from hil_sim.scenario import HARSH, Scenario

    over: dict[str, Any] = {"duration_s": case.duration_s, "seed": case.seed}
    if case.baseline_m is not None:
        over["base_offset_enu_m"] = Scenario.base_offset_for(case.baseline_m)
    if case.harsh:
        over["rover_environment"] = HARSH if case.undetected_slips_per_h is None else \
            replace(HARSH, unflagged_slips_per_h=case.undetected_slips_per_h)
    sc = Scenario.multi(case.world, model, systems=case.systems, **over) if case.multi else \
        Scenario.default(model, **over)
    if case.undetected_slips_per_h is not None:
        sc = replace(sc, errors=replace(sc.errors, slip_undetected_rate_per_h=case.undetected_slips_per_h))
    if case.start_hour is not None:
        midnight = sc.start.add_s(-(sc.start.tow_s % 86400.0))
        sc = replace(sc, start=midnight.add_s(case.start_hour * 3600.0))
    if case.max_sats is not None:
        sc = replace(sc, rover_receiver=replace(sc.rover_receiver, max_sats=case.max_sats),
                     base_receiver=replace(sc.base_receiver, max_sats=case.max_sats))
    return sc


def simulate(case: SimCase, model: str) -> SimData:
    """Run the World and the byte paths of `case` for rover/base receivers of `model` ("lea6t" or "m8t")."""
    from hil_sim import ubx_encode as enc
    from hil_sim.world import World
    from onboard.base.station import BaseCore, BaseOptions
    from onboard.receiver.base_epochs import collect_rtcm
    from onboard.receiver.ubx_collect import collect

    world = World(scenario_for(case, model))
    encode = enc.rxm_raw if model == "lea6t" else enc.rxm_rawx
    t0 = world.start
    n = int(case.duration_s) - 1  # the World simulates [start, start + duration): keep clear of its end
    rover_ubx = b"".join(encode(world.observe("rover", t0.add_s(k))) for k in range(n))
    base_ubx = b"".join(encode(world.observe("base", t0.add_s(k))) for k in range(n))
    rover = collect(iter([rover_ubx])).epochs
    base_decoded = collect(iter([base_ubx])).epochs
    drops = radio_drops(n + 2, *case.radio_loss, case.seed) if case.radio_loss else np.zeros(n + 2, bool)

    def lost_at(t_s: float) -> bool:
        return any(a <= t_s < b for a, b in case.gaps_s) or bool(drops[min(max(round(t_s), 0), n + 1)])

    if case.multi:
        return _simulate_multi(case, world, rover, base_decoded, lost_at)
    core = BaseCore(BaseOptions(station_id=7, position_ecef_m=tuple(float(v) for v in world.base_ecef_m),
                                radio_budget_bytes_s=2000.0))
    for eph in world.ephemerides():  # the base receiver's own subframes, decoded
        core.on_item(eph)
    radio = []
    lost = 0
    for ep in base_decoded:
        sent = b"".join(f for _, f in core.on_item(ep))
        t_s = ep.time.diff_s(t0)
        if lost_at(t_s):
            lost += len(sent)
        else:
            radio.append(sent)
    rtcm = collect_rtcm(radio, rover[0].time)
    if rtcm.base_position is None:
        raise RuntimeError(f"{case.name}: no 1006 got through")
    nav = Nav(EphemerisStore(rtcm.ephemerides), world.iono_params())
    init = world.truth(t0)["antenna_ecef_m"] if case.known_start else None
    return SimData(rover, rtcm.epochs, nav, rtcm.base_position.phase_centre_ecef_m, world.truth, init,
                   sum(len(b) for b in radio), lost)


MSM_SYSTEMS = (0, 6, 2, 5, 3)
"""gnssIds in the order a u-blox base sends their MSMs (GPS, GLONASS, Galileo, QZSS, BeiDou)."""


def _simulate_multi(case: SimCase, world: Any, rover: list[ObsEpoch], base_decoded: list[ObsEpoch],
                    lost_at: Callable[[float], bool]) -> SimData:
    """The multi-constellation base path: MSM7 per system + 1006 + GPS 1019 → radio → collect_rtcm."""
    from onboard.receiver.base_epochs import collect_rtcm
    from onboard.receiver.rtcm import BasePosition, MsmEncoder, encode_base_position, encode_ephemeris

    t0 = world.start
    msm = MsmEncoder(station_id=7)
    pos = encode_base_position(BasePosition(7, tuple(float(v) for v in world.base_ecef_m)))
    ephs = b"".join(encode_ephemeris(e) for e in world.ephemerides())
    radio: list[bytes] = []
    lost = 0
    for k, ep in enumerate(base_decoded):
        present = [g for g in MSM_SYSTEMS if np.any(ep.gnss_id == g)]
        frames = [msm.encode(ep, g, kind=7, more_follow=j < len(present) - 1) for j, g in enumerate(present)]
        sent = b"".join(f for f in frames if f is not None)
        if k % 10 == 0:
            sent = pos + (ephs if k % 60 == 0 else b"") + sent
        if lost_at(ep.time.diff_s(t0)):
            lost += len(sent)
        else:
            radio.append(sent)
    rtcm = collect_rtcm(radio, rover[0].time, glo_fcn=world.glonass_channels())
    if rtcm.base_position is None:
        raise RuntimeError(f"{case.name}: no 1006 got through")
    nav = Nav(EphemerisStore(rtcm.ephemerides or world.ephemerides()), world.iono_params(),
              broadcast=world.broadcast_navigation())
    init = world.truth(t0)["antenna_ecef_m"] if case.known_start else None
    return SimData(rover, [b.obs for b in rtcm.gnss_epochs], nav, rtcm.base_position.phase_centre_ecef_m,
                   world.truth, init, sum(len(b) for b in radio), lost)


def base_age_s(rover: list[ObsEpoch], base: list[ObsEpoch], pair_tolerance_s: float) -> np.ndarray:
    """Age (s) of the newest base epoch at each rover epoch in time order (inf before the first base epoch);
    rover tags are receiver time, within 1 ms of GPS time: a base epoch up to `pair_tolerance_s` later counts."""
    base_times = np.array(sorted(b.time.total_ns for b in base), dtype=np.int64)
    rov_ns = np.array(sorted(r.time.total_ns for r in rover), dtype=np.int64)
    i = np.searchsorted(base_times, rov_ns + round(pair_tolerance_s * 1e9), side="right") - 1
    return np.where(i >= 0, (rov_ns - base_times[np.maximum(i, 0)]) / 1e9, np.inf)


def score_epochs(q: np.ndarray, err_m: np.ndarray, armed: np.ndarray, age_s: np.ndarray,
                 t_s: np.ndarray) -> dict[str, Any]:
    """The matrix's figures of one run from per-epoch arrays: solution quality `q` (0 where none), 3D error
    from the true antenna `err_m` (m, NaN where no solution), motors `armed`, base age `age_s` and time `t_s`
    (s after the first epoch). Airborne: armed with base data at most STALE_S old; wrong: Q=1 > 10 cm in 3D
    over all epochs (stale ones included)."""
    stale = age_s > STALE_S
    fixed = q == Q_FIX
    air = armed & ~stale
    e = err_m[fixed]
    return {
        "epochs": len(q),
        "solved": int(np.sum(q > 0)),
        "fixed": int(fixed.sum()),
        "airborne": int(air.sum()),
        "air fix %": 100.0 * float(fixed[air].mean()) if air.any() else float("nan"),
        "fix %": 100.0 * float(fixed.mean()) if len(q) else 0.0,
        "3D RMS cm": 100 * float(np.sqrt(np.mean(e**2))) if e.size else float("nan"),
        "max cm": 100 * float(e.max()) if e.size else float("nan"),
        "wrong": int(np.sum(fixed & (err_m > 0.10))),
        "stale wrong": int(np.sum(fixed & stale & (err_m > 0.10))),
        "first fix s": float(t_s[int(np.argmax(fixed))]) if fixed.any() else float("nan"),
        "stale": int(stale.sum()),
        "stale fixed": int(np.sum(fixed & stale)),
    }


def evaluate(case: SimCase, model: str, options: RtkOptions | None = None,
             data: SimData | None = None, direction: str = "forward") -> dict[str, Any]:
    """Simulate (unless `data`, the simulation of `case`, is given) and solve `case` in `direction` (forward: the
    drone's real-time solution; combined: the ground's deliverable): the figures `bench/rtk_sim.py` prints (and
    per-epoch q, err_m, armed, age_s)."""
    data = data or simulate(case, model)
    opts = options or (RtkOptions(systems=case.systems.upper()) if case.multi else RtkOptions())
    if data.init_pos_ecef_m is not None:
        opts = replace(opts, static_start=True)
    t_run = time.process_time()
    sols, stats = postprocess(data.rover, data.base, data.nav, data.base_pos_ecef_m, opts, direction,
                              data.init_pos_ecef_m)
    cpu = time.process_time() - t_run
    q = np.array([s.q for s in sols])
    err = np.array([np.linalg.norm(s.pos_ecef_m - data.truth(s.time)["antenna_ecef_m"]) for s in sols])
    armed = np.array([bool(data.truth(s.time)["armed"]) for s in sols])
    age = base_age_s(data.rover, data.base, opts.pair_tolerance_s)
    t_s = np.array([s.time.diff_s(sols[0].time) for s in sols])
    return {
        **score_epochs(q, err, armed, age, t_s),
        "slips": sum(s.slips for s in stats),
        "float restarts": sum(s.float_restarts for s in stats),
        "us/epoch": 1e6 * cpu / max(len(sols), 1),
        "q": q, "err_m": err, "armed": armed, "age_s": age,
    }
