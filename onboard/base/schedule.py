"""What the MSM base sends each epoch within the radio's byte budget (pure: no I/O, no clock).

`SecondBudget` holds the bytes of each second (GPS seconds of the epochs, `floor(t_s)`) to the budget: the
observations of an epoch always go (the rover needs every epoch; when they alone exceed the budget the second is
counted in `over_budget_s`, and the caller has already tried a smaller MSM), then the optional messages in the
order given while they fit; what does not fit is deferred and counted per kind, never dropped silently — the
caller offers it again at the next epoch. `EphemerisRotation` decides which ephemerides are due: a satellite's
new issue (never sent) first, then every satellite again once `interval_s` has passed since it was last sent,
the longest-waiting first.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Mapping
from dataclasses import dataclass, field


@dataclass
class BudgetCounts:
    """What went out (messages and bytes per kind), what was deferred, and the seconds whose observations alone
    exceeded the budget."""

    sent_bytes: int = 0
    sent: dict[str, int] = field(default_factory=dict)
    sent_bytes_by_kind: dict[str, int] = field(default_factory=dict)
    deferred: dict[str, int] = field(default_factory=dict)
    over_budget_s: int = 0


class SecondBudget:
    """At most `budget_bytes_s` bytes in any second of the epochs' time line (observations excepted, see module)."""

    def __init__(self, budget_bytes_s: float) -> None:
        if budget_bytes_s <= 0:
            raise ValueError("budget must be > 0 B/s")
        self.budget_bytes_s = budget_bytes_s
        self.counts = BudgetCounts()
        self._second: int | None = None
        self.used_bytes = 0
        """Bytes already sent in the current second."""
        self._over = False

    def left_bytes(self, t_s: float) -> float:
        """Bytes still free in the second of `t_s` (negative when the observations overran it)."""
        return self.budget_bytes_s - (self.used_bytes if math.floor(t_s) == self._second else 0)

    def offer(self, t_s: float, required: list[tuple[str, bytes]],
              optional: list[tuple[str, bytes]]) -> list[tuple[str, bytes]]:
        """The frames to send at `t_s`: every `required` one, then the `optional` ones (in order) that fit."""
        second = math.floor(t_s)
        if second != self._second:
            self._second, self.used_bytes, self._over = second, 0, False
        out = []
        for kind, frame in required:
            self._send(out, kind, frame)
        if self.used_bytes > self.budget_bytes_s and not self._over:
            self._over = True
            self.counts.over_budget_s += 1
        for kind, frame in optional:
            if self.used_bytes + len(frame) <= self.budget_bytes_s:
                self._send(out, kind, frame)
            else:
                self.counts.deferred[kind] = self.counts.deferred.get(kind, 0) + 1
        return out

    def _send(self, out: list[tuple[str, bytes]], kind: str, frame: bytes) -> None:
        out.append((kind, frame))
        self.used_bytes += len(frame)
        c = self.counts
        c.sent_bytes += len(frame)
        c.sent[kind] = c.sent.get(kind, 0) + 1
        c.sent_bytes_by_kind[kind] = c.sent_bytes_by_kind.get(kind, 0) + len(frame)


class EphemerisRotation:
    """Which satellites' ephemerides are due (see module doc); keys are any satellite ids, issues any value that
    changes with a new ephemeris (e.g. (toe, IODE))."""

    def __init__(self, interval_s: float) -> None:
        self.interval_s = interval_s
        self._last: dict[Hashable, tuple[Hashable, float]] = {}

    def due(self, t_s: float, issues: Mapping[Hashable, Hashable]) -> list[Hashable]:
        """The keys of `issues` (satellite → its current issue) due at `t_s`, in sending order."""
        new, old = [], []
        for key, issue in issues.items():
            last = self._last.get(key)
            if last is None or last[0] != issue:
                new.append(key)
            elif t_s - last[1] >= self.interval_s:
                old.append((last[1], key))
        return sorted(new, key=repr) + [k for _, k in sorted(old, key=lambda lk: (lk[0], repr(lk[1])))]

    def sent(self, key: Hashable, issue: Hashable, t_s: float) -> None:
        """Record that `key`'s `issue` went out at `t_s`."""
        self._last[key] = (issue, t_s)
