"""A scripted u-blox configuration responder and a ConfigLink over it (no real time: silence returns at once).

Byte-level on purpose: it stores the payloads it is sent and answers polls with them, so what the tests check
is what went over the wire, not our own encoder's view of it.
"""

from __future__ import annotations

from collections.abc import Callable

from onboard.receiver.framing import Frame, iter_frames, ubx_frame

KEY_LEN = {(0x06, 0x00): 1, (0x06, 0x01): 2, (0x06, 0x31): 1}  # CFG-PRT portID, CFG-MSG class/id, CFG-TP5 tpIdx


def mon_ver_payload(sw: str, hw: str, *ext: str) -> bytes:
    """MON-VER payload: swVersion C30, hwVersion C10, extensions C30 each."""
    return sw.encode().ljust(30, b"\0") + hw.encode().ljust(10, b"\0") + b"".join(e.encode().ljust(30, b"\0") for e in ext)


M8T_MON_VER = mon_ver_payload("EXT CORE 3.01 (111141)", "00080000", "ROM BASE 2.01 (75331)", "FWVER=TIM 1.10",
                              "PROTVER=22.00", "MOD=NEO-M8T-0")
LEA6T_MON_VER = mon_ver_payload("7.03 (45970)", "00040007")


class FakeUblox:
    """Answers CFG SETs with ACK/NAK, polls with the stored payload, MON-VER polls with `mon_ver`.

    Knobs: `baud` current rate; `nak(cls, id, payload)` which SETs (and polls) to NAK; `silent` answer nothing;
    `drop_first` ignore the first N frames; `ack_after_baud_change` send the CFG-PRT ACK at the new rate;
    `clear_align_over_1s` clear CFG-TP5 alignToTow when the period exceeds 1 s (as the M8T may);
    `tamper[(cls, id)]` rewrites a stored payload before it is polled back; `answer_polls` False = ignore polls.
    """

    def __init__(self, mon_ver: bytes = M8T_MON_VER, baud: int = 115200) -> None:
        self.mon_ver = mon_ver
        self.baud = baud
        self.nak: Callable[[int, int, bytes], bool] = lambda _c, _i, _p: False
        self.silent = False
        self.drop_first = 0
        self.ack_after_baud_change = True
        self.clear_align_over_1s = True
        self.tamper: dict[tuple[int, int], Callable[[bytes], bytes]] = {}
        self.answer_polls = True
        # Factory UART1 setting: 8N1 at `baud`, in UBX+NMEA+RTCM, out UBX+NMEA.
        self.stored: dict[tuple[int, int, bytes], bytes] = {
            (0x06, 0x00, b"\x01"): bytes((1, 0, 0, 0)) + (0x8C0).to_bytes(4, "little") + baud.to_bytes(4, "little")
            + bytes((7, 0, 3, 0, 0, 0, 0, 0))
        }
        self.received: list[Frame] = []

    def handle(self, raw: bytes) -> list[tuple[int, bytes]]:
        """Bytes in at the current rate → list of (baud at which it is sent, frame) out."""
        out: list[tuple[int, bytes]] = []
        for frame in iter_frames(raw):
            self.received.append(frame)
            if self.drop_first > 0:
                self.drop_first -= 1
                continue
            if self.silent:
                continue
            out += self._answer(frame.msg_class, frame.msg_id, frame.payload)
        return out

    def _answer(self, cls: int, mid: int, payload: bytes) -> list[tuple[int, bytes]]:
        if (cls, mid) == (0x0A, 0x04):
            return [(self.baud, ubx_frame(0x0A, 0x04, self.mon_ver))] if not payload else []
        if cls != 0x06:
            return []
        key = payload[: KEY_LEN.get((cls, mid), 0)]
        if len(payload) == len(key):  # a poll
            if self.nak(cls, mid, payload) or not self.answer_polls:
                return [(self.baud, ubx_frame(0x05, 0x00, bytes((cls, mid))))] if self.answer_polls else []
            stored = self.stored.get((cls, mid, key))
            if stored is None:
                return [(self.baud, ubx_frame(0x05, 0x00, bytes((cls, mid))))]
            tamper = self.tamper.get((cls, mid))
            return [(self.baud, ubx_frame(cls, mid, tamper(stored) if tamper else stored))]
        if self.nak(cls, mid, payload):
            return [(self.baud, ubx_frame(0x05, 0x00, bytes((cls, mid))))]
        if (cls, mid) == (0x06, 0x31) and self.clear_align_over_1s:
            period_us = int.from_bytes(payload[12:16], "little")
            if period_us > 1_000_000:
                payload = payload[:28] + bytes((payload[28] & ~0x20,)) + payload[29:]
        if (cls, mid) != (0x06, 0x09):
            self.stored[(cls, mid, key)] = payload
        ack = ubx_frame(0x05, 0x01, bytes((cls, mid)))
        if (cls, mid) == (0x06, 0x00) and payload[0] in (1, 2):
            self.baud = int.from_bytes(payload[8:12], "little")
            return [(self.baud, ack)] if self.ack_after_baud_change else []
        return [(self.baud, ack)]


class ScriptedLink:
    """ConfigLink over a FakeUblox: frames sent at another rate than the link's are garbage (dropped)."""

    def __init__(self, receiver: FakeUblox, baud: int = 115200) -> None:
        self.receiver = receiver
        self.baud = baud
        self.pending: list[tuple[int, Frame]] = []
        self.sent: list[bytes] = []
        self.reopens: list[int] = []
        self.timeouts: list[float] = []
        self.garbled = 0

    async def send(self, raw: bytes) -> None:
        self.pending.clear()
        self.sent.append(raw)
        if self.baud != self.receiver.baud:
            self.garbled += 1  # the receiver sees framing errors, not a message
            return
        for baud, frame in self.receiver.handle(raw):
            self.pending += [(baud, f) for f in iter_frames(frame)]

    async def reopen(self, baud: int) -> None:
        self.reopens.append(baud)
        self.baud = baud

    async def wait_frame(self, match: Callable[[Frame], bool], timeout_s: float) -> Frame | None:
        self.timeouts.append(timeout_s)
        while self.pending:
            baud, frame = self.pending.pop(0)
            if baud == self.baud and match(frame):
                return frame
        return None
