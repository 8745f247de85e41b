"""The u-blox receiver emulator's state machine: configuration, ACK/NAK, polls, and the output streams.

Pure: no file, port, thread or clock. The shell (`hil_sim.pty_server`) feeds it input frames and the
simulated GPS time; it returns the bytes the receiver would send. The physics (observations, ephemerides,
camera events, truth) come from a World (`hil_sim.world.World`, see `WorldLike`).

Modelling choices (each switchable where the documents leave the real behaviour open):

- Factory state: UART1 at 9600 baud 8N1, NMEA GGA/GLL/GSA/GSV/RMC/VTG at 1 per epoch, UBX raw off,
  measRate 1000 ms, CFG-TP5 as the real NEO-M8T dump `rtkbase_U-Blox_NEO-M8T_rtkbase.txt` (TIMEPULSE flags
  0xF7: lockedOtherSet with pulseLenRatio 0, so no pulse before valid time; TIMEPULSE2 flags 0xFE, inactive).
  The LEA-6T uses the same values with flags limited to u-blox 6's 8 bits and the version byte 0 (reserved
  there); its MON-VER is swVersion "7.03 (45969)", hwVersion "00040007" without extension strings.
- Navigation solution: NAV-SOL (both) and NAV-PVT (M8T only) = the World's antenna truth + `nav_noise_m`
  white noise, no fix before valid time; TIM-TP (next whole-second pulse) once time is valid.
- CFG-GNSS (M8T only; NAK on the LEA-6T, which has no such message): the factory blocks are those of the real
  NEO-M8T dump (GPS, SBAS, Galileo, BeiDou, QZSS on; GLONASS, IMES off; 32 channels; the flags' reserved high
  byte as dumped). A SET is applied block by block (by gnssId, keeping that byte) and NAKed unless the result
  keeps the M8 rules: msgVer 0, numTrkChUse 1–32 (0xFF = all), every block maxTrkCh ≥ resTrkCh and ≤
  numTrkChUse, an enabled major GNSS (GPS, Galileo, BeiDou, GLONASS) with maxTrkCh ≥ 4 and a signal, 1–3 major
  GNSS enabled, the enabled systems' reserved channels within numTrkChUse. RXM-RAWX then carries only the
  enabled systems. CFG-RST is never answered (as the real receiver); it is counted, no restart is modelled.
- AID-EPH polls are answered on both models (deprecated on M8, kept for the daemon's backup path).
- Every CFG input is answered at once (well within the 1 s of the spec); the ACK of a CFG-PRT baud change
  goes out at the new rate (`baud_rate` changes before the ACK is written).
- NAK: unknown messages and ids, wrong lengths, incomplete CFG-PRT (UART mode without 8N1 bits, unsupported
  baud), RXM-RAWX on u-blox 6 (or ACK-and-ignore), RXM-RAW on M8 (no such message), CFG-TP on M8, CFG-TP5
  on LEA-6T (option), NAV-PVT and RXM-SFRBX on LEA-6T, rates below the model's minimum (200 ms LEA-6T,
  100 ms M8T; or ACK with the minimum applied), bad tpIdx, pulse length ≥ period. navRate is forced to 1
  on the LEA-6T (ACKed; the poll shows 1). CFG-CFG clear/save/load act on ports, message rates and
  navigation/timepulse sections (no power cycle is modelled, so saved settings only matter for load).
- Output is limited by the configured baud's byte budget in simulated time (baud/10 B/s, a TX buffer of
  `tx_buffer_bytes`): a message that does not fit is dropped whole (a raw epoch is lost, as on real ports).
- TIM-TM2: per EXTINT channel, only the last rising and last falling edge between two navigation epochs are
  reported, at the next epoch; `count` counts rising edges. The flash pulls the hot-shoe line low (falling
  edge on channel 0) and the contact opens `contact_closed_s` later (rising). The trigger pulse (TIMEPULSE
  driving the camera, `camera_tp_idx`) is reported on channel 1 when `trigger_extint` is on.
- Camera pulses come from `world.camera_events`; the emulator gates them: no pulse (hence no photo) while the
  camera TIMEPULSE is inactive, or before valid time when it uses lockedOtherSet with pulseLenRatio 0.
- Subframes 1–3 of each tracked GPS satellite are emitted when each ends (6 s subframes, 30 s frames; 4 and
  5, almanac pages, are not simulated). An AID-EPH poll is answered with the ephemeris once its three
  subframes have been received, else with the 8-byte "no ephemeris" reply.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np

from hil_sim import galileo_pages as galp
from hil_sim import glonass_strings as gls
from hil_sim import ubx_encode as enc
from hil_sim.faults import FaultOptions, FaultState, hot_shoe_edges
from onboard.gnsstime import GLONASST_MINUS_UTC_S, NS_PER_S, GpsTime, leap_seconds_at_utc
from onboard.receiver.framing import Frame
from onboard.receiver.framing import Protocol as FrameProtocol
from onboard.rtk import lnav
from onboard.rtk.geodesy import ecef_to_llh
from onboard.rtk.types import (
    GNSS_GALILEO,
    GNSS_GLONASS,
    GNSS_GPS,
    GNSS_QZSS,
    Ephemeris,
    GlonassEphemeris,
    ObsEpoch,
)

log = logging.getLogger(__name__)

ModelName = Literal["lea6t", "m8t"]

# message ids (class, id)
RXM_RAW = (0x02, 0x10)
RXM_RAWX = (0x02, 0x15)
RXM_SFRB = (0x02, 0x11)
RXM_SFRBX = (0x02, 0x13)
NAV_SOL = (0x01, 0x06)
NAV_PVT = (0x01, 0x07)
TIM_TP = (0x0D, 0x01)
TIM_TM2 = (0x0D, 0x03)
AID_EPH = (0x0B, 0x31)
MON_VER = (0x0A, 0x04)
NMEA_IDS = {0x00: "GGA", 0x01: "GLL", 0x02: "GSA", 0x03: "GSV", 0x04: "RMC", 0x05: "VTG"}
UART1 = 1
PORT_RATE_INDEX = UART1  # CFG-MSG rates: DDC, UART1, UART2, USB, SPI, reserved
VALID_BAUDS = (4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800)
UART_MODE_8N1_MASK = 0x3EC0  # charLen (bits 6-7), parity (9-11), nStopBits (12-13)
UART_MODE_8N1 = 0x08C0

# CFG-CFG section bits (clear/save/load masks)
CFG_IOPORT = 0x0001
CFG_MSGCONF = 0x0002
CFG_NAVCONF = 0x0008

M8T_TP5_DEFAULTS: tuple[dict[str, int], dict[str, int]] = (
    # exactly the two CFG-TP5 payloads of the real NEO-M8T dump (rtkbase_U-Blox_NEO-M8T_rtkbase.txt)
    {"tpIdx": 0, "version": 1, "reserved0": 0, "antCableDelay": 50, "rfGroupDelay": 0,
     "freqPeriod": 1_000_000, "freqPeriodLock": 1_000_000, "pulseLenRatio": 0, "pulseLenRatioLock": 100_000,
     "userConfigDelay": 0, "flags": 0xF7},
    {"tpIdx": 1, "version": 1, "reserved0": 0, "antCableDelay": 50, "rfGroupDelay": 0,
     "freqPeriod": 4, "freqPeriodLock": 1, "pulseLenRatio": 125_000, "pulseLenRatioLock": 100_000,
     "userConfigDelay": 0, "flags": 0xFE},
)
# legacy CFG-TP factory values (u-blox 6 receiver description: 1 s, 100 ms, positive, UTC, 50 ns cable)
LEA6T_TP_DEFAULT: dict[str, int] = {"interval": 1_000_000, "length": 100_000, "status": 1, "timeRef": 0,
                                    "flags": 0, "reserved1": 0, "antennaCableDelay": 50, "rfGroupDelay": 0,
                                    "userDelay": 0}

# the CFG-GNSS answer of the real NEO-M8T dump: (gnssId, resTrkCh, maxTrkCh, flags)
M8T_GNSS_DEFAULTS: tuple[tuple[int, int, int, int], ...] = (
    (0, 8, 16, 0x01010001), (1, 1, 3, 0x01010001), (2, 8, 8, 0x01010001), (3, 8, 8, 0x01010001),
    (4, 0, 8, 0x03010000), (5, 0, 3, 0x05010001), (6, 8, 14, 0x01010000))
M8T_TRACKING_CHANNELS = 32
MAJOR_GNSS = frozenset({0, 2, 3, 6})  # GPS, Galileo, BeiDou, GLONASS
MAX_MAJOR_GNSS = 3
GNSS_ENABLE = 0x01
GNSS_SIG_MASK = 0x00FF0000
GNSS_RESERVED_HIGH = 0xFF000000

TP5_ACTIVE = 0x01
TP5_LOCKED_OTHER_SET = 0x04
TP5_IS_FREQ = 0x08
TP5_IS_LENGTH = 0x10
TP5_ALIGN_TO_TOW = 0x20


@dataclass(frozen=True)
class ModelSpec:
    """What distinguishes the emulated receiver models (strings as the real firmware reports them)."""

    name: ModelName
    sw_version: str
    hw_version: str
    extensions: tuple[str, ...]
    raw_msg: tuple[int, int]
    subframe_msg: tuple[int, int]
    has_cfg_tp: bool
    min_meas_rate_ms: int
    tp5_flags_mask: int
    time_refs: tuple[int, ...]


MODELS: dict[str, ModelSpec] = {
    # u-blox 6 ROM 7.03: swVersion "7.03 (45969)", hwVersion "00040007" and no extension strings (public
    # NEO-6M captures and drivers report none; protocol version 13/14 is implied, not advertised)
    "lea6t": ModelSpec("lea6t", "7.03 (45969)", "00040007", (), RXM_RAW, RXM_SFRB, True, 200,
                       0xFF, (0, 1)),
    # the real NEO-M8T MON-VER of the rtkbase dump
    "m8t": ModelSpec("m8t", "EXT CORE 3.01 (111141)", "00080000",
                     ("ROM BASE 2.01 (75331)", "FWVER=TIM 1.10", "PROTVER=22.00", "MOD=NEO-M8T-0",
                      "FIS=0xEF4015 (100111)", "GPS;GLO;GAL;BDS", "SBAS;IMES;QZSS"),
                     RXM_RAWX, RXM_SFRBX, False, 100, 0x3FFF, (0, 1, 2, 3, 4)),
}


@dataclass(frozen=True)
class ReceiverOptions:
    """Behaviours of the emulated receiver (documents leave them open, so each is switchable).

    `align_to_tow`: "clear" clears alignToTow for periods that do not divide 1 s, "keep" keeps it.
    `rawx_on_u6`: "nak" or "ack-ignore" for CFG-MSG enabling RXM-RAWX on a LEA-6T.
    `tp5_on_u6`: "ack" (FW ≥ 7.0) or "nak" (older firmware) for CFG-TP5 on a LEA-6T.
    `silent`: never answers any input, streams the factory output.
    `ack_invalid_rates`: ACK a CFG-RATE below the minimum but apply the minimum instead.
    `trigger_extint`: the trigger pulse is wired to EXTINT1 (TIM-TM2 channel 1).
    `camera_tp_idx`: which TIMEPULSE drives the camera. `time_valid_after_s`: simulated time to first fix.
    `contact_closed_s`: hot-shoe contact closure (falling→rising). `acc_est_ns`: TIM-TM2 accEst.
    `mark_noise_ns`: σ of the TIM-TM2 time error. `tx_buffer_bytes`: TX buffer (budget burst).
    `nav_noise_m`: σ of the NAV-SOL/NMEA position around the truth.
    """

    align_to_tow: Literal["clear", "keep"] = "clear"
    rawx_on_u6: Literal["nak", "ack-ignore"] = "nak"
    tp5_on_u6: Literal["ack", "nak"] = "ack"
    silent: bool = False
    ack_invalid_rates: bool = False
    trigger_extint: bool = False
    camera_tp_idx: int = 1
    time_valid_after_s: float = 2.0
    contact_closed_s: float = 0.004
    acc_est_ns: int = 21
    mark_noise_ns: float = 7.0
    tx_buffer_bytes: int = 4096
    nav_noise_m: float = 1.5
    receiver: Literal["rover", "base"] = "rover"
    faults: FaultOptions = field(default_factory=FaultOptions)


class WorldLike(Protocol):
    """What the emulator needs from the simulated world (hil_sim.world.World provides it)."""

    def observe(self, receiver: str, t_rx_nominal: GpsTime) -> ObsEpoch: ...

    def ephemerides(self) -> list[Ephemeris]: ...

    def camera_events(self, t0: GpsTime, t1: GpsTime) -> list[Any]: ...

    def truth(self, t: GpsTime) -> Mapping[str, Any]: ...


@dataclass
class ReceiverStats:
    """Counters the shell and tests read."""

    frames_in: int = 0
    acked: int = 0
    naked: int = 0
    polls_answered: int = 0
    gnss_restarts: int = 0
    epochs_out: int = 0
    epochs_dropped_budget: int = 0
    epochs_dropped_fault: int = 0
    messages_dropped_budget: int = 0
    subframes_out: int = 0
    marks_out: int = 0
    marks_dropped_fault: int = 0
    edges_lost: int = 0
    pulses_suppressed: int = 0


class TxBudget:
    """Token bucket of the UART transmitter in simulated time: baud/10 bytes per second, `capacity_b` burst."""

    def __init__(self, baud: int, capacity_b: int) -> None:
        self.baud = baud
        self.capacity_b = capacity_b
        self.tokens_b = float(capacity_b)

    def refill(self, dt_s: float) -> None:
        """Add the bytes the line can carry in `dt_s` simulated seconds."""
        self.tokens_b = min(float(self.capacity_b), self.tokens_b + max(0.0, dt_s) * self.baud / 10.0)

    def take(self, n_bytes: int) -> bool:
        """True (and spend) when `n_bytes` fit now; False leaves the budget untouched (message dropped)."""
        if n_bytes > self.tokens_b:
            return False
        self.tokens_b -= n_bytes
        return True


class TimeMarkChannel:
    """One EXTINT input of the time-mark unit: keeps the last rising/falling edge since the last report."""

    def __init__(self, channel: int) -> None:
        self.channel = channel
        self.count = 0
        self.rising: GpsTime | None = None
        self.falling: GpsTime | None = None
        self.new_rising = False
        self.new_falling = False
        self.edges_since_report = 0
        self.edges_lost = 0
        """Edges overwritten by a later edge of the same polarity before a report (lost marks)."""

    def edge(self, t: GpsTime, rising: bool) -> None:
        """Register an edge at GPS time `t` (a later edge of the same polarity overwrites the earlier one)."""
        self.edges_since_report += 1
        if rising:
            self.count = (self.count + 1) & 0xFFFF
            self.rising, self.new_rising = t, True
        else:
            self.falling, self.new_falling = t, True

    def report(self, time_valid: bool, acc_est_ns: int) -> enc.TimeMarkReport | None:
        """The TIM-TM2 content at a navigation epoch (None when no new edge arrived); clears the 'new' bits."""
        if not (self.new_rising or self.new_falling):
            return None
        rep = enc.TimeMarkReport(self.channel, self.count, self.rising, self.falling, self.new_rising,
                                 self.new_falling, time_valid, acc_est_ns)
        self.edges_lost += self.edges_since_report - int(self.new_rising) - int(self.new_falling)
        self.new_rising = self.new_falling = False
        self.edges_since_report = 0
        return rep


def _factory_msg_rates() -> dict[tuple[int, int], list[int]]:
    return {(0xF0, mid): [1, 1, 0, 1, 1, 0] for mid in NMEA_IDS}


def _factory_ports() -> dict[int, dict[str, int]]:
    uart = {"portID": UART1, "reserved0": 0, "txReady": 0, "mode": UART_MODE_8N1, "baudRate": 9600,
            "inProtoMask": 0x0007, "outProtoMask": 0x0003, "flags": 0, "reserved5": 0}
    return {0: {**uart, "portID": 0, "mode": 0x84, "baudRate": 0},
            1: uart,
            2: {**uart, "portID": 2},
            3: {**uart, "portID": 3, "mode": 0, "baudRate": 0},
            4: {**uart, "portID": 4, "mode": 0, "baudRate": 0}}


@dataclass
class Config:
    """The configuration sections the emulator models (field dicts keyed by the layouts' names)."""

    ports: dict[int, dict[str, int]]
    msg_rates: dict[tuple[int, int], list[int]]
    rate: dict[str, int]
    tp5: dict[int, dict[str, int]]
    tp: dict[str, int]
    gnss: dict[int, dict[str, int]] = field(default_factory=dict)
    """CFG-GNSS blocks by gnssId (M8T; empty on the LEA-6T)."""
    num_trk_ch_use: int = M8T_TRACKING_CHANNELS

    @classmethod
    def factory(cls, model: ModelSpec) -> Config:
        # u-blox 6 has no CFG-TP5 version byte (reserved, reads 0) and only 8 flag bits
        version = 1 if model.name == "m8t" else 0
        tp5 = {i: {**d, "version": version, "flags": d["flags"] & model.tp5_flags_mask}
               for i, d in enumerate(M8T_TP5_DEFAULTS)}
        gnss = ({g: {"gnssId": g, "resTrkCh": r, "maxTrkCh": m, "reserved1": 0, "flags": f}
                 for g, r, m, f in M8T_GNSS_DEFAULTS} if model.name == "m8t" else {})
        return cls(_factory_ports(), _factory_msg_rates(), {"measRate": 1000, "navRate": 1, "timeRef": 1},
                   tp5, dict(LEA6T_TP_DEFAULT), gnss)

    def copy(self) -> Config:
        return Config({k: dict(v) for k, v in self.ports.items()},
                      {k: list(v) for k, v in self.msg_rates.items()}, dict(self.rate),
                      {k: dict(v) for k, v in self.tp5.items()}, dict(self.tp),
                      {k: dict(v) for k, v in self.gnss.items()}, self.num_trk_ch_use)

    def gnss_enabled(self) -> frozenset[int] | None:
        """gnssIds enabled by CFG-GNSS (None: the model has no CFG-GNSS and tracks what it tracks)."""
        if not self.gnss:
            return None
        return frozenset(g for g, b in self.gnss.items() if b["flags"] & GNSS_ENABLE)


def _period_divides_second(value: int, is_freq: bool) -> bool:
    if is_freq:
        return value >= 1
    return value > 0 and 1_000_000 % value == 0


class ReceiverCore:
    """The receiver: `handle_frame` answers input, `advance` produces the output up to a simulated time.

    `t_start` is the GPS time at power-on (time becomes valid `time_valid_after_s` later).
    """

    def __init__(self, model: ModelName | str, options: ReceiverOptions, world: WorldLike,
                 t_start: GpsTime) -> None:
        if model not in MODELS:
            raise ValueError(f"unknown receiver model {model!r}; known: {', '.join(MODELS)}")
        self.model = MODELS[model]
        self.options = options
        self.world = world
        self.t_start = t_start
        self.config = Config.factory(self.model)
        self.saved = self.config.copy()
        self.stats = ReceiverStats()
        self.faults = FaultState(options.faults)
        self.budget = TxBudget(self.baud_rate, options.tx_buffer_bytes)
        self.marks = {0: TimeMarkChannel(0), 1: TimeMarkChannel(1)}
        self._t_last: GpsTime | None = None
        self._sf_last: GpsTime | None = None
        self._next_epoch: GpsTime | None = None
        self._epoch_index = 0
        self._events_until: GpsTime = t_start
        self._pending_edges: list[tuple[GpsTime, int, bool]] = []
        self._eph_received: dict[int, Ephemeris] = {}
        self._subframes_seen: dict[int, set[tuple[int, int]]] = {}
        self._frame_cache: dict[tuple[int, int], list[list[int]]] = {}
        self._tracked: list[int] = []
        self._tracked_glo: list[tuple[int, int]] = []
        """(slot, channel k) of the GLONASS satellites tracked at the last epoch (M8T with GLONASS enabled)."""
        self._glo_ephs: dict[int, GlonassEphemeris] | None = None
        self._tracked_qzss: list[int] = []
        self._tracked_gal: list[int] = []
        self._gal_ephs: dict[int, Any] | None = None
        self._qzss_ephs: dict[int, Ephemeris] | None = None
        self._ephs: list[Ephemeris] | None = None
        self._rng = np.random.default_rng(options.faults.seed + 17)
        self.dropped_flash_reports: list[enc.TimeMarkReport] = []
        """TIM-TM2 flash-line reports withheld by the `drop_flash_mark_rate` fault (truth for tests)."""
        self.on_camera_pulse: Callable[[Any], None] | None = None
        """Called with each camera event whose trigger pulse this receiver emitted (after the TIMEPULSE gate),
        as the pulse is produced: the autopilot stand-in's CAMERA_FEEDBACK follows the same camera."""
        end = getattr(world, "end", None)
        self.t_end: GpsTime | None = end if isinstance(end, GpsTime) else None
        self._ended_logged = False
        self._period_warned = False
        self._handlers: dict[tuple[int, int], Callable[[bytes], list[bytes]]] = {
            (0x06, 0x00): self._cfg_prt, (0x06, 0x01): self._cfg_msg, (0x06, 0x08): self._cfg_rate,
            (0x06, 0x31): self._cfg_tp5, (0x06, 0x07): self._cfg_tp, (0x06, 0x09): self._cfg_cfg,
            (0x06, 0x3E): self._cfg_gnss, (0x06, 0x04): self._cfg_rst,
            MON_VER: self._mon_ver, AID_EPH: self._aid_eph,
        }

    # ----------------------------------------------------------------------------------------- state
    @property
    def baud_rate(self) -> int:
        """UART1's configured line rate (the rate the client must use)."""
        return self.config.ports[UART1]["baudRate"]

    def time_valid(self, t: GpsTime) -> bool:
        """True once the receiver has a fix and valid GPS time."""
        return t.diff_s(self.t_start) >= self.options.time_valid_after_s

    def _out_ubx(self) -> bool:
        return bool(self.config.ports[UART1]["outProtoMask"] & 0x1)

    def _out_nmea(self) -> bool:
        return bool(self.config.ports[UART1]["outProtoMask"] & 0x2)

    def rate_of(self, msg: tuple[int, int]) -> int:
        """CFG-MSG output rate of `msg` on UART1 (0 = off)."""
        return self.config.msg_rates.get(msg, [0] * 6)[PORT_RATE_INDEX]

    # ----------------------------------------------------------------------------------------- input
    def handle_frame(self, frame: Frame) -> list[bytes]:
        """Answer one input frame: a list of frames to send (ACK/NAK, poll replies), possibly empty."""
        self.stats.frames_in += 1
        if self.options.silent or frame.protocol is not FrameProtocol.UBX:
            return []
        if not self.config.ports[UART1]["inProtoMask"] & 0x1:
            return []
        key = (frame.msg_class, frame.msg_id)
        handler = self._handlers.get(key)
        if handler is None:
            log.info("unknown UBX message 0x%02X 0x%02X: NAK", *key)
            return [self._nak(key)]
        return handler(frame.payload)

    def _ack(self, key: tuple[int, int]) -> bytes:
        self.stats.acked += 1
        return enc.ack(key[0], key[1], True)

    def _nak(self, key: tuple[int, int]) -> bytes:
        self.stats.naked += 1
        return enc.ack(key[0], key[1], False)

    def _poll_reply(self, name: str, head: Mapping[str, Any], rows: Sequence[Mapping[str, Any]] = ()) -> bytes:
        self.stats.polls_answered += 1
        return enc.frame(name, head, rows)

    def _cfg_prt(self, payload: bytes) -> list[bytes]:
        key = (0x06, 0x00)
        if len(payload) == 0:
            return [self._poll_reply("CFG-PRT", self.config.ports[UART1]), self._ack(key)]
        if len(payload) == 1:
            if payload[0] not in self.config.ports:
                return [self._nak(key)]
            return [self._poll_reply("CFG-PRT", self.config.ports[payload[0]]), self._ack(key)]
        if len(payload) != 20:
            return [self._nak(key)]
        new, _ = enc.unpack(enc.LAYOUTS["CFG-PRT"], payload)
        port = new["portID"]
        if port not in self.config.ports:
            return [self._nak(key)]
        uart_bad = new["mode"] & UART_MODE_8N1_MASK != UART_MODE_8N1 or new["baudRate"] not in VALID_BAUDS
        if port in (1, 2) and uart_bad:
            log.info("CFG-PRT incomplete or unsupported (mode 0x%X, baud %d): NAK", new["mode"], new["baudRate"])
            return [self._nak(key)]
        self.config.ports[port] = new
        if port == UART1:
            self.budget.baud = new["baudRate"]
        # the ACK leaves at the new rate: the shell writes it after reading `baud_rate`
        return [self._ack(key)]

    def _cfg_msg(self, payload: bytes) -> list[bytes]:
        key = (0x06, 0x01)
        if len(payload) == 2:
            msg = (payload[0], payload[1])
            rates = self.config.msg_rates.get(msg, [0] * 6)
            return [self._poll_reply("CFG-MSG", {"msgClass": msg[0], "msgID": msg[1], "rateDDC": rates[0],
                                                 "rateUART1": rates[1], "rateUART2": rates[2], "rateUSB": rates[3],
                                                 "rateSPI": rates[4], "reserved": rates[5]}), self._ack(key)]
        if len(payload) == 3:
            msg = (payload[0], payload[1])
            rates = list(self.config.msg_rates.get(msg, [0] * 6))
            rates[PORT_RATE_INDEX] = payload[2]
        elif len(payload) == 8:
            msg = (payload[0], payload[1])
            rates = list(payload[2:8])
        else:
            return [self._nak(key)]
        if self.model.name == "lea6t" and msg == RXM_RAWX:
            if self.options.rawx_on_u6 == "nak":
                return [self._nak(key)]
            return [self._ack(key)]  # acknowledged, never produced
        if self.model.name == "m8t" and msg in (RXM_RAW, RXM_SFRB):
            return [self._nak(key)]
        if self.model.name == "lea6t" and msg in (RXM_SFRBX, NAV_PVT):
            return [self._nak(key)]  # u-blox 7/8 messages a FW 7.03 does not know
        self.config.msg_rates[msg] = rates
        return [self._ack(key)]

    def _cfg_rate(self, payload: bytes) -> list[bytes]:
        key = (0x06, 0x08)
        if len(payload) == 0:
            return [self._poll_reply("CFG-RATE", self.config.rate), self._ack(key)]
        if len(payload) != 6:
            return [self._nak(key)]
        new, _ = enc.unpack(enc.LAYOUTS["CFG-RATE"], payload)
        if new["timeRef"] not in self.model.time_refs or new["navRate"] == 0:
            return [self._nak(key)]
        if new["measRate"] < self.model.min_meas_rate_ms:
            if not self.options.ack_invalid_rates:
                return [self._nak(key)]
            log.info("CFG-RATE measRate %d ms below the minimum: ACKed, %d ms applied", new["measRate"],
                     self.model.min_meas_rate_ms)
            new["measRate"] = self.model.min_meas_rate_ms
        if self.model.name == "lea6t":
            new["navRate"] = 1  # fixed on u-blox 5/6 whatever is sent
        self.config.rate = new
        self._next_epoch = None  # re-grid the epochs on the new rate
        return [self._ack(key)]

    def _cfg_tp5(self, payload: bytes) -> list[bytes]:
        key = (0x06, 0x31)
        if self.model.name == "lea6t" and self.options.tp5_on_u6 == "nak":
            return [self._nak(key)]
        if len(payload) in (0, 1):
            idx = payload[0] if payload else 0
            if idx not in self.config.tp5:
                return [self._nak(key)]
            return [self._poll_reply("CFG-TP5", self.config.tp5[idx]), self._ack(key)]
        if len(payload) != 32:
            return [self._nak(key)]
        new, _ = enc.unpack(enc.LAYOUTS["CFG-TP5"], payload)
        if new["tpIdx"] not in self.config.tp5:
            return [self._nak(key)]
        flags = new["flags"] & self.model.tp5_flags_mask
        is_freq = bool(flags & TP5_IS_FREQ)
        pairs = ((new["freqPeriod"], new["pulseLenRatio"]), (new["freqPeriodLock"], new["pulseLenRatioLock"]))
        if not is_freq and flags & TP5_IS_LENGTH:
            for period_us, length_us in pairs:
                if period_us > 0 and length_us >= period_us:
                    log.info("CFG-TP5 pulse length %d µs ≥ period %d µs: NAK", length_us, period_us)
                    return [self._nak(key)]
        if flags & TP5_ALIGN_TO_TOW and self.options.align_to_tow == "clear":
            used = pairs if flags & TP5_LOCKED_OTHER_SET else pairs[:1]
            if not all(_period_divides_second(p, is_freq) for p, _ in used):
                flags &= ~TP5_ALIGN_TO_TOW
                log.info("CFG-TP5 tpIdx %d: period does not divide 1 s, alignToTow cleared", new["tpIdx"])
        new["flags"] = flags
        if self.model.name == "lea6t":
            new["version"] = 0  # a reserved byte on u-blox 6: polls read it back as 0
        self.config.tp5[new["tpIdx"]] = new
        return [self._ack(key)]

    def _cfg_tp(self, payload: bytes) -> list[bytes]:
        key = (0x06, 0x07)
        if not self.model.has_cfg_tp:
            return [self._nak(key)]
        if len(payload) == 0:
            return [self._poll_reply("CFG-TP", self.config.tp), self._ack(key)]
        if len(payload) != 20:
            return [self._nak(key)]
        new, _ = enc.unpack(enc.LAYOUTS["CFG-TP"], payload)
        if new["timeRef"] > 2 or (new["status"] != 0 and new["length"] >= new["interval"]):
            return [self._nak(key)]
        self.config.tp = new
        return [self._ack(key)]

    def _cfg_gnss(self, payload: bytes) -> list[bytes]:
        key = (0x06, 0x3E)
        if self.model.name != "m8t":
            return [self._nak(key)]
        if len(payload) == 0:
            head = {"msgVer": 0, "numTrkChHw": M8T_TRACKING_CHANNELS, "numTrkChUse": self.config.num_trk_ch_use}
            return [self._poll_reply("CFG-GNSS", head, [self.config.gnss[g] for g in sorted(self.config.gnss)]),
                    self._ack(key)]
        try:
            head, rows = enc.unpack(enc.LAYOUTS["CFG-GNSS"], payload)
        except enc.LayoutError:
            return [self._nak(key)]
        use = M8T_TRACKING_CHANNELS if head["numTrkChUse"] == 0xFF else head["numTrkChUse"]
        if head["msgVer"] != 0 or not 1 <= use <= M8T_TRACKING_CHANNELS:
            return [self._nak(key)]
        new = {g: dict(b) for g, b in self.config.gnss.items()}
        for row in rows:
            if row["gnssId"] not in new:
                return [self._nak(key)]
            kept_high = new[row["gnssId"]]["flags"] & GNSS_RESERVED_HIGH  # the receiver's own reserved byte
            new[row["gnssId"]] = {**row, "reserved1": 0, "flags": (row["flags"] & ~GNSS_RESERVED_HIGH) | kept_high}
        enabled = [b for b in new.values() if b["flags"] & GNSS_ENABLE]
        majors = [b for b in enabled if b["gnssId"] in MAJOR_GNSS]
        valid = (all(b["resTrkCh"] <= b["maxTrkCh"] <= use for b in new.values())
                 and all(b["maxTrkCh"] >= 4 for b in majors)
                 and all(b["flags"] & GNSS_SIG_MASK for b in enabled)
                 and 1 <= len(majors) <= MAX_MAJOR_GNSS
                 and sum(b["resTrkCh"] for b in enabled) <= use)
        if not valid:
            log.info("CFG-GNSS breaks the M8 channel rules (%d major enabled, %d channels): NAK", len(majors), use)
            return [self._nak(key)]
        self.config.gnss = new
        self.config.num_trk_ch_use = use
        return [self._ack(key)]

    def _cfg_rst(self, payload: bytes) -> list[bytes]:
        if len(payload) == 4:
            self.stats.gnss_restarts += 1  # never acknowledged; tracking goes on (no restart modelled)
        return []

    def _cfg_cfg(self, payload: bytes) -> list[bytes]:
        key = (0x06, 0x09)
        if len(payload) not in (12, 13):
            return [self._nak(key)]
        head, _ = enc.unpack(enc.LAYOUTS["CFG-CFG"], payload[:12])
        factory = Config.factory(self.model)
        sections: tuple[tuple[int, tuple[str, ...]], ...] = (
            (CFG_IOPORT, ("ports",)), (CFG_MSGCONF, ("msg_rates",)), (CFG_NAVCONF, ("rate", "tp5", "tp", "gnss", "num_trk_ch_use")))
        for bit, names in sections:
            for name in names:
                if head["clearMask"] & bit:
                    setattr(self.saved, name, getattr(factory.copy(), name))
                if head["saveMask"] & bit:
                    setattr(self.saved, name, getattr(self.config.copy(), name))
                if head["loadMask"] & bit:
                    setattr(self.config, name, getattr(self.saved.copy(), name))
        self.budget.baud = self.baud_rate
        return [self._ack(key)]

    def _mon_ver(self, payload: bytes) -> list[bytes]:
        if payload:
            return [self._nak(MON_VER)]
        self.stats.polls_answered += 1
        return [enc.mon_ver(self.model.sw_version, self.model.hw_version, self.model.extensions)]

    def _aid_eph(self, payload: bytes) -> list[bytes]:
        if len(payload) == 0:
            prns: Iterable[int] = range(1, 33)
        elif len(payload) == 1 and 1 <= payload[0] <= 32:
            prns = (payload[0],)
        else:
            return [self._nak(AID_EPH)]  # a 104-byte AID-EPH *input* (aiding) is not modelled
        out = []
        for prn in prns:
            eph = self._eph_received.get(prn)
            self.stats.polls_answered += 1
            if eph is None:
                out.append(enc.aid_eph(prn))
            else:
                how, words = lnav.aid_eph_words(eph)
                out.append(enc.aid_eph(prn, how, words))
        return out

    # ----------------------------------------------------------------------------------------- output
    @property
    def next_epoch(self) -> GpsTime | None:
        """The next measurement epoch the receiver will output (None before the first `advance`)."""
        return self._next_epoch

    def next_epoch_time(self, t: GpsTime) -> GpsTime:
        """The first measurement epoch (nominal GPS time on the measRate grid) strictly after `t`."""
        step = self.config.rate["measRate"] * 1_000_000
        return GpsTime.from_total_ns((t.total_ns // step + 1) * step)

    def advance(self, t: GpsTime) -> list[bytes]:
        """Everything the receiver sends from the last call up to simulated GPS time `t`, in order."""
        out: list[bytes] = []
        if self._t_last is None:
            self._t_last = t
            self._next_epoch = self.next_epoch_time(t)
            return out
        self.budget.refill(t.diff_s(self._t_last))
        if self._next_epoch is None:
            self._next_epoch = self.next_epoch_time(self._t_last)
        while self._next_epoch <= t:
            te = self._next_epoch
            out += self._subframes_until(te)
            out += self._epoch(te)
            self._next_epoch = self.next_epoch_time(te)
        self._t_last = t
        return out

    def _send(self, out: list[bytes], data: bytes) -> bool:
        if self.budget.take(len(data)):
            out.append(data)
            return True
        self.stats.messages_dropped_budget += 1
        return False

    def _epoch(self, t: GpsTime) -> list[bytes]:
        out: list[bytes] = []
        if self.t_end is not None and t > self.t_end:
            # the world is simulated only over its scenario: afterwards the receiver lost all signals
            if not self._ended_logged:
                log.warning("scenario ended at %s: no more measurements", self.t_end)
                self._ended_logged = True
            return out
        self._epoch_index += 1
        idx = self._epoch_index
        valid = self.time_valid(t)
        obs = self.world.observe(self.options.receiver, t)
        enabled = self.config.gnss_enabled()
        if enabled is not None and not np.all(np.isin(obs.gnss_id, list(enabled))):
            obs = obs.select(np.isin(obs.gnss_id, list(enabled)))  # CFG-GNSS: disabled systems are not tracked
        self._tracked = sorted(int(s) for g, s in zip(obs.gnss_id, obs.sv_id, strict=True)
                               if int(g) == GNSS_GPS and 1 <= int(s) <= 32)
        self._tracked_qzss = sorted(int(s) for g, s in zip(obs.gnss_id, obs.sv_id, strict=True) if int(g) == GNSS_QZSS)
        self._tracked_gal = sorted(int(s) for g, s in zip(obs.gnss_id, obs.sv_id, strict=True) if int(g) == GNSS_GALILEO)
        if obs.glo_fcn.shape[0] == len(obs):
            self._tracked_glo = sorted((int(s), int(k)) for g, s, k in zip(obs.gnss_id, obs.sv_id, obs.glo_fcn,
                                                                          strict=True) if int(g) == GNSS_GLONASS)
        self._process_camera(t)

        def due(msg: tuple[int, int]) -> bool:
            r = self.rate_of(msg)
            return r > 0 and idx % r == 0

        fix = self._nav_fix(t, len(obs)) if valid else None
        if self._out_ubx():
            if due(NAV_SOL):
                pos, vel = fix if fix is not None else (None, None)
                self._send(out, enc.nav_sol(t, pos, vel, num_sv=len(obs) if valid else 0, p_acc_m=2.5, pdop=1.6))
            if due(NAV_PVT) and self.model.name == "m8t":
                pos, vel = fix if fix is not None else (None, None)
                self._send(out, enc.nav_pvt(t, pos, vel, num_sv=len(obs) if valid else 0, h_acc_m=2.0, pdop=1.6))
            if due(self.model.raw_msg):
                if self.faults.drop_epoch():
                    self.stats.epochs_dropped_fault += 1
                else:
                    raw = enc.rxm_raw(obs) if self.model.raw_msg == RXM_RAW else enc.rxm_rawx(obs)
                    if self._send(out, raw):
                        self.stats.epochs_out += 1
                    else:
                        self.stats.epochs_dropped_budget += 1
            for ch in (0, 1):
                rep = self.marks[ch].report(valid, self.options.acc_est_ns)
                if rep is None or not due(TIM_TM2):
                    continue
                if ch == 0 and self.faults.drop_flash_mark():
                    self.stats.marks_dropped_fault += 1
                    self.dropped_flash_reports.append(rep)
                elif self._send(out, enc.tim_tm2(rep)):
                    self.stats.marks_out += 1
            self.stats.edges_lost = self.marks[0].edges_lost + self.marks[1].edges_lost
            if due(TIM_TP):
                step = self.config.rate["measRate"] * 1_000_000
                next_pulse = GpsTime.from_total_ns((t.total_ns // NS_PER_S + 1) * NS_PER_S)
                if next_pulse.total_ns - t.total_ns <= step and valid:
                    self._send(out, enc.tim_tp(next_pulse))
        else:
            for ch in (0, 1):
                self.marks[ch].report(valid, self.options.acc_est_ns)
        if self._out_nmea():
            for mid, name in NMEA_IDS.items():
                if due((0xF0, mid)):
                    self._send(out, _nmea(name, t, fix, obs))
        return out

    def _nav_fix(self, t: GpsTime, n_sv: int) -> tuple[np.ndarray, np.ndarray] | None:
        if n_sv < 4:
            return None
        pos, vel = antenna_state(self.world.truth(t), self.options.receiver)
        return pos + self._rng.normal(0.0, self.options.nav_noise_m, 3), vel

    # ---- subframes
    def _ephemeris_for(self, prn: int, t: GpsTime) -> Ephemeris | None:
        if self._ephs is None:
            self._ephs = list(self.world.ephemerides())
        best: Ephemeris | None = None
        best_key = math.inf
        for eph in self._ephs:
            if eph.prn != prn:
                continue
            ahead_s = eph.toe.diff_s(t)
            # the broadcast set in use has its toe 0–2 h ahead of now; otherwise take the nearest
            key = ahead_s if 0 <= ahead_s < 7200 else 1e7 + abs(ahead_s)
            if key < best_key:
                best, best_key = eph, key
        return best

    def _subframes_until(self, t: GpsTime) -> list[bytes]:
        """Subframes 1–3 of every tracked satellite that ended in (last epoch, t]."""
        out: list[bytes] = []
        if self.t_end is not None and t > self.t_end:
            return out
        six = 6 * NS_PER_S
        since = self._sf_last if self._sf_last is not None else t
        self._sf_last = t
        first = since.total_ns // six + 1
        last = t.total_ns // six
        want = self.rate_of(self.model.subframe_msg) > 0 and self._out_ubx()
        for k in range(first, last + 1):
            end = GpsTime.from_total_ns(k * six)
            sf_id = (round(end.tow_ns / six) - 1) % 5 + 1
            if sf_id > 3:
                continue
            frame_start = end.add_ns(-6 * NS_PER_S * sf_id)
            for chn, prn in enumerate(self._tracked):
                eph = self._ephemeris_for(prn, end)
                if eph is None:
                    continue
                ck = (prn, frame_start.total_ns // NS_PER_S)
                frame = self._lnav_frame(ck, eph, frame_start, f"PRN {prn}")
                if frame is None:
                    continue
                words30 = frame[sf_id - 1]
                seen = self._subframes_seen.setdefault(prn, set())
                seen.add((ck[1], sf_id))
                if all((ck[1], s) in seen for s in (1, 2, 3)):
                    self._eph_received[prn] = eph
                if not want:
                    continue
                if self.model.subframe_msg == RXM_SFRB:
                    words24, _ = lnav.words24_from_words30(words30)
                    data = enc.rxm_sfrb(chn, prn, words24)
                else:
                    data = enc.rxm_sfrbx(chn, prn, lnav.sfrbx_from_transmitted(words30))
                if self._send(out, data):
                    self.stats.subframes_out += 1
            if want and self.model.subframe_msg == RXM_SFRBX:
                out += self._qzss_subframes(sf_id, frame_start, len(self._tracked) + len(self._tracked_glo))
            if len(self._frame_cache) > 256:
                self._frame_cache.clear()
        if want and self.model.subframe_msg == RXM_SFRBX and self._tracked_glo:
            out += self._glonass_strings(since, t)
        if want and self.model.subframe_msg == RXM_SFRBX and self._tracked_gal:
            out += self._galileo_pages(since, t)
        return out

    def _broadcast(self, gnss_id: int, t: GpsTime) -> dict[int, Any]:
        """The world's broadcast ephemeris of every satellite of `gnss_id` (empty for a GPS-only world)."""
        make = getattr(self.world, "broadcast_navigation", None)
        nav = make() if make is not None else None
        if nav is None:
            return {}
        return {sv: e for g, sv in nav.satellites() if g == gnss_id and (e := nav.select(g, sv, t)) is not None}

    def _galileo_pages(self, since: GpsTime, t: GpsTime) -> list[bytes]:
        """RXM-SFRBX E1-B page pairs of I/NAV word types 1–5 (hil_sim.galileo_pages) of every tracked Galileo
        satellite whose page ended in (since, t]; almanac and spare pages are not sent."""
        if self._gal_ephs is None:
            self._gal_ephs = self._broadcast(GNSS_GALILEO, t)
        out: list[bytes] = []
        two = galp.PAGE_S * NS_PER_S
        page_word = {k: w for w, k in galp.PAGE_OF_WORD.items()}
        chn0 = len(self._tracked) + len(self._tracked_glo) + len(self._tracked_qzss)
        for k in range(since.total_ns // two + 1, t.total_ns // two + 1):
            end = GpsTime.from_total_ns(k * two)
            page = (end.tow_ns // NS_PER_S) % galp.SUBFRAME_S // galp.PAGE_S - 1  # page ending at `end`
            word_type = page_word.get(page % (galp.SUBFRAME_S // galp.PAGE_S))
            if word_type is None:
                continue
            for chn, sv in enumerate(self._tracked_gal):
                eph = self._gal_ephs.get(sv)
                if not isinstance(eph, Ephemeris):
                    continue
                try:
                    word = galp.words(eph, end.tow_ns / NS_PER_S)[word_type]
                except ValueError as exc:
                    log.warning("Galileo E%02d: cannot encode I/NAV words (%s)", sv, exc)
                    continue
                if self._send(out, enc.rxm_sfrbx_galileo(chn0 + chn, sv, galp.sfrbx_words(word))):
                    self.stats.subframes_out += 1
        return out

    def _lnav_frame(self, key: tuple[int, int], eph: Ephemeris, frame_start: GpsTime, who: str
                    ) -> list[list[int]] | None:
        """Subframes 1–3 (as transmitted) of the LNAV frame starting at `frame_start`, encoded once per `key`
        (satellite, frame start s); None, with a warning naming `who`, when the ephemeris cannot be encoded."""
        if key not in self._frame_cache:
            try:
                self._frame_cache[key] = lnav.encode_subframes_transmitted(eph, frame_start.tow_ns / NS_PER_S)
            except lnav.LnavError as exc:
                log.warning("%s: cannot encode subframes (%s)", who, exc)
                return None
        return self._frame_cache[key]

    def _qzss_subframes(self, sf_id: int, frame_start: GpsTime, chn0: int) -> list[bytes]:
        """RXM-SFRBX subframe `sf_id` (1–3) of the frame starting at `frame_start` for every tracked QZSS
        satellite: the L1 C/A LNAV format of GPS (IS-QZSS-PNT), its broadcast ephemeris from the world."""
        out: list[bytes] = []
        if self._qzss_ephs is None:
            self._qzss_ephs = {sv: e for sv, e in self._broadcast(GNSS_QZSS, frame_start).items()
                               if isinstance(e, Ephemeris)}
        for chn, sv in enumerate(self._tracked_qzss):
            eph = self._qzss_ephs.get(sv)
            if eph is None:
                continue
            frame = self._lnav_frame((1000 + sv, frame_start.total_ns // NS_PER_S), eph, frame_start, f"QZSS {sv}")
            if frame is None:
                continue
            data = enc.rxm_sfrbx(chn0 + chn, sv, lnav.sfrbx_from_transmitted(frame[sf_id - 1]), gnss_id=GNSS_QZSS)
            if self._send(out, data):
                self.stats.subframes_out += 1
        return out

    def _glonass_strings(self, since: GpsTime, t: GpsTime) -> list[bytes]:
        """RXM-SFRBX GLONASS strings 1–5 (hil_sim.glonass_strings) of every tracked GLONASS satellite whose
        2-s string ended in (since, t]; strings 6–15 (almanac) are not sent."""
        if self._glo_ephs is None:
            self._glo_ephs = {sv: e for sv, e in self._broadcast(GNSS_GLONASS, t).items()
                              if isinstance(e, GlonassEphemeris)}
        out: list[bytes] = []
        leap_s = leap_seconds_at_utc(t.to_utc())
        two = gls.STRING_S * NS_PER_S
        shift = (GLONASST_MINUS_UTC_S - leap_s) * NS_PER_S  # GLONASS time − GPS time
        for k in range((since.total_ns + shift) // two + 1, (t.total_ns + shift) // two + 1):
            end_glo = k * two
            m = (end_glo // NS_PER_S) % gls.FRAME_S // gls.STRING_S  # string m ends 2m s into its frame
            if not 1 <= m <= 5:
                continue
            frame_start = GpsTime.from_total_ns(end_glo - m * two - shift)
            for chn, (slot, _k) in enumerate(self._tracked_glo):
                eph = self._glo_ephs.get(slot)
                if eph is None:
                    continue
                try:
                    words = gls.sfrbx_words(gls.strings(eph, frame_start, leap_s)[m], frame_start, leap_s)
                except ValueError as exc:
                    log.warning("GLONASS slot %d: cannot encode strings (%s)", slot, exc)
                    continue
                if self._send(out, enc.rxm_sfrbx_glonass(len(self._tracked) + chn, slot, eph.channel, words)):
                    self.stats.subframes_out += 1
        return out

    # ---- camera
    def _camera_pulse_enabled(self, t: GpsTime) -> bool:
        tp = self.config.tp5.get(self.options.camera_tp_idx)
        if tp is None or not tp["flags"] & TP5_ACTIVE:
            return False
        if self.time_valid(t) and tp["flags"] & TP5_LOCKED_OTHER_SET:
            return tp["pulseLenRatioLock"] > 0
        if not self.time_valid(t) and tp["flags"] & TP5_LOCKED_OTHER_SET:
            return tp["pulseLenRatio"] > 0
        return tp["pulseLenRatio"] > 0

    def _pulse_length_s(self, t: GpsTime) -> float:
        tp = self.config.tp5[self.options.camera_tp_idx]
        locked = self.time_valid(t) and tp["flags"] & TP5_LOCKED_OTHER_SET
        period, length = ((tp["freqPeriodLock"], tp["pulseLenRatioLock"]) if locked
                          else (tp["freqPeriod"], tp["pulseLenRatio"]))
        if tp["flags"] & TP5_IS_LENGTH:
            return length * 1e-6
        period_s = 1.0 / period if tp["flags"] & TP5_IS_FREQ and period else period * 1e-6
        return period_s * length / 2**32

    def _check_camera_period(self, t: GpsTime) -> None:
        """Warn once when the configured camera TIMEPULSE period differs from the world's camera plan (the
        world's pulse times are used either way: the emulator does not re-time the camera)."""
        plan_period_s = getattr(getattr(getattr(self.world, "scenario", None), "camera", None), "period_s", None)
        if self._period_warned or plan_period_s is None:
            return
        tp = self.config.tp5[self.options.camera_tp_idx]
        locked = self.time_valid(t) and tp["flags"] & TP5_LOCKED_OTHER_SET
        value = tp["freqPeriodLock"] if locked else tp["freqPeriod"]
        period_s = (1.0 / value if value else 0.0) if tp["flags"] & TP5_IS_FREQ else value * 1e-6
        if abs(period_s - float(plan_period_s)) > 1e-6:
            log.warning("camera TIMEPULSE%d period %.3f s differs from the world's camera period %.3f s",
                        self.options.camera_tp_idx + 1, period_s, plan_period_s)
            self._period_warned = True

    def _process_camera(self, t: GpsTime) -> None:
        events = self.world.camera_events(self._events_until, t) if t > self._events_until else []
        self._events_until = t
        for ev in events:
            pulse_t: GpsTime = ev.pulse_time
            if not self._camera_pulse_enabled(pulse_t):
                self.stats.pulses_suppressed += 1
                continue
            self._check_camera_period(pulse_t)
            if self.on_camera_pulse is not None:
                self.on_camera_pulse(ev)
            if self.options.trigger_extint:
                self._pending_edges.append((pulse_t, 1, True))
                self._pending_edges.append((pulse_t.add_s(self._pulse_length_s(pulse_t)), 1, False))
            flash_t: GpsTime | None = getattr(ev, "flash_time", None)
            if flash_t is not None:
                bounce_t = getattr(ev, "bounce_time", None)  # a bounce the world's camera simulated
                for te, rising in hot_shoe_edges(flash_t, self.options.contact_closed_s, self.faults,
                                                 extra_bounces=() if bounce_t is None else (bounce_t,)):
                    self._pending_edges.append((te, 0, rising))
        self._pending_edges.sort(key=lambda e: (e[0], e[1]))
        keep = []
        for te, ch, rising in self._pending_edges:
            if te <= t:
                noisy = te.add_ns(round(self._rng.normal(0.0, self.options.mark_noise_ns)))
                self.marks[ch].edge(noisy, rising)
            else:
                keep.append((te, ch, rising))
        self._pending_edges = keep


def antenna_state(truth: Mapping[str, Any], receiver: str) -> tuple[np.ndarray, np.ndarray]:
    """Antenna ECEF position (m) and velocity (m/s) of `receiver` from a World truth record."""
    for pos_key, vel_key in ((f"{receiver}_ecef_m", f"{receiver}_vel_ecef_m_s"),
                             ("antenna_ecef_m", "antenna_vel_ecef_m_s")):
        if pos_key in truth:
            vel = truth.get(vel_key)
            return (np.asarray(truth[pos_key], float),
                    np.asarray(vel, float) if vel is not None else np.zeros(3))
    raise KeyError(f"truth record has no position for {receiver!r}: keys {sorted(truth)}")


def _nmea(name: str, t: GpsTime, fix: tuple[np.ndarray, np.ndarray] | None, obs: ObsEpoch) -> bytes:
    """One NMEA 0183 sentence (GP talker, as the factory firmware) from the navigation fix."""
    utc = t.to_utc()
    hhmmss = utc.strftime("%H%M%S") + f".{utc.microsecond // 10000:02d}"
    ddmmyy = utc.strftime("%d%m%y")
    if fix is not None:
        lat, lon, h = ecef_to_llh(fix[0])
        lat_d, lon_d = math.degrees(float(lat)), math.degrees(float(lon))
        la = f"{int(abs(lat_d)):02d}{(abs(lat_d) % 1) * 60:08.5f},{'N' if lat_d >= 0 else 'S'}"
        lo = f"{int(abs(lon_d)):03d}{(abs(lon_d) % 1) * 60:08.5f},{'E' if lon_d >= 0 else 'W'}"
        speed_kn = float(np.linalg.norm(fix[1])) * 1.943844
        ok, q, alt = "A", 1, f"{float(h):.1f}"
    else:
        la, lo, speed_kn, ok, q, alt = ",", ",", 0.0, "V", 0, ""
    n = len(obs) if fix is not None else 0
    svs = [int(s) for s in obs.sv_id][:12] if fix is not None else []
    if name == "GGA":
        body = f"GPGGA,{hhmmss},{la},{lo},{q},{n:02d},1.0,{alt},M,0.0,M,,"
    elif name == "GLL":
        body = f"GPGLL,{la},{lo},{hhmmss},{ok},{'A' if fix is not None else 'N'}"
    elif name == "GSA":
        body = "GPGSA,A,{},{},1.6,1.0,1.3".format(3 if fix is not None else 1,
                                                   ",".join([f"{s:02d}" for s in svs] + [""] * (12 - len(svs))))
    elif name == "GSV":
        rows = [(int(s), round(float(c))) for s, c in zip(obs.sv_id, obs.cn0_dbhz, strict=True)][:4]
        sats = ",".join(f"{s:02d},,,{c:02d}" for s, c in rows)
        body = f"GPGSV,1,1,{len(obs):02d}" + ("," + sats if sats else "")
    elif name == "RMC":
        body = f"GPRMC,{hhmmss},{ok},{la},{lo},{speed_kn:.3f},,{ddmmyy},,,{'A' if fix is not None else 'N'}"
    else:
        body = f"GPVTG,,T,,M,{speed_kn:.3f},N,{speed_kn * 1.852:.3f},K,{'A' if fix is not None else 'N'}"
    return enc.nmea_sentence(body)
