"""gpiozero EdgeSource: timestamped edges of one GPIO input (e.g. the camera trigger line).

The pin factory is passed in (lgpio in production, set explicitly; `MockFactory` in tests). The edge time is
the factory's tick of the change — with lgpio the kernel's line-event timestamp on CLOCK_MONOTONIC — read from
the device's last-change tick inside the callback, because gpiozero callbacks get no timestamp argument.
"""

from __future__ import annotations

import logging
from typing import Any

from gpiozero import DigitalInputDevice

from onboard.hw.edge_queue import EdgeQueue
from onboard.hw.ports import Edge

log = logging.getLogger(__name__)


def lgpio_factory() -> Any:
    """The production pin factory (lgpio: works on Pi 4 and Pi 5; pigpio does not work on a Pi 5)."""
    from gpiozero.pins.lgpio import LGPIOFactory

    return LGPIOFactory()


def pin_factory(name: str) -> Any:
    """The gpiozero pin factory named by the settings key `gpio.pin_factory`: "lgpio" (the Pi) or "mock"
    (gpiozero's MockFactory: the hardware edge's test double, pins driven by a test)."""
    if name == "mock":
        from gpiozero.pins.mock import MockFactory

        return MockFactory()
    return lgpio_factory()


class GpioEdgeSource:
    """Queue of edges on one BCM pin.

    Parameters
    ----------
    pin : BCM pin number (or gpiozero pin name).
    pin_factory : gpiozero pin factory (never a global default: the composition root chooses it).
    line : name put in each `Edge.line` (e.g. "trigger").
    pull_up : gpiozero pull-up setting (None with `active_state` for an externally driven line).
    max_queue : edges kept when nobody reads (oldest dropped and counted in `dropped`).
    """

    def __init__(
        self,
        pin: int | str,
        pin_factory: Any,
        line: str = "gpio",
        pull_up: bool | None = False,
        max_queue: int = 4096,
    ) -> None:
        self.line = line
        self._factory = pin_factory
        active_state = True if pull_up is None else None
        # gpiozero reports "active" = low when the internal pull-up is on; edges are about the level.
        self._active_high = pull_up is not True
        self._device = DigitalInputDevice(pin, pull_up=pull_up, active_state=active_state, pin_factory=pin_factory)
        self._queue = EdgeQueue(max_queue)
        self._device.when_activated = lambda: self._on_edge(True)
        self._device.when_deactivated = lambda: self._on_edge(False)

    def _on_edge(self, active: bool) -> None:
        # `_last_changed` is set by gpiozero to the event's tick just before this callback fires.
        ticks_s = float(self._device._last_changed)
        rising = active if self._active_high else not active
        self._queue.put(Edge(self.line, rising, round(ticks_s * 1e9)))

    @property
    def dropped(self) -> int:
        """Edges dropped because nobody read them (the queue was full)."""
        return self._queue.dropped

    @property
    def closed(self) -> bool:
        """True after `close`."""
        return self._queue.closed

    def get(self, timeout_s: float) -> Edge | None:
        """The next edge in order, waiting up to `timeout_s`; None on timeout or after close."""
        return self._queue.get(timeout_s)

    def close(self) -> None:
        """Release the pin and wake any waiting reader."""
        self._device.close()
        self._queue.close()
