"""The autopilot link's byte edge: a serial port (TELEM2, a pty) or a UDP socket (a mavlink-router endpoint) as a
`ByteStream`, named by one settings string:

    serial:/dev/ttyAMA0[@921600]   the autopilot's telemetry port (pyserial puts a tty, also a pty, in raw mode)
    udpin:HOST:PORT                listen there; answer the last sender (mavlink-router `-e HOST:PORT` sends to us)
    udpout:HOST:PORT               send there from an ephemeral port; read what comes back

Every OS failure becomes `LinkLost`. A `udpin` link has nowhere to send before it heard a datagram: `write`
then returns 0 (the autopilot learns our route from our heartbeat once it has spoken).
"""

from __future__ import annotations

import logging
import socket
from collections.abc import Callable
from dataclasses import dataclass

from onboard.errors import LinkLost
from onboard.hw.ports import ByteStream

log = logging.getLogger(__name__)

DEFAULT_SERIAL_BAUD = 921600
MAX_DATAGRAM_BYTES = 65535


@dataclass(frozen=True)
class LinkSpec:
    """A parsed link string: `kind` "serial", "udpin" or "udpout"; `device`+`baud` or `host`+`port`."""

    kind: str
    device: str = ""
    baud: int = DEFAULT_SERIAL_BAUD
    host: str = ""
    port: int = 0


def parse_link_spec(spec: str) -> LinkSpec:
    """`serial:DEV[@BAUD]`, `udpin:HOST:PORT` or `udpout:HOST:PORT` → LinkSpec; ValueError naming the rule."""
    kind, sep, rest = spec.partition(":")
    if sep and kind == "serial" and rest:
        device, _, baud = rest.partition("@")
        if not device:
            raise ValueError(f"{spec!r}: the serial device is missing (serial:/dev/ttyAMA0@921600)")
        try:
            rate = int(baud) if baud else DEFAULT_SERIAL_BAUD
        except ValueError:
            raise ValueError(f"{spec!r}: the line rate {baud!r} must be a whole number of bit/s") from None
        if not 1200 <= rate <= 4_000_000:
            raise ValueError(f"{spec!r}: the line rate {rate} must be 1200–4000000 bit/s")
        return LinkSpec("serial", device=device, baud=rate)
    if sep and kind in ("udpin", "udpout"):
        host, _, port = rest.rpartition(":")
        if not host or not port.isdigit() or not 1 <= int(port) <= 65535:
            raise ValueError(f"{spec!r}: expected {kind}:HOST:PORT with a port 1–65535")
        return LinkSpec(kind, host=host, port=int(port))
    raise ValueError(f"{spec!r}: expected serial:DEVICE[@BAUD], udpin:HOST:PORT or udpout:HOST:PORT")


class UdpByteStream:
    """A UDP socket as a ByteStream: `udpin` binds (host, port) and sends to the last sender; `udpout` sends to
    (host, port). `read` returns one datagram (b"" after `read_timeout_s`)."""

    def __init__(self, spec: LinkSpec, read_timeout_s: float = 0.1) -> None:
        self.spec = spec
        self._peer: tuple[str, int] | None = None
        try:
            self._sock: socket.socket | None = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            if spec.kind == "udpin":
                self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                self._sock.bind((spec.host, spec.port))
            else:
                self._peer = (socket.gethostbyname(spec.host), spec.port)
            self._sock.settimeout(read_timeout_s)
        except OSError as exc:
            raise LinkLost(f"{spec.kind}:{spec.host}:{spec.port}: {exc}") from exc

    def read(self, max_bytes: int) -> bytes:
        """One datagram (truncated to `max_bytes`), b"" on timeout; LinkLost if the socket failed."""
        sock = self._require()
        try:
            data, peer = sock.recvfrom(MAX_DATAGRAM_BYTES)
        except TimeoutError:
            return b""
        except ConnectionRefusedError:
            return b""  # an ICMP port-unreachable for our last send: the autopilot side is not up yet
        except OSError as exc:
            raise LinkLost(f"{self.spec.kind}:{self.spec.host}:{self.spec.port}: {exc}") from exc
        if self.spec.kind == "udpin":
            self._peer = peer
        return data[:max_bytes]

    def write(self, data: bytes) -> int:
        """Send one datagram to the peer; 0 while a `udpin` link has heard nobody yet."""
        sock = self._require()
        if self._peer is None:
            return 0
        try:
            return sock.sendto(data, self._peer)
        except ConnectionRefusedError:
            return 0
        except OSError as exc:
            raise LinkLost(f"{self.spec.kind}:{self.spec.host}:{self.spec.port}: {exc}") from exc

    def close(self) -> None:
        """Close the socket (idempotent)."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def _require(self) -> socket.socket:
        if self._sock is None:
            raise LinkLost(f"{self.spec.kind}:{self.spec.host}:{self.spec.port} is closed")
        return self._sock


def open_mavlink_link(spec: str, read_timeout_s: float = 0.1) -> Callable[[], ByteStream]:
    """A factory for the autopilot link named by `spec` (see module doc); ValueError if malformed."""
    link = parse_link_spec(spec)
    if link.kind == "serial":

        def open_serial() -> ByteStream:
            from onboard.hw.serial_port import SerialByteStream

            return SerialByteStream(link.device, link.baud, read_timeout_s)

        return open_serial
    return lambda: UdpByteStream(link, read_timeout_s)
