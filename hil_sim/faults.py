"""Fault injection for the receiver emulator: corrupt bytes, dropped epochs, port loss, hot-shoe bounce.

Pure and reproducible: every random choice comes from one seeded generator per emulator. The shell applies
`corrupt` to the bytes it writes and follows `unplug_windows_s` to close and recreate the pty; the receiver
core asks `drop_epoch` for each raw epoch and uses `hot_shoe_edges` for each flash.

What each fault does (documented behaviour the daemon is tested against):
- corrupt bytes: each byte written is XORed with a random non-zero value with probability
  `corrupt_byte_rate` (checksums then fail and the reader must resynchronise; nothing else is lost).
- dropped epochs: each raw epoch (RXM-RAW/RAWX) is withheld with probability `drop_epoch_rate` (a gap in the
  epochs, as when the receiver's TX buffer overflows).
- port loss: during each window (start_s, duration_s) of simulated time after start, the pty is closed (the
  reader gets EIO/hang-up) and the `--link` symlink removed; afterwards a new pty is created and the link
  points at it. The receiver keeps running and keeps its configuration (a USB-serial adapter re-enumerating,
  not a power cycle); output produced meanwhile is lost.
- lost flash report: each TIM-TM2 report of the flash line (EXTINT0) is withheld with probability
  `drop_flash_mark_rate` (as when line noise destroys that one frame): the flash's falling edge and the
  contact's rising edge are lost together, so the next flash report's `count` jumps by one extra — the only
  sign the recorder gets of a missed flash.
- hot-shoe bounce: with probability `bounce_prob` per flash, the contact opens and closes again
  `bounce_gap_s` after the flash (an extra rising and falling edge): TIM-TM2 then reports the bounce's
  falling edge and `count` jumps by 2.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from onboard.gnsstime import GpsTime


@dataclass(frozen=True)
class FaultOptions:
    """Fault rates and schedules (0 / empty = no fault). Times are simulated seconds after start."""

    seed: int = 0
    corrupt_byte_rate: float = 0.0
    drop_epoch_rate: float = 0.0
    drop_flash_mark_rate: float = 0.0
    bounce_prob: float = 0.0
    bounce_gap_s: float = 0.0006
    unplug_windows_s: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        for name in ("corrupt_byte_rate", "drop_epoch_rate", "drop_flash_mark_rate", "bounce_prob"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{name} must be a probability in [0, 1], got {v}")
        for start, dur in self.unplug_windows_s:
            if start < 0 or dur <= 0:
                raise ValueError(f"unplug window ({start}, {dur}) must start ≥ 0 s and last > 0 s")


class FaultState:
    """The seeded random state behind the faults, with counters of what was injected."""

    def __init__(self, options: FaultOptions) -> None:
        self.options = options
        self._rng = np.random.default_rng(options.seed)
        self.bytes_corrupted = 0
        self.epochs_dropped = 0
        self.flash_marks_dropped = 0
        self.bounces = 0

    def corrupt(self, data: bytes) -> bytes:
        """`data` with each byte XORed by a random non-zero value with probability `corrupt_byte_rate`."""
        rate = self.options.corrupt_byte_rate
        if rate <= 0.0 or not data:
            return data
        arr = np.frombuffer(data, np.uint8).copy()
        hit = self._rng.random(arr.size) < rate
        n = int(hit.sum())
        if n:
            arr[hit] ^= self._rng.integers(1, 256, n, dtype=np.uint8)
            self.bytes_corrupted += n
        return arr.tobytes()

    def drop_epoch(self) -> bool:
        """True when this raw epoch is to be withheld."""
        if self.options.drop_epoch_rate <= 0.0:
            return False
        if self._rng.random() < self.options.drop_epoch_rate:
            self.epochs_dropped += 1
            return True
        return False

    def drop_flash_mark(self) -> bool:
        """True when this TIM-TM2 report of the flash line is to be withheld."""
        if self.options.drop_flash_mark_rate <= 0.0:
            return False
        if self._rng.random() < self.options.drop_flash_mark_rate:
            self.flash_marks_dropped += 1
            return True
        return False

    def bounce(self) -> bool:
        """True when this flash's contact bounces."""
        if self.options.bounce_prob <= 0.0:
            return False
        if self._rng.random() < self.options.bounce_prob:
            self.bounces += 1
            return True
        return False

    def unplugged(self, elapsed_s: float) -> bool:
        """True while simulated time `elapsed_s` (since start) lies in an unplug window."""
        return any(start <= elapsed_s < start + dur for start, dur in self.options.unplug_windows_s)


def hot_shoe_edges(flash: GpsTime, contact_closed_s: float, faults: FaultState,
                   extra_bounces: Iterable[GpsTime] = ()) -> list[tuple[GpsTime, bool]]:
    """Edges (GPS time, rising?) of the hot-shoe line for one flash: falling at the flash, rising when the
    contact opens; a bounce adds an open/close pair `bounce_gap_s` apart. `extra_bounces` are falling-edge
    times of bounces the world already simulated (each preceded by a rising edge half a gap earlier)."""
    edges: list[tuple[GpsTime, bool]] = [(flash, False)]
    gap = faults.options.bounce_gap_s
    if faults.bounce():
        edges += [(flash.add_s(gap / 2), True), (flash.add_s(gap), False)]
    for b in extra_bounces:
        edges += [(b.add_s(-gap / 2), True), (b, False)]
    last_fall = max(t for t, rising in edges if not rising)
    edges.append((max(flash.add_s(contact_closed_s), last_fall.add_s(gap / 2)), True))
    return sorted(edges, key=lambda e: e[0])
