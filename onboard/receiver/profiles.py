"""Receiver configuration profiles as data: ordered tables of CFG messages for the LEA-6T and the M8T.

A profile is built from one frozen :class:`ReceiverOptions` and holds, per message, its u-blox field values
(pyubx2 names), the key of the poll that reads it back, which fields the receiver is known to change on its
own (`alignToTow` for a period that does not divide one second) and the fallback group it belongs to (a NAK
of any member replaces the whole group by the profile's fallback messages: CFG-TP5 → legacy CFG-TP,
RXM-RAWX/SFRBX → RXM-RAW/SFRB, NAV-PVT → NAV-SOL on a u-blox 6).

Frames are serialised with pyubx2 `UBXMessage` (SET) where it can, with `ubx_tables` where it cannot
(legacy CFG-TP). `decode_cfg` turns a CFG frame (ours or a poll answer) back into the same field names.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from pyubx2 import GET, SET, UBXMessage, UBXReader
from pyubx2.exceptions import UBXMessageError, UBXParseError, UBXTypeError

from onboard.errors import ReceiverError
from onboard.receiver.framing import UBX_SYNC
from onboard.receiver.ubx_tables import (
    CFG_PAYLOAD_LENGTHS,
    LAYOUTS,
    UBX_IDS,
    UBX_NAMES,
    build_frame,
    poll_key,
    unpack_payload,
)
from onboard.timepulse.pulse import (
    TIMEPULSE,
    TIMEPULSE2,
    camera_pulse_spec,
    legacy_tp_fields,
    pps_pulse_spec,
    tp5_fields,
)

MODELS = ("lea6t", "m8t", "unknown")
TRIGGERS = ("extint1", "gpio", "none")
BAUD_RATES = (9600, 38400, 57600, 115200, 230400)
# CFG-PRT portID -> the CFG-MSG rate field of that port.
PORT_RATE_FIELD: Mapping[int, str] = MappingProxyType(
    {0: "rateDDC", 1: "rateUART1", 2: "rateUART2", 3: "rateUSB", 4: "rateSPI"}
)
UART_PORTS = (1, 2)
NMEA_DEFAULT_ON = ("NMEA-GGA", "NMEA-GLL", "NMEA-GSA", "NMEA-GSV", "NMEA-RMC", "NMEA-VTG")


@dataclass(frozen=True, slots=True)
class GnssChannels:
    """One CFG-GNSS block of the M8 channel budget: `gnss_id` (u-blox gnssId), `major` (GPS, GLONASS, Galileo,
    BeiDou: the M8 tracks at most three of them at once), `res_trk_ch`/`max_trk_ch` the reserved (minimum, when
    enabled) and maximum tracking channels, `sig_cfg_mask` the signal (0x01: the L1-band signal of the system)."""

    gnss_id: int
    major: bool
    res_trk_ch: int
    max_trk_ch: int
    sig_cfg_mask: int = 0x01


# u-blox M8 receiver description UBX-13003221, CFG-GNSS and "GNSS configuration": 32 hardware channels; each
# enabled major GNSS needs maxTrkCh ≥ 4; the reserved channels of the enabled systems must fit numTrkChUse;
# at most 3 major GNSS concurrently; GPS and QZSS enabled together (cross-correlation). The allocations are the
# M8 defaults as the real NEO-M8T dump (rtkbase_U-Blox_NEO-M8T_rtkbase.txt) reports them, Galileo at the M8
# default 4/8. Names are the keys of the profile's CFG-GNSS fields ("enable_GLONASS").
M8_GNSS_CHANNELS: Mapping[str, GnssChannels] = MappingProxyType({
    "GPS": GnssChannels(0, True, 8, 16),
    "SBAS": GnssChannels(1, False, 1, 3),
    "Galileo": GnssChannels(2, True, 4, 8),
    "BeiDou": GnssChannels(3, True, 8, 16),
    "IMES": GnssChannels(4, False, 0, 8),
    "QZSS": GnssChannels(5, False, 0, 3),
    "GLONASS": GnssChannels(6, True, 8, 14),
})
M8_TRACKING_CHANNELS = 32
M8_MAX_MAJOR_GNSS = 3
GNSS_BLOCK_FIELDS = ("enable", "resTrkCh", "maxTrkCh", "sigCfMask")
"""The CFG-GNSS block fields we set and compare (pyubx2 names); the flags' reserved high byte is the
receiver's own (the real M8T dump reads back 0x01/0x03/0x05 there) and is not compared."""
# CFG-CFG save mask: ioPort, msgConf, infMsg, navConf, rxmConf (bits 0–4, the same on u-blox 6 and M8).
CFG_SAVE_MASK = 0x0000001F


@dataclass(frozen=True, slots=True)
class ReceiverOptions:
    """Everything the receiver configuration depends on (units in names).

    `port_id` CFG-PRT port the Pi is wired to (1 UART1, 2 UART2, 3 USB); `baud` its rate (UART only);
    `meas_rate_ms` measurement period; `camera_period_s` 2–3 s; `pulse_len_ms` trigger pulse length;
    `pulse_rising` True when the pulse is high-active (CFG-TP5 polarity 1); `use_timepulse2` drive the camera
    from TIMEPULSE2 and keep TIMEPULSE at 1 PPS; `trigger` where the trigger pulse is measured ("extint1":
    TIM-TM2 channel 1, "gpio": a Pi input, "none": not measured); `*_every_n` message rates in measurement
    epochs (0 off); `ant_cable_delay_ns` CFG-TP5 antenna cable delay; `save_to_bbr` end with CFG-CFG save;
    `ack_timeout_s` ACK/NAK and poll-answer wait; `retries` extra attempts after silence; `baud_settle_s` wait
    between sending a baud-changing CFG-PRT and reopening at the new rate (the frame must have left and been
    read at the old rate; the ACK may then be missed, the poll-back confirms). `aid_eph_poll_s` the recorder's
    backup ephemeris path: poll AID-EPH (all SVs) after the first fix and then this often (0 = never).
    """

    port_id: int = 1
    baud: int = 115200
    meas_rate_ms: int = 200
    camera_period_s: float = 3.0
    pulse_len_ms: float = 100.0
    pulse_rising: bool = True
    use_timepulse2: bool = True
    trigger: str = "extint1"
    raw_every_n: int = 1
    subframes_every_n: int = 1
    time_mark_every_n: int = 1
    nav_every_n: int = 1
    ant_cable_delay_ns: int = 50
    save_to_bbr: bool = False
    ack_timeout_s: float = 1.0
    retries: int = 2
    baud_settle_s: float = 0.1
    aid_eph_poll_s: float = 1800.0
    gnss: str = "GPS,GLONASS,Galileo,QZSS"

    def __post_init__(self) -> None:
        if self.port_id not in PORT_RATE_FIELD:
            raise ValueError(f"port_id must be one of {sorted(PORT_RATE_FIELD)}, got {self.port_id}")
        if self.port_id in UART_PORTS and self.baud not in BAUD_RATES:
            raise ValueError(f"baud must be one of {BAUD_RATES}, got {self.baud}")
        if not 25 <= self.meas_rate_ms <= 65535:
            raise ValueError(f"meas_rate_ms must be within 25–65535 ms, got {self.meas_rate_ms}")
        if self.trigger not in TRIGGERS:
            raise ValueError(f"trigger must be one of {TRIGGERS}, got {self.trigger!r}")
        for name in ("raw_every_n", "subframes_every_n", "time_mark_every_n", "nav_every_n"):
            if not 0 <= getattr(self, name) <= 255:
                raise ValueError(f"{name} must be within 0–255, got {getattr(self, name)}")
        if self.ack_timeout_s <= 0 or self.retries < 0 or not 0 <= self.baud_settle_s <= 2:
            raise ValueError("ack_timeout_s must be > 0, retries ≥ 0 and baud_settle_s within 0–2 s")
        if self.aid_eph_poll_s < 0:
            raise ValueError(f"aid_eph_poll_s must be ≥ 0 (0 = never), got {self.aid_eph_poll_s}")
        camera_pulse_spec(self.camera_period_s, self.pulse_len_ms, self.pulse_rising)  # validates both
        if not isinstance(self.gnss, str):
            raise TypeError(f"gnss must be text such as 'GPS,GLONASS,Galileo,QZSS', got {self.gnss!r}")
        unknown = [g for g in self.gnss_systems if g not in M8_GNSS_CHANNELS]
        if unknown:
            raise ValueError(f"gnss: unknown system(s) {unknown}; known: {', '.join(M8_GNSS_CHANNELS)}")
        if len(set(self.gnss_systems)) != len(self.gnss_systems):
            raise ValueError(f"gnss: a system named twice in {self.gnss!r}")
        majors = [g for g in self.gnss_systems if M8_GNSS_CHANNELS[g].major]
        if not 1 <= len(majors) <= M8_MAX_MAJOR_GNSS:
            raise ValueError(f"gnss: the M8 tracks 1 to {M8_MAX_MAJOR_GNSS} major systems (GPS, GLONASS, "
                             f"Galileo, BeiDou) at once, got {majors}")
        if ("GPS" in self.gnss_systems) != ("QZSS" in self.gnss_systems):
            raise ValueError("gnss: enable GPS and QZSS together (u-blox: cross-correlation otherwise)")

    @property
    def gnss_systems(self) -> tuple[str, ...]:
        """`gnss` as a tuple of system names."""
        return tuple(g.strip() for g in self.gnss.split(",") if g.strip())


RTK_LETTERS: Mapping[str, str] = MappingProxyType({"GPS": "G", "GLONASS": "R", "Galileo": "E", "BeiDou": "C",
                                                   "QZSS": "J"})
"""`ReceiverOptions.gnss` names → RINEX letters of the constellations the RTK engine uses (SBAS, IMES: none)."""
RAW_MESSAGES = ("RXM-RAW", "RXM-RAWX")


def rtk_systems(raw_message: str, gnss: str) -> str:
    """The constellations (RINEX letters in "GRECJ" order, `RtkOptions.systems`) a rover's RTK can use, by the raw
    observation message its receiver sends: "RXM-RAW" (u-blox 6 LEA-6T, or an M8 fallen back to it) GPS only,
    "G", whatever `gnss` says; "RXM-RAWX" (u-blox 8, the M8T) the systems of its `gnss` setting
    (`ReceiverOptions.gnss`, e.g. "GPS,GLONASS,Galileo,QZSS" → "GREJ"). ValueError for another message or an
    RXM-RAWX setting without any of them."""
    if raw_message == "RXM-RAW":
        return "G"
    if raw_message != "RXM-RAWX":
        raise ValueError(f"raw_message must be one of {RAW_MESSAGES}, got {raw_message!r}")
    named = {RTK_LETTERS[g] for g in (n.strip() for n in gnss.split(",")) if g in RTK_LETTERS}
    letters = "".join(c for c in "GRECJ" if c in named)
    if not letters:
        raise ValueError(f"gnss {gnss!r} names none of {', '.join(RTK_LETTERS)}: nothing for RTK")
    return letters


@dataclass(frozen=True, slots=True)
class ProfileEntry:
    """One CFG message of a profile.

    `label` unique human name ("CFG-TP5 TIMEPULSE2 camera"); `name` the UBX message; `fields` its SET values;
    `poll` the poll key payload (None: cannot be read back, e.g. CFG-CFG); `compare` the fields checked on
    poll-back; `may_alter` fields the receiver is known to change (recorded, not an error); `group` fallback
    group; `baud_change` the CFG-PRT that moves the link to a new baud rate; `raw` the serialised frame;
    `expect_ack` False for a message the receiver never acknowledges (CFG-RST).
    """

    label: str
    name: str
    fields: Mapping[str, int]
    poll: bytes | None
    compare: tuple[str, ...]
    raw: bytes
    may_alter: frozenset[str] = frozenset()
    group: str | None = None
    baud_change: int | None = None
    expect_ack: bool = True


@dataclass(frozen=True, slots=True)
class Profile:
    """An ordered configuration for one receiver model, plus the fallbacks by group and what it sets up.

    `camera_timepulse` "TIMEPULSE2" or "TIMEPULSE" (the pin the camera must be wired to);
    `trigger` where trigger pulses are measured (ReceiverOptions.trigger).
    """

    model: str
    entries: tuple[ProfileEntry, ...]
    fallbacks: Mapping[str, tuple[ProfileEntry, ...]] = field(default_factory=dict)
    camera_timepulse: str = "TIMEPULSE2"
    trigger: str = "extint1"

    def frames(self) -> list[bytes]:
        """The serialised frames in sending order (fallbacks not included)."""
        return [e.raw for e in self.entries]


# --- codec ------------------------------------------------------------------------------------------------

_MASK_FIELDS = ("clearMask", "saveMask", "loadMask")


def _gnss_to_pyubx2(fields: Mapping[str, int]) -> dict[str, Any]:
    """Our CFG-GNSS fields (per system: "enable_GPS", …) → pyubx2's numbered repeating group, gnssId order."""
    systems = sorted((g for g in M8_GNSS_CHANNELS if f"enable_{g}" in fields),
                     key=lambda g: M8_GNSS_CHANNELS[g].gnss_id)
    out: dict[str, Any] = {"msgVer": fields["msgVer"], "numTrkChHw": 0, "numTrkChUse": fields["numTrkChUse"],
                           "numConfigBlocks": len(systems)}
    for n, g in enumerate(systems, start=1):
        out[f"gnssId_{n:02d}"] = M8_GNSS_CHANNELS[g].gnss_id
        out |= {f"{f}_{n:02d}": fields[f"{f}_{g}"] for f in GNSS_BLOCK_FIELDS}
    return out


def _gnss_from_pyubx2(parsed: Mapping[str, int]) -> dict[str, int]:
    """pyubx2's parsed CFG-GNSS (numbered blocks in the receiver's order) → our per-system field names."""
    names = {c.gnss_id: g for g, c in M8_GNSS_CHANNELS.items()}
    out = {k: parsed[k] for k in ("msgVer", "numTrkChHw", "numTrkChUse", "numConfigBlocks") if k in parsed}
    for n in range(1, parsed.get("numConfigBlocks", 0) + 1):
        gnss_id = parsed.get(f"gnssId_{n:02d}")
        name = names.get(gnss_id, f"gnssId{gnss_id}") if gnss_id is not None else None
        if name is None or f"enable_{name}" in out:
            raise ReceiverError(f"CFG-GNSS: block {n} has no or a repeated gnssId ({gnss_id})")
        out |= {f"{f}_{name}": parsed[f"{f}_{n:02d}"] for f in GNSS_BLOCK_FIELDS}
    return out


def encode_cfg(name: str, fields: Mapping[str, int]) -> bytes:
    """A CFG SET frame for `name` with `fields` (pyubx2 names; CFG-GNSS blocks named per system, "enable_GPS"):
    pyubx2 builds it unless we own the layout."""
    if name in LAYOUTS:
        return build_frame(LAYOUTS[name], fields)
    kwargs: dict[str, Any] = _gnss_to_pyubx2(fields) if name == "CFG-GNSS" else dict(fields)
    for mask in _MASK_FIELDS:  # pyubx2 wants X4 masks as bytes
        if mask in kwargs:
            kwargs[mask] = int(kwargs[mask]).to_bytes(4, "little")
    return bytes(UBXMessage("CFG", name, SET, **kwargs).serialize())


def decode_cfg(raw: bytes, *, mode: int = GET) -> dict[str, int]:
    """Field dict of a CFG frame (our SET frame with mode=SET, a poll answer with GET).

    Raises ReceiverError with the message name when the frame cannot be parsed.
    """
    if len(raw) < 8 or raw[:2] != UBX_SYNC:
        raise ReceiverError(f"not a UBX frame: {raw[:8].hex(' ')}")
    name = UBX_NAMES.get((raw[2], raw[3]), f"0x{raw[2]:02X} 0x{raw[3]:02X}")
    if name in LAYOUTS:
        return unpack_payload(LAYOUTS[name], raw[6:-2])
    lengths = CFG_PAYLOAD_LENGTHS.get(name)
    if lengths is not None and len(raw) - 8 not in lengths:
        raise ReceiverError(f"{name}: payload is {len(raw) - 8} bytes, expected {' or '.join(map(str, lengths))}")
    if name == "CFG-GNSS" and (len(raw) - 8 < 4 or (len(raw) - 12) % 8 or (len(raw) - 12) // 8 != raw[9]):
        raise ReceiverError(f"CFG-GNSS: payload of {len(raw) - 8} bytes is not 4 + 8 × numConfigBlocks")
    try:
        msg = UBXReader.parse(raw, msgmode=mode)
    except (UBXParseError, UBXMessageError, UBXTypeError, ValueError, KeyError, IndexError, struct.error) as exc:
        raise ReceiverError(f"{name}: cannot parse ({exc})") from exc
    out: dict[str, int] = {}
    for key, value in vars(msg).items():
        if key.startswith("_"):
            continue
        if isinstance(value, bytes | bytearray):
            value = int.from_bytes(value, "little")
        if isinstance(value, int):
            out[key] = value
    return _gnss_from_pyubx2(out) if name == "CFG-GNSS" else out


def _entry(
    label: str,
    name: str,
    fields: Mapping[str, int],
    poll: bytes | None,
    *,
    compare_skip: tuple[str, ...] = (),
    may_alter: frozenset[str] = frozenset(),
    group: str | None = None,
    baud_change: int | None = None,
    expect_ack: bool = True,
) -> ProfileEntry:
    fields = MappingProxyType(dict(fields))
    compare = tuple(k for k in fields if k not in compare_skip)
    return ProfileEntry(
        label, name, fields, poll, compare, encode_cfg(name, fields), may_alter, group, baud_change, expect_ack
    )


# --- builders ---------------------------------------------------------------------------------------------


def prt_entry(options: ReceiverOptions) -> ProfileEntry:
    """A complete CFG-PRT: 8N1, UBX in and out only (NMEA off at the port), the chosen baud."""
    uart = options.port_id in UART_PORTS
    fields = {
        "portID": options.port_id,
        "enable": 0,
        "pol": 0,
        "pin": 0,
        "thres": 0,
        "charLen": 3 if uart else 0,  # 8 bits
        "parity": 4 if uart else 0,  # none
        "nStopBits": 0,  # 1 stop bit
        "baudRate": options.baud if uart else 0,
        "inUBX": 1,
        "inNMEA": 0,
        "inRTCM": 0,
        "inRTCM3": 0,
        "outUBX": 1,
        "outNMEA": 0,
        "outRTCM3": 0,
        "extendedTxTimeout": 0,
    }
    return _entry(
        f"CFG-PRT port {options.port_id}",
        "CFG-PRT",
        fields,
        poll_key("CFG-PRT", options.port_id),
        baud_change=options.baud if uart else None,
    )


def msg_entry(options: ReceiverOptions, message: str, every_n: int, group: str | None = None) -> ProfileEntry:
    """CFG-MSG (8-byte form): `message` every `every_n` epochs on the port in use, off on every other port."""
    cls, mid = UBX_IDS[message]
    fields = {"msgClass": cls, "msgID": mid} | {f: 0 for f in PORT_RATE_FIELD.values()}
    fields[PORT_RATE_FIELD[options.port_id]] = every_n
    state = "off" if every_n == 0 else f"every {every_n}"
    return _entry(f"CFG-MSG {message} {state}", "CFG-MSG", fields, poll_key("CFG-MSG", cls, mid), group=group)


def rate_entry(options: ReceiverOptions) -> ProfileEntry:
    """CFG-RATE: measurement period, one navigation solution per measurement, GPS time reference."""
    fields = {"measRate": options.meas_rate_ms, "navRate": 1, "timeRef": 1}
    return _entry(f"CFG-RATE {options.meas_rate_ms} ms", "CFG-RATE", fields, poll_key("CFG-RATE"))


def tp5_entry(tp_idx: int, fields: Mapping[str, int], purpose: str) -> ProfileEntry:
    """CFG-TP5 for one pulse; `alignToTow` may be cleared by the receiver when the period is not ≤ 1 s."""
    pin = "TIMEPULSE" if tp_idx == TIMEPULSE else "TIMEPULSE2"
    may_alter = frozenset({"alignToTow"}) if fields["freqPeriod"] > 1_000_000 else frozenset()
    return _entry(
        f"CFG-TP5 {pin} {purpose}",
        "CFG-TP5",
        fields,
        poll_key("CFG-TP5", tp_idx),
        compare_skip=("version",),
        may_alter=may_alter,
        group="tp5",
    )


def legacy_tp_entry(options: ReceiverOptions) -> ProfileEntry:
    """Legacy u-blox 6 CFG-TP carrying the camera pulse on TIMEPULSE (CFG-TP5 NAKed)."""
    spec = camera_pulse_spec(options.camera_period_s, options.pulse_len_ms, options.pulse_rising,
                             options.ant_cable_delay_ns)
    return _entry("CFG-TP TIMEPULSE camera", "CFG-TP", legacy_tp_fields(spec), poll_key("CFG-TP"))


def gnss_entry(options: ReceiverOptions) -> ProfileEntry:
    """CFG-GNSS (M8): `options.gnss` enabled with their channel budget, every other system off (reserving none).

    All seven blocks are sent, so the result does not depend on what the receiver had enabled before; the poll
    answer (every supported system, in the receiver's order) is compared per system.
    """
    fields: dict[str, int] = {"msgVer": 0, "numTrkChUse": M8_TRACKING_CHANNELS}
    for name, ch in M8_GNSS_CHANNELS.items():
        on = name in options.gnss_systems
        fields |= {f"enable_{name}": int(on), f"resTrkCh_{name}": ch.res_trk_ch if on else 0,
                   f"maxTrkCh_{name}": ch.max_trk_ch, f"sigCfMask_{name}": ch.sig_cfg_mask}
    reserved = sum(fields[f"resTrkCh_{g}"] for g in M8_GNSS_CHANNELS)
    assert reserved <= M8_TRACKING_CHANNELS, "M8_GNSS_CHANNELS reserves more channels than the M8 has"
    label = "CFG-GNSS " + "+".join(options.gnss_systems)
    return _entry(label, "CFG-GNSS", fields, poll_key("CFG-GNSS"))


def gnss_restart_entry() -> ProfileEntry:
    """CFG-RST hot start, controlled software reset of the GNSS part only (resetMode 0x02: ports, configuration
    and stored orbits kept): the M8 applies a new CFG-GNSS channel allocation at the next GNSS start. CFG-RST is
    never acknowledged; not polled (*check on hardware*: whether an unchanged CFG-GNSS needs it)."""
    fields = {"navBbrMask": 0x0000, "resetMode": 0x02, "reserved1": 0}
    return _entry("CFG-RST GNSS restart (hot)", "CFG-RST", fields, None, expect_ack=False)


def cfg_save_entry() -> ProfileEntry:
    """CFG-CFG: save the current configuration to battery-backed RAM (not polled back)."""
    fields = {"clearMask": 0, "saveMask": CFG_SAVE_MASK, "loadMask": 0, "devBBR": 1}
    return _entry("CFG-CFG save to BBR", "CFG-CFG", fields, None)


def build_profile(model: str, options: ReceiverOptions) -> Profile:
    """The profile for `model` ("lea6t", "m8t"; "unknown" gets the M8T table with u-blox 6 fallbacks)."""
    if model not in MODELS:
        raise ValueError(f"model must be one of {MODELS}, got {model!r}")
    u6 = model == "lea6t"
    tp_version = 0 if u6 else 1
    camera = camera_pulse_spec(options.camera_period_s, options.pulse_len_ms, options.pulse_rising,
                               options.ant_cable_delay_ns)
    entries: list[ProfileEntry] = [prt_entry(options)]
    if model == "m8t":  # an "unknown" receiver may be a u-blox 6 (no CFG-GNSS): it keeps its own systems
        entries += [gnss_entry(options), gnss_restart_entry()]
    entries += [msg_entry(options, nmea, 0) for nmea in NMEA_DEFAULT_ON]
    entries.append(rate_entry(options))
    fallbacks: dict[str, tuple[ProfileEntry, ...]] = {"tp5": (legacy_tp_entry(options),)}
    if u6:
        entries.append(msg_entry(options, "RXM-RAW", options.raw_every_n))
        entries.append(msg_entry(options, "RXM-SFRB", options.subframes_every_n))
    else:
        entries.append(msg_entry(options, "RXM-RAWX", options.raw_every_n, group="raw"))
        entries.append(msg_entry(options, "RXM-SFRBX", options.subframes_every_n, group="raw"))
        fallbacks["raw"] = (
            msg_entry(options, "RXM-RAW", options.raw_every_n),
            msg_entry(options, "RXM-SFRB", options.subframes_every_n),
        )
    entries.append(msg_entry(options, "TIM-TM2", options.time_mark_every_n))
    if u6:
        entries.append(msg_entry(options, "NAV-SOL", options.nav_every_n))
    else:
        entries.append(msg_entry(options, "NAV-PVT", options.nav_every_n, group="nav"))
        fallbacks["nav"] = (msg_entry(options, "NAV-SOL", options.nav_every_n),)
    if options.use_timepulse2:
        pps = pps_pulse_spec(options.ant_cable_delay_ns)
        entries.append(tp5_entry(TIMEPULSE, tp5_fields(TIMEPULSE, pps, tp_version), "1 PPS"))
        entries.append(tp5_entry(TIMEPULSE2, tp5_fields(TIMEPULSE2, camera, tp_version), "camera"))
    else:
        entries.append(tp5_entry(TIMEPULSE, tp5_fields(TIMEPULSE, camera, tp_version), "camera"))
    if options.save_to_bbr:
        entries.append(cfg_save_entry())
    return Profile(
        model=model,
        entries=tuple(entries),
        fallbacks=MappingProxyType(fallbacks),
        camera_timepulse="TIMEPULSE2" if options.use_timepulse2 else "TIMEPULSE",
        trigger=options.trigger,
    )
