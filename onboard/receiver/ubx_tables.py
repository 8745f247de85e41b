"""Declarative UBX layouts we pack and parse ourselves, and the message-id table configuration uses.

pyubx2 1.4.0 cannot build or parse the u-blox 6 legacy CFG-TP (0x06 0x07: a field named `length` collides
with a property), and it prints a stray debug line when it builds a CFG-TP5 poll with `tpIdx`. Those frames are
described here as tables of (field, struct code) and packed with `struct` (little-endian, as every UBX payload).
Pure: no I/O, no pyubx2.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass

from onboard.errors import ReceiverError
from onboard.receiver.framing import ubx_frame

# (class, id) of every UBX message the configuration code names. Names as in the u-blox interface descriptions.
UBX_IDS: Mapping[str, tuple[int, int]] = {
    "ACK-NAK": (0x05, 0x00),
    "ACK-ACK": (0x05, 0x01),
    "CFG-PRT": (0x06, 0x00),
    "CFG-MSG": (0x06, 0x01),
    "CFG-RST": (0x06, 0x04),
    "CFG-TP": (0x06, 0x07),
    "CFG-RATE": (0x06, 0x08),
    "CFG-CFG": (0x06, 0x09),
    "CFG-TP5": (0x06, 0x31),
    "CFG-GNSS": (0x06, 0x3E),
    "MON-VER": (0x0A, 0x04),
    "NAV-SOL": (0x01, 0x06),
    "NAV-PVT": (0x01, 0x07),
    "RXM-RAW": (0x02, 0x10),
    "RXM-SFRB": (0x02, 0x11),
    "RXM-SFRBX": (0x02, 0x13),
    "RXM-RAWX": (0x02, 0x15),
    "AID-EPH": (0x0B, 0x31),
    "TIM-TM2": (0x0D, 0x03),
    "TIM-TP": (0x0D, 0x01),
    "NMEA-GGA": (0xF0, 0x00),
    "NMEA-GLL": (0xF0, 0x01),
    "NMEA-GSA": (0xF0, 0x02),
    "NMEA-GSV": (0xF0, 0x03),
    "NMEA-RMC": (0xF0, 0x04),
    "NMEA-VTG": (0xF0, 0x05),
}
UBX_NAMES: Mapping[tuple[int, int], str] = {v: k for k, v in UBX_IDS.items()}


def message_name(msg_class: int, msg_id: int) -> str:
    """The table name of a (class, id) pair, or e.g. "UBX-0x06-0x99" when unknown."""
    return UBX_NAMES.get((msg_class, msg_id), f"UBX-0x{msg_class:02X}-0x{msg_id:02X}")


@dataclass(frozen=True, slots=True)
class Layout:
    """A fixed-length UBX payload as an ordered table of (field name, struct code)."""

    name: str
    fields: tuple[tuple[str, str], ...]

    @property
    def struct_format(self) -> str:
        """The little-endian struct format of the whole payload."""
        return "<" + "".join(code for _, code in self.fields)

    @property
    def size(self) -> int:
        """Payload length in bytes."""
        return struct.calcsize(self.struct_format)

    @property
    def ids(self) -> tuple[int, int]:
        """(class, id) of the message."""
        return UBX_IDS[self.name]


# u-blox 6 Receiver Description GPS.G6-SW-10018, CFG-TP (20 bytes). `status`: >0 positive, 0 off, <0 negative
# polarity; `timeRef`: 0 UTC, 1 GPS, 2 local; `flags` bit0 syncMode (1: pulses only while synchronised to GPS).
CFG_TP = Layout(
    "CFG-TP",
    (
        ("interval", "I"),  # µs
        ("length", "I"),  # µs
        ("status", "b"),
        ("timeRef", "B"),
        ("flags", "B"),
        ("reserved1", "B"),
        ("antennaCableDelay", "h"),  # ns
        ("rfGroupDelay", "h"),  # ns
        ("userDelay", "i"),  # ns
    ),
)

# u-blox M8 receiver description, CFG-RST (4 bytes; never acknowledged). navBbrMask: the battery-backed data to
# clear (0x0000 hot start, 0xFFFF cold start; pyubx2 only takes it bit by bit); resetMode 0x02: controlled
# software reset of the GNSS part only (ports and configuration kept).
CFG_RST = Layout("CFG-RST", (("navBbrMask", "H"), ("resetMode", "B"), ("reserved1", "B")))

LAYOUTS: Mapping[str, Layout] = {CFG_TP.name: CFG_TP, CFG_RST.name: CFG_RST}


def pack_payload(layout: Layout, values: Mapping[str, int]) -> bytes:
    """Pack `values` (every field of `layout`, reserved ones default to 0) into a payload.

    Raises ValueError naming the field when a value is missing, unknown or out of range.
    """
    unknown = set(values) - {name for name, _ in layout.fields}
    if unknown:
        raise ValueError(f"{layout.name}: unknown field(s) {sorted(unknown)}")
    out = bytearray()
    for name, code in layout.fields:
        if name not in values and not name.startswith("reserved"):
            raise ValueError(f"{layout.name}.{name}: missing value")
        try:
            out += struct.pack("<" + code, int(values.get(name, 0)))
        except struct.error as exc:
            raise ValueError(f"{layout.name}.{name}: {values.get(name)!r} does not fit {code!r}") from exc
    return bytes(out)


def unpack_payload(layout: Layout, payload: bytes) -> dict[str, int]:
    """Parse a payload of `layout` into a field dict; raises ReceiverError on a wrong length."""
    if len(payload) != layout.size:
        raise ReceiverError(f"{layout.name}: payload is {len(payload)} bytes, expected {layout.size}")
    return dict(zip((name for name, _ in layout.fields), struct.unpack(layout.struct_format, payload), strict=True))


def build_frame(layout: Layout, values: Mapping[str, int]) -> bytes:
    """A complete UBX frame of `layout` with `values`."""
    cls, mid = layout.ids
    return ubx_frame(cls, mid, pack_payload(layout, values))


# Payload lengths of the CFG messages we send and read back. pyubx2 1.4.0 parses a short or long payload
# without complaint (missing fields read as 0), so a truncated poll answer must be caught here.
CFG_PAYLOAD_LENGTHS: Mapping[str, tuple[int, ...]] = {
    "CFG-PRT": (20,),
    "CFG-MSG": (8,),
    "CFG-RATE": (6,),
    "CFG-TP5": (32,),
    "CFG-TP": (20,),
    "CFG-CFG": (12, 13),
    "CFG-RST": (4,),
}

# Polls: message name -> struct code of its key payload (empty for a poll without payload). The poll answer
# starts with the same key bytes, which is how we recognise it (e.g. CFG-TP5 for tpIdx 1 starts with 0x01).
POLL_KEYS: Mapping[str, str] = {
    "CFG-PRT": "B",  # portID
    "CFG-MSG": "BB",  # msgClass, msgID
    "CFG-RATE": "",
    "CFG-TP": "",
    "CFG-TP5": "B",  # tpIdx: built by hand, pyubx2 prints a debug line for it
    "CFG-GNSS": "",  # the answer holds a block for every GNSS the receiver supports, enabled or not
    "MON-VER": "",
    "AID-EPH": "",  # empty: all 32 GPS SVs (a one-byte svid polls one; pyubx2's keyword forms poll all)
}


def poll_key(name: str, *key: int) -> bytes:
    """The key payload of a poll for `name` (e.g. poll_key("CFG-TP5", 1) == b"\\x01")."""
    if name not in POLL_KEYS:
        raise ValueError(f"no poll layout for {name}")
    code = POLL_KEYS[name]
    if len(key) != len(code):
        raise ValueError(f"{name} poll takes {len(code)} key value(s), got {len(key)}")
    return struct.pack("<" + code, *key) if code else b""


def poll_frame(name: str, *key: int) -> bytes:
    """A complete poll request frame (e.g. poll_frame("MON-VER"), poll_frame("CFG-TP5", 1))."""
    cls, mid = UBX_IDS[name]
    return ubx_frame(cls, mid, poll_key(name, *key))
