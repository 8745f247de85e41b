"""Apply a configuration profile over a `ConfigLink`: one CFG at a time, ACK/NAK, retry, poll back, diff, report.

The daemon owns the one reader loop (every byte is journaled before the framer sees it) and hands frames to
the link; this module never reads the port. Nothing here raises on a NAK or silence: each problem becomes a
`ConfigRejected` (message, field, detail) in the JSON-able `ConfigReport` the status snapshot shows, and the
caller keeps recording whatever the receiver sends. Only `LinkLost` (from the link) propagates.

Timeouts are the link's: `wait_frame` waits on the event loop's monotonic clock (never the wall clock).
"""

from __future__ import annotations

import asyncio
import logging
from collections import deque
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from onboard.errors import ConfigRejected, ReceiverError
from onboard.receiver.framing import Frame, ubx_frame
from onboard.receiver.framing import Protocol as FrameProtocol
from onboard.receiver.profiles import BAUD_RATES, Profile, ProfileEntry, ReceiverOptions, decode_cfg
from onboard.receiver.ubx_tables import UBX_IDS, poll_frame
from onboard.timepulse.marks import timepulse_record

log = logging.getLogger(__name__)

ACK_CLASS = 0x05
ACK_ID, NAK_ID = UBX_IDS["ACK-ACK"][1], UBX_IDS["ACK-NAK"][1]


class ConfigLink(Protocol):
    """What configuration needs from the receiver link.

    `send(raw)` writes the bytes and returns once they are handed to the device (drained). `wait_frame(match,
    timeout_s)` returns the first valid frame received *after the latest* `send` for which `match` is true,
    waiting at most `timeout_s` on a monotonic clock, or None. `reopen(baud)` reopens the port at a new
    rate (a no-op on USB or a pseudo-terminal).
    """

    async def send(self, raw: bytes) -> None: ...

    async def wait_frame(self, match: Callable[[Frame], bool], timeout_s: float) -> Frame | None: ...

    async def reopen(self, baud: int) -> None: ...


class FrameQueueLink:
    """A `ConfigLink` fed by the caller's reader loop: `feed(frame)` for every frame the framer yields.

    `write` sends bytes to the device; `reopen` (optional) changes its baud rate. Frames older than the latest
    `send` are dropped, so an answer to an earlier message can never be taken for the current one. Keeps at
    most `max_frames` unconsumed frames (a chatty receiver cannot grow memory).
    """

    def __init__(
        self,
        write: Callable[[bytes], Awaitable[None]],
        reopen: Callable[[int], Awaitable[None]] | None = None,
        max_frames: int = 512,
    ) -> None:
        self._write = write
        self._reopen = reopen
        self._frames: deque[Frame] = deque(maxlen=max_frames)
        self._arrived = asyncio.Event()

    def feed(self, frame: Frame) -> None:
        """Hand one received frame to the link (call from the reader loop, same event loop)."""
        self._frames.append(frame)
        self._arrived.set()

    async def send(self, raw: bytes) -> None:
        """Forget earlier frames, then write `raw`."""
        self._frames.clear()
        await self._write(raw)

    async def reopen(self, baud: int) -> None:
        """Reopen at `baud` (no-op without a reopen hook) and forget frames received at the old rate."""
        if self._reopen is not None:
            await self._reopen(baud)
        self._frames.clear()

    async def wait_frame(self, match: Callable[[Frame], bool], timeout_s: float) -> Frame | None:
        """First queued or arriving frame that matches, or None after `timeout_s`."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while True:
            while self._frames:
                frame = self._frames.popleft()
                if match(frame):
                    return frame
            remaining = deadline - loop.time()
            if remaining <= 0:
                return None
            self._arrived.clear()
            try:
                await asyncio.wait_for(self._arrived.wait(), remaining)
            except TimeoutError:
                return None


# --- receiver identification ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ReceiverInfo:
    """MON-VER contents and the model we derived: "lea6t", "m8t" or "unknown"; `family` "u-blox 6"/"u-blox 8"/""."""

    model: str
    sw_version: str
    hw_version: str
    extensions: tuple[str, ...]
    family: str = ""

    def to_json(self) -> dict[str, Any]:
        """JSON-able dict for the status snapshot."""
        return {
            "model": self.model,
            "family": self.family,
            "sw_version": self.sw_version,
            "hw_version": self.hw_version,
            "extensions": list(self.extensions),
        }


def _cstr(raw: bytes) -> str:
    return raw.split(b"\x00", 1)[0].decode("ascii", "replace").strip()


def parse_mon_ver(payload: bytes) -> ReceiverInfo:
    """ReceiverInfo from a MON-VER payload (swVersion C30, hwVersion C10, n × extension C30).

    hwVersion 00040007 is u-blox 6 (our LEA-6T profile: RXM-RAW/SFRB, CFG-TP fallback); 00080000 with a
    timing firmware (FWVER=TIM…) or MOD=…M8T is the M8T; anything else is "unknown".
    """
    if len(payload) < 40 or (len(payload) - 40) % 30:
        raise ReceiverError(f"MON-VER: payload of {len(payload)} bytes is not 40 + 30·n")
    sw = _cstr(payload[:30])
    hw = _cstr(payload[30:40])
    ext = tuple(s for s in (_cstr(payload[i : i + 30]) for i in range(40, len(payload), 30)) if s)
    joined = " ".join(ext).upper()
    if hw.startswith("0004"):
        family, model = "u-blox 6", ("lea6t" if hw == "00040007" else "unknown")
    elif hw.startswith("0008"):
        family = "u-blox 8"
        model = "m8t" if ("FWVER=TIM" in joined or "M8T" in joined) else "unknown"
    else:
        family, model = "", "unknown"
    return ReceiverInfo(model, sw, hw, ext, family)


def _is_answer(name: str, key: bytes) -> Callable[[Frame], bool]:
    cls, mid = UBX_IDS[name]

    def match(frame: Frame) -> bool:
        return (
            frame.protocol is FrameProtocol.UBX
            and frame.msg_class == cls
            and frame.msg_id == mid
            and len(frame.payload) > len(key)
            and frame.payload.startswith(key)
        )

    return match


def _is_ack(cls: int, mid: int) -> Callable[[Frame], bool]:
    def match(frame: Frame) -> bool:
        return (
            frame.protocol is FrameProtocol.UBX
            and frame.msg_class == ACK_CLASS
            and frame.msg_id in (ACK_ID, NAK_ID)
            and frame.payload[:2] == bytes((cls, mid))
        )

    return match


async def detect_receiver(link: ConfigLink, timeout_s: float = 1.0, retries: int = 2) -> ReceiverInfo:
    """Poll MON-VER (up to 1 + `retries` times) and identify the receiver.

    Raises ConfigRejected("MON-VER", …) when the receiver never answers or answers garbage.
    """
    match = _is_answer("MON-VER", b"")
    for attempt in range(1 + retries):
        await link.send(poll_frame("MON-VER"))
        frame = await link.wait_frame(match, timeout_s)
        if frame is not None:
            try:
                info = parse_mon_ver(frame.payload)
            except ReceiverError as exc:
                raise ConfigRejected("MON-VER", str(exc)) from exc
            log.info("receiver %s: sw %s hw %s %s", info.model, info.sw_version, info.hw_version, info.extensions)
            return info
        log.warning("MON-VER poll %d unanswered", attempt + 1)
    raise ConfigRejected("MON-VER", f"no answer to {1 + retries} polls within {timeout_s} s each")


async def probe_baud(
    link: ConfigLink,
    reopen: Callable[[int], Awaitable[None]] | None = None,
    candidates: Sequence[int] = BAUD_RATES,
    listen_s: float = 1.0,
) -> int | None:
    """Find the receiver's baud rate: reopen at each candidate, poll MON-VER, confirm by any valid frame.

    At a wrong rate the framer sees only checksum failures, so one valid UBX or NMEA frame confirms the rate.
    Returns the rate, or None when no candidate produced a valid frame (the port is left at the last one).
    """
    do_reopen = reopen if reopen is not None else link.reopen
    for baud in candidates:
        await do_reopen(baud)
        await link.send(poll_frame("MON-VER"))
        if await link.wait_frame(lambda _f: True, listen_s) is not None:
            log.info("receiver answers at %d baud", baud)
            return baud
    return None


# --- applying a profile -----------------------------------------------------------------------------------


@dataclass(slots=True)
class FieldDiff:
    """A field whose polled-back value differs from what we sent; `tolerated` when the receiver may do so."""

    field: str
    wanted: int
    applied: int | None
    tolerated: bool

    def to_json(self) -> dict[str, Any]:
        """JSON-able dict."""
        return {"field": self.field, "wanted": self.wanted, "applied": self.applied, "tolerated": self.tolerated}


@dataclass(slots=True)
class MessageResult:
    """What happened to one CFG message.

    `ack` "ack" | "nak" | "none"; `polled_back` True when the poll answer arrived; `status` "ok", "altered"
    (only tolerated differences), "mismatch", "naked", "silent", "unverified" (ACKed, poll unanswered),
    "replaced" (its group fell back), "sent" (cannot be polled, ACKed); `applied` the polled-back values of
    the compared fields; `fallback_for` the group this message replaces.
    """

    label: str
    name: str
    attempts: int = 0
    ack: str = "none"
    polled_back: bool = False
    status: str = "silent"
    diff: list[FieldDiff] = field(default_factory=list)
    applied: dict[str, int | None] = field(default_factory=dict)
    detail: str = ""
    fallback_for: str | None = None

    def to_json(self) -> dict[str, Any]:
        """JSON-able dict."""
        return {
            "label": self.label,
            "name": self.name,
            "attempts": self.attempts,
            "ack": self.ack,
            "polled_back": self.polled_back,
            "status": self.status,
            "diff": [d.to_json() for d in self.diff],
            "applied": dict(self.applied),
            "detail": self.detail,
            "fallback_for": self.fallback_for,
        }


@dataclass(slots=True)
class ConfigReport:
    """The outcome of `apply_profile`, JSON-able through `to_json()` for the status snapshot.

    `errors` ConfigRejected per failed message (NAK without fallback, silence, wrong poll-back);
    `warnings` texts (fallbacks taken, tolerated alterations, unverified settings); `camera_timepulse` the pin
    actually driving the camera; `baud` the link's rate at the end (None if unknown).
    """

    model: str
    receiver: ReceiverInfo | None
    camera_timepulse: str
    trigger: str
    messages: list[MessageResult] = field(default_factory=list)
    errors: list[ConfigRejected] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    baud: int | None = None

    @property
    def ok(self) -> bool:
        """True when every message was applied (tolerated alterations and fallbacks allowed)."""
        return not self.errors

    def result(self, label: str) -> MessageResult:
        """The result of the message with `label` (KeyError if it was never attempted)."""
        for msg in self.messages:
            if msg.label == label:
                return msg
        raise KeyError(label)

    def to_json(self) -> dict[str, Any]:
        """JSON-able dict for the status snapshot and the flight manifest."""
        return {
            "ok": self.ok,
            "model": self.model,
            "receiver": self.receiver.to_json() if self.receiver else None,
            "camera_timepulse": self.camera_timepulse,
            "trigger": self.trigger,
            "trigger_measured": self.trigger != "none",
            "baud": self.baud,
            "messages": [m.to_json() for m in self.messages],
            "errors": [{"message": e.message, "field": e.field, "detail": e.detail} for e in self.errors],
            "warnings": list(self.warnings),
        }


async def _wait_ack(link: ConfigLink, entry: ProfileEntry, timeout_s: float) -> str:
    frame = await link.wait_frame(_is_ack(entry.raw[2], entry.raw[3]), timeout_s)
    if frame is None:
        return "none"
    return "ack" if frame.msg_id == ACK_ID else "nak"


async def _poll_back(link: ConfigLink, entry: ProfileEntry, options: ReceiverOptions) -> Frame | None:
    assert entry.poll is not None
    cls, mid = entry.raw[2], entry.raw[3]
    answer = _is_answer(entry.name, entry.poll)
    nak = _is_ack(cls, mid)
    for _ in range(1 + options.retries):
        await link.send(ubx_frame(cls, mid, entry.poll))
        frame = await link.wait_frame(lambda f: answer(f) or (nak(f) and f.msg_id == NAK_ID), options.ack_timeout_s)
        if frame is not None:
            return None if frame.msg_class == ACK_CLASS else frame
    return None


def _compare(entry: ProfileEntry, result: MessageResult, frame: Frame) -> None:
    try:
        applied = decode_cfg(frame.raw)
    except ReceiverError as exc:
        result.status = "mismatch"
        result.detail = f"poll answer unreadable: {exc}"
        return
    result.applied = {f: applied.get(f) for f in entry.compare}
    result.diff = [
        FieldDiff(f, entry.fields[f], applied.get(f), f in entry.may_alter)
        for f in entry.compare
        if applied.get(f) != entry.fields[f]
    ]
    if any(not d.tolerated for d in result.diff):
        result.status = "mismatch"
    elif result.diff:
        result.status = "altered"
    else:
        result.status = "ok"


async def _apply_entry(
    link: ConfigLink, entry: ProfileEntry, options: ReceiverOptions, current_baud: int | None
) -> tuple[MessageResult, int | None]:
    """Send one CFG (with retries), poll it back and compare. Returns the result and the link's baud after."""
    result = MessageResult(entry.label, entry.name)
    if not entry.expect_ack:  # never answered (CFG-RST): nothing to wait for, nothing to read back
        result.attempts = 1
        await link.send(entry.raw)
        result.status = "sent"
        result.detail = "not acknowledged by design"
        return result, current_baud
    changes_baud = entry.baud_change is not None and entry.baud_change != current_baud
    for _ in range(1 + options.retries):
        result.attempts += 1
        await link.send(entry.raw)
        if changes_baud:
            assert entry.baud_change is not None
            # The receiver answers at the new rate or not at all: move over, then let the poll-back decide.
            # First let the frame leave at the old rate (a pty or USB bridge buffers past tcdrain).
            await asyncio.sleep(options.baud_settle_s)
            await link.reopen(entry.baud_change)
            # The ACK, if we catch it at all, is already due: the poll-back below is the real confirmation.
            result.ack = await _wait_ack(link, entry, max(options.baud_settle_s, 0.05))
            if result.ack == "nak":
                if current_baud is not None:
                    await link.reopen(current_baud)
                break
            frame = await _poll_back(link, entry, options)
            if frame is not None:
                result.polled_back = True
                _compare(entry, result, frame)
                if result.ack == "none":
                    result.detail = "no ACK across the baud change; confirmed by poll-back at the new rate"
                return result, entry.baud_change
            if result.ack == "ack":  # the ACK came at the new rate: the receiver is there, only the poll failed
                result.status = "unverified"
                result.detail = f"ACKed at {entry.baud_change} baud, but the poll-back was not answered"
                return result, entry.baud_change
            if current_baud is not None:
                # Nothing at the new rate: is the receiver still at the old one (it NAKed or ignored us there)?
                await link.reopen(current_baud)
                frame = await _poll_back(link, entry, options)
                if frame is not None:
                    result.polled_back = True
                    _compare(entry, result, frame)
                    result.detail = f"receiver stayed at {current_baud} baud"
                    return result, current_baud
            continue
        result.ack = await _wait_ack(link, entry, options.ack_timeout_s)
        if result.ack != "none":
            break
        log.warning("%s: no ACK/NAK within %.1f s (attempt %d)", entry.label, options.ack_timeout_s, result.attempts)
    if result.ack == "nak":
        result.status = "naked"
        result.detail = "NAKed by the receiver"
        return result, current_baud
    if result.ack == "none":
        result.status = "silent"
        if changes_baud:
            result.detail = f"no valid frames at {entry.baud_change} baud after {result.attempts} attempt(s)"
        else:
            result.detail = f"no ACK/NAK within {options.ack_timeout_s} s after {result.attempts} attempt(s)"
        return result, current_baud
    if entry.poll is None:
        result.status = "sent"
        return result, current_baud
    frame = await _poll_back(link, entry, options)
    if frame is None:
        result.status = "unverified"
        result.detail = "ACKed, but the poll-back was not answered"
        return result, current_baud
    result.polled_back = True
    _compare(entry, result, frame)
    return result, current_baud


def _record(report: ConfigReport, entry: ProfileEntry, result: MessageResult) -> None:
    report.messages.append(result)
    if result.status in ("ok", "sent", "replaced"):
        return
    if result.status == "altered":
        for d in result.diff:
            report.warnings.append(f"{entry.label}: receiver set {d.field}={d.applied} (sent {d.wanted})")
        return
    if result.status == "unverified":
        report.warnings.append(f"{entry.label}: {result.detail}")
        return
    if result.status == "mismatch":
        bad = [d for d in result.diff if not d.tolerated]
        if bad:
            for d in bad:
                report.errors.append(
                    ConfigRejected(entry.label, f"receiver applied {d.applied}, we sent {d.wanted}", d.field)
                )
        else:
            report.errors.append(ConfigRejected(entry.label, result.detail))
        return
    field_name = "baudRate" if entry.baud_change is not None and result.status == "silent" else None
    report.errors.append(ConfigRejected(entry.label, result.detail, field_name))


async def apply_profile(
    link: ConfigLink,
    profile: Profile,
    options: ReceiverOptions,
    *,
    receiver: ReceiverInfo | None = None,
    current_baud: int | None = None,
) -> ConfigReport:
    """Apply `profile` one message at a time and report what the receiver actually applied.

    Each CFG: send, wait ACK/NAK ≤ `options.ack_timeout_s`, resend after silence up to `options.retries`
    times, poll back and compare field by field. A NAK of a message in a fallback group (CFG-TP5, RXM-RAWX,
    NAV-PVT) replaces the rest of that group by the profile's fallback messages (legacy CFG-TP, RXM-RAW,
    NAV-SOL). `current_baud` is the rate the link is open at (None when unknown: a CFG-PRT is then treated
    as a baud change). Never raises on receiver behaviour; `LinkLost` from the link propagates.
    """
    report = ConfigReport(profile.model, receiver, profile.camera_timepulse, profile.trigger, baud=current_baud)
    replaced: set[str] = set()
    for entry in profile.entries:
        if entry.group in replaced:
            _record(report, entry, MessageResult(entry.label, entry.name, status="replaced",
                                                 detail=f"group {entry.group} fell back"))
            continue
        result, report.baud = await _apply_entry(link, entry, options, report.baud)
        fallback = profile.fallbacks.get(entry.group) if entry.group else None
        if result.status == "naked" and fallback:
            replaced.add(entry.group or "")
            result.detail += f"; falling back to {', '.join(f.label for f in fallback)}"
            report.messages.append(result)
            report.warnings.append(f"{entry.label}: NAKed, using {', '.join(f.label for f in fallback)}")
            for fb_entry in fallback:
                fb_result, report.baud = await _apply_entry(link, fb_entry, options, report.baud)
                fb_result.fallback_for = entry.group
                _record(report, fb_entry, fb_result)
                if fb_entry.name == "CFG-TP" and fb_result.status in ("ok", "altered", "unverified"):
                    report.camera_timepulse = "TIMEPULSE"
            continue
        _record(report, entry, result)
    for err in report.errors:
        log.error("configuration: %s", err)
    return report


def camera_timepulse_record(report: ConfigReport, profile: Profile) -> dict[str, Any]:
    """The `timepulse` event record (onboard.timepulse.marks) of what the receiver applied to the camera pulse.

    Values as polled back where the poll answered, else as sent (`align_to_tow` None: not known).
    """
    cam_entries = [e for e in profile.entries if e.label.endswith("camera")]
    cam_entries += [e for group in profile.fallbacks.values() for e in group if e.label.endswith("camera")]
    for entry in reversed(cam_entries):  # a fallback, when taken, supersedes the CFG-TP5 it replaced
        try:
            result = report.result(entry.label)
        except KeyError:
            continue
        if result.status in ("naked", "replaced", "silent"):
            continue
        got = {k: v for k, v in result.applied.items() if v is not None} if result.polled_back else {}
        values = {**entry.fields, **got}
        if entry.name == "CFG-TP":
            return timepulse_record(report.camera_timepulse, values["interval"], values["length"],
                                    values["status"] > 0, None, report.trigger)
        return timepulse_record(report.camera_timepulse, values["freqPeriodLock"], values["pulseLenRatioLock"],
                                bool(values["polarity"]), got.get("alignToTow"), report.trigger)
    rec = timepulse_record(report.camera_timepulse, 0, 0, True, None, report.trigger)
    rec["note"] = "camera pulse not configured: " + "; ".join(str(e) for e in report.errors)
    return rec
