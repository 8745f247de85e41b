"""pyserial ByteStream for the receiver port (a UART, USB CDC device or pseudo-terminal).

Every pyserial or OS failure becomes `LinkLost`, so the daemon has one thing to handle when the cable is
pulled or the USB device re-enumerates; `reopen(baud)` follows a CFG-PRT baud change.
"""

from __future__ import annotations

import logging
import os
import threading

import serial

from onboard.errors import LinkLost

log = logging.getLogger(__name__)


class _OpenFailures:
    """The last open error logged per device, so that a port retried every few seconds fills the console (and
    the journal) with one WARNING per distinct error, not one per attempt; a successful open forgets it.

    Process-wide on purpose: the recorder builds a new SerialByteStream for every attempt. It only decides what
    is logged, never what is done."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._last: dict[str, str] = {}

    def failed(self, device: str, message: str) -> bool:
        """Note a failure; True when it differs from the last one logged for `device` (log it)."""
        with self._lock:
            if self._last.get(device) == message:
                return False
            self._last[device] = message
            return True

    def opened(self, device: str) -> None:
        with self._lock:
            self._last.pop(device, None)


_open_failures = _OpenFailures()


class SerialByteStream:
    """A ByteStream on a serial device.

    Parameters
    ----------
    device : path of the device (`/dev/ttyAMA0`, `/dev/ttyACM0`, a pty slave path).
    baud : line rate in bit/s (ignored by ptys and USB CDC).
    read_timeout_s : how long `read` waits for the first byte before returning b"".
    """

    def __init__(self, device: str, baud: int = 115200, read_timeout_s: float = 0.1) -> None:
        self.device = device
        self.baud = baud
        self.read_timeout_s = read_timeout_s
        self._port: serial.Serial | None = None
        self._open()

    def _open(self) -> None:
        try:
            self._port = serial.Serial(
                self.device, self.baud, timeout=self.read_timeout_s, write_timeout=1.0, exclusive=True
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            self._port = None
            message = f"cannot open {self.device} at {self.baud} Bd: {exc}"
            if _open_failures.failed(self.device, message):
                log.warning("%s (retrying; the same error is not logged again)", message)
            raise LinkLost(message) from exc
        _open_failures.opened(self.device)
        log.info("opened %s at %d Bd", self.device, self.baud)

    def read(self, max_bytes: int) -> bytes:
        """What is waiting (at least one byte, up to `max_bytes`), b"" after the timeout; LinkLost if gone."""
        port = self._require()
        try:
            # read(1) blocks up to the timeout for the first byte; then take whatever else is buffered.
            first = port.read(1)
            if not first:
                if not os.path.exists(self.device):
                    raise LinkLost(f"{self.device} disappeared")
                return b""
            waiting = min(port.in_waiting, max_bytes - 1)
            return first + (port.read(waiting) if waiting > 0 else b"")
        except (serial.SerialException, OSError) as exc:
            self._drop()
            raise LinkLost(f"{self.device}: {exc}") from exc

    def write(self, data: bytes) -> int:
        """Write all of `data`; LinkLost if the device is gone or the write times out."""
        port = self._require()
        try:
            n = port.write(data)
            port.flush()
            return int(n or 0)
        except (serial.SerialException, serial.SerialTimeoutException, OSError) as exc:
            self._drop()
            raise LinkLost(f"{self.device}: {exc}") from exc

    def reopen(self, baud: int) -> None:
        """Close and open again at `baud` (after a CFG-PRT baud change)."""
        self._drop()
        self.baud = baud
        self._open()

    def close(self) -> None:
        """Close the port (idempotent)."""
        self._drop()

    def _require(self) -> serial.Serial:
        if self._port is None:
            raise LinkLost(f"{self.device} is not open")
        return self._port

    def _drop(self) -> None:
        if self._port is not None:
            try:
                self._port.close()
            except (serial.SerialException, OSError) as exc:
                log.debug("closing %s: %s", self.device, exc)
            self._port = None
