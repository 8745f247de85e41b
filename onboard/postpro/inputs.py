"""The inputs of `onboard rtk`: rover and base observations and navigation, read from files into the engine's types.

Rover and base: RINEX 2.11/3.0x observation files (gzip accepted) or UBX logs (RXM-RAW/RAWX). The base may also
be an RTCM3 stream, a mixed UBX/RTCM3 log or a journal folder (e.g. the rover's `radio/` journal), decoded by
`onboard.receiver.base_epochs` (1002/1004/1074/1077 GPS, 1005/1006 base position, 1019 ephemerides). RTCM epochs
carry no GPS week: it is resolved from the rover's first epoch. UBX epochs found in the same stream are used
instead when they outnumber the RTCM ones (a base that logs its own raw data at full rate is better than its
lossy radio stream). Unusable input raises `InputError` naming the file.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from onboard.errors import DataRefused, InputError
from onboard.gnsstime import GpsTime
from onboard.rtk.ephemeris import EphemerisStore
from onboard.rtk.rtkpos import Nav
from onboard.rtk.types import Ephemeris, ObsEpoch

if TYPE_CHECKING:
    from onboard.receiver.ubx_collect import StreamPlaces

log = logging.getLogger(__name__)

@dataclass
class ObsInput:
    """Observations read from one file: epochs, ephemerides found in it, header antenna position."""

    epochs: list[ObsEpoch]
    ephemerides: list[Ephemeris]
    antenna_pos_ecef_m: np.ndarray | None
    kind: str


def is_rinex(path: Path) -> bool:
    from onboard.formats.textfile import read_head_bytes

    head = read_head_bytes(path, 4096)
    return b"RINEX VERSION" in head[:200]


def input_chunks(path: Path, warn: Callable[[str], None] | None = None) -> tuple[Iterator[bytes], StreamPlaces]:
    """Bytes of an input (a flight journal directory, segments in order, or a UBX log, gzip accepted) and
    where each byte lives; missing segments and gzip damage go to `warn` (default: logged warnings)."""
    from onboard.receiver.decode import iter_file_bytes
    from onboard.receiver.ubx_collect import StreamPlaces

    if path.is_dir():
        from onboard.logger.journal import iter_journal_bytes, list_segments

        segments = list_segments(path)
        if not segments:
            raise InputError(f"{path}: no journal segments (*.ubx) in this directory")
        places = StreamPlaces(tuple((f"{path / p.name}", p.stat().st_size) for p in segments))
        return iter(iter_journal_bytes(path, warn=warn)), places
    if not path.exists():
        raise InputError(f"{path}: no such file")
    gz = path.is_file() and _starts_with(path, b"\x1f\x8b")
    return iter_file_bytes(path, warn=warn), StreamPlaces(((str(path), None if gz else path.stat().st_size),))


def _starts_with(path: Path, magic: bytes) -> bool:
    try:
        with open(path, "rb") as f:
            return f.read(len(magic)) == magic
    except OSError:
        return False  # the reader says why it cannot read the file


def read_observations(path: str | Path, systems: str = "G") -> ObsInput:
    """RINEX observation file (the satellites of `systems`, RINEX letters), UBX log (every system it holds), or a
    flight's journal directory (its segments in recording order, e.g. the rover's own flight folder) → ObsInput.
    Raises InputError when unusable."""
    path = Path(path)
    if path.is_dir():
        return _read_ubx(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    if is_rinex(path):
        from onboard.formats.rinex_obs import read_rinex_obs

        # only the systems used: parsing the other systems' fields was a quarter of a GPS run's reading
        # (M8P rover + RAWX base 0.065 -> 0.049 s CPU, with the GLW1 CORS base 0.091 -> 0.070 s)
        rnx = read_rinex_obs(path, systems=systems)
        return ObsInput(rnx.epochs, [], rnx.header.antenna_position_ecef_m(), "rinex")
    return _read_ubx(path)


def _read_ubx(path: Path) -> ObsInput:
    """A UBX log or journal directory → ObsInput (what the reader skipped is logged with its place)."""
    from onboard.receiver.ubx_collect import collect, describe_unframed

    chunks, places = input_chunks(path)
    col = collect(chunks)
    for message in describe_unframed(col, places):  # what the reader skipped
        log.warning("%s", message)
    if not col.epochs:
        what = "a journal directory without" if path.is_dir() else "neither a RINEX observation file nor a UBX log with"
        raise InputError(f"{path}: {what} RXM-RAW/RXM-RAWX epochs")
    pos = np.median(np.array(col.fixes_ecef_m), axis=0) if col.fixes_ecef_m else None
    return ObsInput(col.epochs, col.ephemerides, pos, "ubx")


def read_navigation(paths: Sequence[str | Path], extra: Sequence[Ephemeris] = (), systems: str = "G") -> Nav:
    """Ephemerides (and Klobuchar coefficients) from RINEX nav files plus ephemerides decoded elsewhere.

    GPS ephemerides go to `Nav.store`; those of the other systems named in `systems` (RINEX letters: R GLONASS,
    E Galileo, C BeiDou, J QZSS) to `Nav.broadcast` (None when `systems` names no other system)."""
    from onboard.formats.rinex_nav import read_rinex_nav
    from onboard.rtk.types import GNSS_GPS

    others = set(systems) - {"G"}
    gps = [isinstance(e, Ephemeris) and e.gnss_id == GNSS_GPS for e in extra]
    store = EphemerisStore(e for e, g in zip(extra, gps) if g)
    broadcast = None
    if others:  # the other systems' modules load only when asked for (start-up time of a GPS run)
        from onboard.rtk.gnss import system
        from onboard.rtk.navstore import BroadcastNavigation, sat_key

        broadcast = BroadcastNavigation(e for e, g in zip(extra, gps)
                                        if not g and system(sat_key(e)[0]).letter in others)
    iono = None
    for p in paths:
        nav = read_rinex_nav(p)
        for eph in nav.ephemerides:
            store.add(eph)
        if broadcast is not None:
            for letter, ephs in (("R", nav.glonass), ("E", nav.galileo), ("C", nav.beidou), ("J", nav.qzss)):
                if letter in others:
                    for other in ephs:
                        broadcast.add(other)
        if nav.iono_alpha is not None and nav.iono_beta is not None:
            iono = (nav.iono_alpha, nav.iono_beta)
    return Nav(store, iono, broadcast)


def read_base_observations(path: str | Path, reference: GpsTime | None, systems: str = "G") -> ObsInput:
    """Base input for `onboard rtk`: RINEX, UBX log, RTCM3 stream or mixed UBX/RTCM3 log → `ObsInput`.

    `reference` (normally the rover's first epoch time) resolves the GPS week of RTCM epochs; without it a
    pure RTCM stream is refused (its week would be a guess). The base position is the RINEX header's, else
    the stream's last 1005/1006 (phase centre = ARP + antenna height), else the median of the log's fixes.
    Raises InputError when the file holds no usable base observations.
    """
    from onboard.formats.textfile import read_head_bytes

    path = Path(path)
    if path.is_dir():  # a journal directory: the rover's radio journal (<flight>/radio) or a base flight
        return _read_journal_dir(path, reference, systems)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    head = read_head_bytes(path, 65536)
    # the RTCM3 decoders (pyrtcm) load only for a base that is not RINEX: `onboard rtk`'s start-up on RINEX
    from onboard.receiver.base_epochs import collect_rtcm, count_protocols
    from onboard.receiver.framing import Protocol
    from onboard.receiver.rtcm import RTCM_GPS_OBS
    if b"RINEX VERSION" in head[:200]:
        return read_observations(path, systems)
    from onboard.receiver.decode import iter_file_bytes

    counts = count_protocols(head)
    if not counts.get(Protocol.RTCM3):
        return read_observations(path, systems)
    if reference is None:
        raise InputError(f"{path}: an RTCM3 stream carries no GPS week; a rover time reference is needed")
    rtcm = collect_rtcm(iter_file_bytes(path), reference)
    gps_msgs = sum(n for m, n in rtcm.messages.items() if m in RTCM_GPS_OBS)
    log.info("%s: %d RTCM3 frames (%s), %d GPS epochs, %d undecodable", path, rtcm.frames,
             ", ".join(f"{m}×{n}" for m, n in sorted(rtcm.messages.items())), len(rtcm.epochs), rtcm.undecodable)
    ubx: ObsInput | None = None
    if counts.get(Protocol.UBX):
        try:
            ubx = read_observations(path)
        except InputError:
            ubx = None  # no RXM-RAW(X) epochs: the RTCM part is all there is
    pos = rtcm.base_position.phase_centre_ecef_m if rtcm.base_position is not None else None
    if ubx is not None and len(ubx.epochs) >= len(rtcm.epochs):
        return ObsInput(ubx.epochs, ubx.ephemerides + rtcm.ephemerides,
                        pos if pos is not None else ubx.antenna_pos_ecef_m, "ubx+rtcm3")
    if not rtcm.epochs:
        raise InputError(f"{path}: RTCM3 stream without GPS observations (messages: "
                         f"{sorted(rtcm.messages) or 'none'}; GPS observation messages: {gps_msgs})")
    ephs = rtcm.ephemerides + (ubx.ephemerides if ubx is not None else [])
    if systems != "G":  # every system's epochs, reassembled per epoch time (a lost message leaves a half one)
        return ObsInput([b.obs for b in rtcm.gnss_epochs], ephs, pos, "rtcm3")
    return ObsInput(rtcm.epochs, ephs, pos, "rtcm3")


def _read_journal_dir(path: Path, reference: GpsTime | None, systems: str = "G") -> ObsInput:
    """Base input from a journal directory (segments in order, torn tail tolerated): RTCM3 or UBX inside."""
    from onboard.logger.journal import iter_journal_bytes
    from onboard.receiver.base_epochs import collect_rtcm, count_protocols
    from onboard.receiver.framing import Protocol
    from onboard.receiver.ubx_collect import collect

    data = b"".join(iter_journal_bytes(path))
    counts = count_protocols(data)
    if counts.get(Protocol.RTCM3):
        if reference is None:
            raise InputError(f"{path}: an RTCM3 stream carries no GPS week; a rover time reference is needed")
        rtcm = collect_rtcm([data], reference)
        if rtcm.epochs:
            pos = rtcm.base_position.phase_centre_ecef_m if rtcm.base_position is not None else None
            epochs = rtcm.epochs if systems == "G" else [b.obs for b in rtcm.gnss_epochs]
            return ObsInput(epochs, rtcm.ephemerides, pos, "rtcm3")
    col = collect(iter([data]))
    if not col.epochs:
        raise InputError(f"{path}: journal without base observations (RTCM3 1002/1004/1074/1077 or UBX RXM-RAW(X))")
    pos = np.median(np.array(col.fixes_ecef_m), axis=0) if col.fixes_ecef_m else None
    return ObsInput(col.epochs, col.ephemerides, pos, "ubx")


@dataclass
class RtkRunInputs:
    """What the RTK engine post-processes, read and checked: GPS epochs of rover and base (time order), the
    navigation data, the base antenna position (ECEF m) and where it came from."""

    rover: list[ObsEpoch]
    base: list[ObsEpoch]
    nav: Nav
    base_pos_ecef_m: np.ndarray
    base_pos_source: str


def observed_systems(run: RtkRunInputs) -> str:
    """The constellations (RINEX letters in "GRECJ" order, for RtkOptions.systems) that both receivers observed
    and whose broadcast ephemerides `run` holds, GPS always (the engine needs it): what `run`, read with every
    constellation, can use."""
    from onboard.rtk.gnss import SYSTEMS_BY_LETTER
    from onboard.validate import GNSS_SYSTEM_LETTERS

    def seen(epochs: Sequence[ObsEpoch]) -> set[int]:
        return set().union(*(e.systems() for e in epochs))

    both = seen(run.rover) & seen(run.base)
    with_eph = {g for g, _ in run.nav.broadcast.satellites()} if run.nav.broadcast is not None else set()
    return "G" + "".join(c for c in GNSS_SYSTEM_LETTERS if c != "G" and SYSTEMS_BY_LETTER[c].gnss_id in both & with_eph)


def load_rtk_inputs(rover_path: str | Path, base_path: str | Path, nav_paths: Sequence[str | Path],
                    base_pos_ecef_m: Sequence[float] | None = None, *, base_pos_hint: str = "--base-pos X,Y,Z",
                    nav_hint: str = "--nav FILE (RINEX navigation)", systems: str = "G") -> RtkRunInputs:
    """Read rover, base and navigation files for a post-processing run and check they can make one.

    The base may be RINEX, a UBX log, an RTCM3 stream or a journal folder; `base_pos_ecef_m` overrides its header
    or stream position; `systems` (RINEX letters) are the constellations read from RINEX observations and whose
    navigation data is loaded (epochs without GPS satellites are dropped, as for GPS alone). Raises `InputError` (unusable files, no base position, no GPS observations, no common
    epochs) or `DataRefused` (no ephemeris valid at the observations' time: a navigation file of another day).
    The hints name, in the caller's words, how to give a base position and a navigation file.
    """
    from onboard.rtk.ephemeris import MAX_EPH_AGE_S
    from onboard.validate import ecef_position_m

    rover = read_observations(rover_path, systems)
    base_file = Path(base_path)
    if base_file.is_file() and is_rinex(base_file):
        base = read_observations(base_file, systems)  # without loading the RTCM3 decoders (start-up time)
    else:
        # the base may also be an RTCM3 stream or a journal folder (e.g. the rover's radio/ journal)
        base = read_base_observations(base_file, rover.epochs[0].time if rover.epochs else None, systems)
    nav = read_navigation(nav_paths, rover.ephemerides + base.ephemerides, systems)
    if len(nav.store) == 0:
        raise InputError(f"no GPS ephemeris: give {nav_hint} or logs with RXM-SFRB(X)/AID-EPH")
    if base_pos_ecef_m is not None:
        base_pos, source = np.asarray(base_pos_ecef_m, dtype=float), "given"
    elif base.antenna_pos_ecef_m is None:
        raise InputError(f"no base position: {base_path} has none in its header; give {base_pos_hint}")
    else:
        base_pos, source = np.asarray(base.antenna_pos_ecef_m, dtype=float), f"{base.kind} header/stream"
        try:
            ecef_position_m(base_pos.tolist(), name=f"{base_path}: header position")
        except ValueError as exc:
            raise InputError(f"{exc}; give {base_pos_hint}") from None
    rov_gps = [e for e in rover.epochs if len(e.gps_only())]
    bas_gps = [e for e in base.epochs if len(e.gps_only())]
    if not rov_gps:
        raise InputError(f"{rover_path}: no GPS observations")
    if not bas_gps:
        raise InputError(f"{base_path}: no GPS observations")
    t0 = max(rov_gps[0].time, bas_gps[0].time)
    t1 = min(rov_gps[-1].time, bas_gps[-1].time)
    if t1.diff_s(t0) < -30.0:
        raise InputError(f"rover ({rov_gps[0].time}..{rov_gps[-1].time}) and base ({bas_gps[0].time}.."
                         f"{bas_gps[-1].time}) have no common epochs")
    times = [rov_gps[0].time, rov_gps[len(rov_gps) // 2].time, rov_gps[-1].time]
    if not any(nav.store.select(prn, t) is not None for t in times for prn in nav.store.prns()):
        first = rov_gps[0].time.to_gpst_datetime()
        last = rov_gps[-1].time.to_gpst_datetime()
        raise DataRefused(f"no GPS ephemeris valid at the observations' time ({first:%Y-%m-%d %H:%M} to "
                          f"{last:%H:%M} GPST; {len(nav.store)} ephemerides, none within "
                          f"{MAX_EPH_AGE_S / 3600:.0f} h): is the navigation file of another day? nothing written")
    return RtkRunInputs(rov_gps, bas_gps, nav, base_pos, source)
