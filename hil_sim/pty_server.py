"""The emulator's thin shell: a real pseudo-terminal, a thread that runs the `ReceiverCore` in simulated time.

Line-rate modelling: a pty has no baud rate, but the termios settings the client applies to the slave are
visible from the master side (`tcgetattr` on a Linux pty master reads the slave's termios). The emulator
compares the client's output speed with the receiver's configured UART1 rate: when they differ, every byte
in either direction is garbage (the receiver does not see the client's frames; the client receives bytes
with the high bit set, which can never form a UBX sync, an NMEA '$' or an RTCM preamble). So after a CFG-PRT
baud change the ACK arrives only once the client has switched to the new rate, like a real UART.
A pty cannot tell when a byte was written, so input counts as sent at the client's rate seen now or at the
previous loop step (≤ 20 ms earlier): a client that writes and switches its rate at once keeps its frame.

Data written while the client is not reading fills the pty buffer (about 4 KiB on Linux); the rest is
dropped and counted (`tx_overrun_bytes`). Open the port with a fresh input flush (pyserial does) to discard
the stale bytes a real UART would never have delivered.
"""

from __future__ import annotations

import dataclasses
import errno
import logging
import os
import select
import termios
import threading
import tty
from pathlib import Path
from typing import Any, Self

from hil_sim.receiver import ModelName, ReceiverCore, ReceiverOptions, WorldLike
from onboard.gnsstime import GpsTime
from onboard.hw.ports import Clock, SystemClock
from onboard.receiver.framing import StreamFramer

log = logging.getLogger(__name__)

_SPEEDS: dict[int, int] = {
    getattr(termios, f"B{b}"): b
    for b in (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600)
    if hasattr(termios, f"B{b}")
}
_BAUD_CONST: dict[int, int] = {v: k for k, v in _SPEEDS.items()}


def garble(data: bytes) -> bytes:
    """What a UART at the wrong rate delivers, modelled: same length, high bit set (never a frame start)."""
    return bytes(((b ^ 0xA5) | 0x80) for b in data)


class PtyPort:
    """A pseudo-terminal pair owned by the emulator, with an optional stable symlink to the slave."""

    def __init__(self, link: str | os.PathLike[str] | None = None) -> None:
        self.link = Path(link) if link is not None else None
        self.master_fd = -1
        self.slave_fd = -1
        self.slave_path = ""
        self.tx_overrun_bytes = 0

    @property
    def is_open(self) -> bool:
        return self.master_fd >= 0

    def open(self, baud: int) -> str:
        """Create a new pty (raw, `baud` preset for clients that do not set one); return the slave path."""
        self.master_fd, self.slave_fd = os.openpty()
        tty.setraw(self.slave_fd)
        attrs = termios.tcgetattr(self.slave_fd)
        attrs[4] = attrs[5] = _BAUD_CONST.get(baud, termios.B9600)
        termios.tcsetattr(self.slave_fd, termios.TCSANOW, attrs)
        os.set_blocking(self.master_fd, False)
        self.slave_path = os.ttyname(self.slave_fd)
        if self.link is not None:
            tmp = self.link.with_name(self.link.name + f".tmp{os.getpid()}")
            tmp.unlink(missing_ok=True)
            os.symlink(self.slave_path, tmp)
            os.replace(tmp, self.link)  # atomic: the link never dangles while a pty exists
        return self.slave_path

    def close(self) -> None:
        """Close both ends (the client sees EIO/hang-up) and remove the symlink."""
        if self.link is not None and self.link.is_symlink():
            self.link.unlink(missing_ok=True)
        for fd in (self.master_fd, self.slave_fd):
            if fd >= 0:
                os.close(fd)
        self.master_fd = self.slave_fd = -1

    def client_baud(self) -> int | None:
        """The line rate the client set on the slave (None if unknown)."""
        if not self.is_open:
            return None
        return _SPEEDS.get(termios.tcgetattr(self.master_fd)[5])

    def read(self) -> bytes:
        """Bytes the client wrote (b"" when none)."""
        try:
            return os.read(self.master_fd, 4096)
        except BlockingIOError:
            return b""
        except OSError as exc:
            if exc.errno == errno.EIO:
                return b""
            raise

    def write(self, data: bytes) -> int:
        """Write without blocking; what does not fit in the pty buffer is dropped and counted."""
        done = 0
        while done < len(data):
            try:
                done += os.write(self.master_fd, data[done:])
            except BlockingIOError:
                break
        self.tx_overrun_bytes += len(data) - done
        return done


class ReceiverEmulator:
    """A u-blox receiver on a real pseudo-terminal, running in a background thread.

    `speed` runs the simulated GPS clock N× real time (the byte budget follows simulated time). `link` makes a
    stable symlink to the current slave (re-pointed when a port-loss fault recreates the pty). `t_start` is
    the simulated GPS time at power-on (default: the World scenario's start). `receiver="base"` makes it the
    world's static base receiver (run a second emulator for it on its own pty).
    """

    def __init__(self, model: ModelName | str, options: ReceiverOptions | None = None,
                 world: WorldLike | None = None, *, speed: float = 1.0, link: str | os.PathLike[str] | None = None,
                 t_start: GpsTime | None = None, initial_baud: int = 9600, clock: Clock | None = None,
                 receiver: str | None = None) -> None:
        if world is None:
            raise ValueError("ReceiverEmulator needs a World (hil_sim.world.World or a WorldLike)")
        if speed <= 0:
            raise ValueError(f"speed must be > 0, got {speed}")
        self.options = options or ReceiverOptions()
        if receiver is not None:  # "rover" or "base": which of the world's receivers this port is
            self.options = dataclasses.replace(self.options, receiver=receiver)  # type: ignore[arg-type]
        if t_start is None:
            scenario: Any = getattr(world, "scenario", None)
            t_start = getattr(scenario, "start", None)
            if t_start is None:
                raise ValueError("t_start not given and the world has no scenario.start")
        self.core = ReceiverCore(model, self.options, world, t_start)
        if initial_baud != 9600:
            self.core.config.ports[1]["baudRate"] = initial_baud
            self.core.saved.ports[1]["baudRate"] = initial_baud
            self.core.budget.baud = initial_baud
        self.speed = float(speed)
        self.t_start = t_start
        self.port = PtyPort(link)
        self.clock = clock or SystemClock()
        self.framer = StreamFramer()
        self.bytes_out = 0
        self.bytes_garbled_in = 0
        self._baud_seen: int | None = None  # the client's rate at the previous loop step (≤ 20 ms ago)
        self.reopen_count = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._mono0 = 0
        self.error: Exception | None = None
        self.lock = threading.Lock()

    @property
    def path(self) -> str:
        """The current slave path (changes after a port-loss fault; use `link` for a stable name)."""
        return self.port.slave_path

    def sim_time(self) -> GpsTime:
        """The simulated GPS time now."""
        return self.t_start.add_ns(round((self.clock.monotonic_ns() - self._mono0) * self.speed))

    def start(self) -> str:
        """Create the pty and start the receiver; returns the slave path."""
        path = self.port.open(self.core.baud_rate)
        self._mono0 = self.clock.monotonic_ns()
        self.core.advance(self.t_start)
        self._thread = threading.Thread(target=self._run, name="hil-receiver", daemon=True)
        self._thread.start()
        log.info("%s emulator on %s (speed %.1f×)", self.core.model.name, path, self.speed)
        return path

    def stop(self) -> None:
        """Stop the thread and close the pty (and remove the link)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self.port.close()

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _mismatch(self) -> bool:
        return self.port.client_baud() not in (None, self.core.baud_rate)

    def _send(self, frames: list[bytes]) -> None:
        if not frames or not self.port.is_open:
            return
        data = b"".join(frames)
        if self._mismatch():
            data = garble(data)
        data = self.core.faults.corrupt(data)
        self.bytes_out += self.port.write(data)

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                self._step()
        except Exception as exc:  # the thread must record why it died; the owner reads `error`
            log.exception("receiver emulator stopped on an error")
            self.error = exc

    def _step(self) -> None:
        t = self.sim_time()
        elapsed_s = t.diff_s(self.t_start)
        with self.lock:
            if self.core.faults.unplugged(elapsed_s):
                if self.port.is_open:
                    log.info("fault: port disappears at %.1f s", elapsed_s)
                    self.port.close()
                    self.framer = StreamFramer()
                self.core.advance(t)  # the receiver runs on; its output is lost
                self._stop.wait(0.01)
                return
            if not self.port.is_open:
                self.port.open(self.core.baud_rate)
                self.reopen_count += 1
                log.info("fault: port back as %s at %.1f s", self.port.slave_path, elapsed_s)
            baud_now = self.port.client_baud()
            rates = {baud_now, self._baud_seen}
            self._baud_seen = baud_now
            data = self.port.read()
            if data:
                # bytes written just before the client switched its rate were sent at the previous rate
                if self.core.baud_rate not in rates and None not in rates:
                    self.bytes_garbled_in += len(data)  # wrong line rate: the UART sees only framing errors
                else:
                    for frame in self.framer.feed(data):
                        self._send(self.core.handle_frame(frame))
            self._send(self.core.advance(self.sim_time()))
            nxt = self.core.next_epoch
        wait_s = 0.02
        if nxt is not None:
            wait_s = min(wait_s, max(0.0, nxt.diff_s(self.sim_time()) / self.speed))
        if self.port.is_open:
            select.select([self.port.master_fd], [], [], wait_s)
        else:
            self._stop.wait(wait_s)


