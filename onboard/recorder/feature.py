"""The recorder's extension seam: a `RecorderFeature` gets the flight's lifecycle and the receiver's data.

A feature is one thing the recorder does besides recording (real-time RTK, the base station's correction sender,
an autopilot link): the composition root (`onboard.recorder.app`) builds the features the settings ask for and
passes them to `Recorder(settings, deps, features)`. The recorder calls each hook at one defined point, on its
event loop, in the order the features were given:

    on_flight_opened(flight)   once, right after the flight directory is chosen and the journal and event log
                               are open, before the reader thread starts (so before any other hook): start
                               threads, open files in `flight.flight_dir`
    on_bytes(data, rx_ns)      every chunk read from the receiver port, after it was journaled
    on_frame(frame)            every checksum-valid frame (UBX, NMEA, RTCM3) of that stream
    on_decoded(item)           every decoded item (`onboard.receiver.decode` types: ObsEpoch, SubframeWords, ...)
    status()                   every status snapshot (~1 s) and at close: a JSON-able dict written as
                               `status_name` beside the recorder's status.json (through `write_status`), or
                               None for nothing
    on_flight_closing(reason)  the flight is about to close (a stop or a roll-over): the event log is still
                               open and `flight.append_event` still writes into this flight; append the last
                               records (what is queued, what can be decided now); the receiver's reader has
                               stopped when the recording stops (not at a roll-over)
    on_flight_closed(reason)   after the journal was closed, before the last snapshot: stop threads,
                               close files

A flight can also end while recording goes on (`FlightContext.close_flight`: the autopilot link after landing):
the recorder closes the flight and opens the next one between two appends of the receiver's bytes, and calls
`on_flight_closed(reason)` with a roll-over reason (`is_rollover(reason)`) then `on_flight_opened(next)`. A
feature that keeps a link open (the autopilot's) may keep it across a roll-over and move only its files; one
that stops its threads at close must be able to start again in the next flight.

A hook must return quickly (it runs on the loop that also times marks and pets the watchdog): slow work goes to
the feature's own threads, which hand results back with `flight.post(fn, *args)` (run on the loop, in order).
An exception in a hook is logged (with its traceback, the first time) and counted in the status snapshot's
`feature_errors`; it never stops recording (the raw bytes are the product).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from onboard.hw.ports import Clock
from onboard.logger.journal import JournalOptions
from onboard.receiver.framing import Frame


@dataclass(frozen=True)
class FlightContext:
    """What a feature gets when the flight opens.

    `flight_dir` the flight being recorded (a resumed flight after a crash is the same directory); `clock` the
    recorder's clock (monotonic and wall ns); `journal_options` how the recorder journals (segment size/age,
    sync interval), for a feature that journals a stream of its own; `status_path` the recorder's status.json
    (a feature's snapshot goes beside it); `post(fn, *args)` runs `fn(*args)` on the recorder's loop in posting
    order (safe from any thread); `request_stop(reason, exit_code)` stops the recorder (loop only);
    `append_event(record)` appends one JSON-able record to the flight's events.jsonl (loop only: from a thread,
    `post(append_event, record)`; None when the recorder keeps no event log); `close_flight(reason)` closes this
    flight and continues recording into a new one without a gap (loop only; None when the recorder cannot);
    `resumed` the flight was resumed after an unclean stop (its past is unknown: maybe mid-air); `previous_flight_dir`
    the flight closed just before this one by a roll-over (None at start).
    """

    flight_dir: Path
    clock: Clock
    journal_options: JournalOptions
    status_path: Path
    post: Callable[..., None]
    request_stop: Callable[[str, int], None]
    append_event: Callable[[dict[str, Any]], None] | None = None
    close_flight: Callable[[str], None] | None = None
    resumed: bool = False
    previous_flight_dir: Path | None = None


ROLLOVER_PREFIX = "rollover: "
"""Start of the close reason of a flight closed while recording continues into the next one."""


def rollover_reason(why: str) -> str:
    """The close reason of a roll-over (`why`: e.g. "disarmed, on the ground for 20 s")."""
    return ROLLOVER_PREFIX + why


def is_rollover(reason: str) -> bool:
    """Whether `on_flight_closed(reason)` will be followed by `on_flight_opened` (recording goes on)."""
    return reason.startswith(ROLLOVER_PREFIX)


class RecorderFeature:
    """Base of the recorder's features: every hook does nothing; override those you need (see module doc).

    `name` identifies the feature in logs and in the status snapshot's `feature_errors`; `status_name` is the
    file its `status()` is written to, beside status.json (None: the feature writes no snapshot).
    """

    name: str = "feature"
    status_name: str | None = None

    def on_flight_opened(self, flight: FlightContext) -> None:
        """The flight is open (journal and event log): start threads, open files."""

    def on_bytes(self, data: bytes, rx_monotonic_ns: int) -> None:
        """Bytes read from the receiver port (already journaled) and the monotonic ns they arrived at."""

    def on_frame(self, frame: Frame) -> None:
        """One checksum-valid frame of the receiver stream."""

    def on_decoded(self, item: Any) -> None:
        """One decoded item of the receiver stream."""

    def status(self) -> dict[str, Any] | None:
        """This feature's snapshot (JSON-able), written as `status_name`; None: nothing to write now."""
        return None

    def on_flight_closing(self, reason: str) -> None:
        """The flight is about to close (`is_rollover(reason)`: recording goes on): the event log is still open;
        append this flight's last records now."""

    def on_flight_closed(self, reason: str) -> None:
        """The flight is closed (`reason` why; `is_rollover(reason)`: the next flight opens at once): stop threads,
        close files."""
