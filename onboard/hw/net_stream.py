"""Base-correction streams over the network: a raw TCP ByteStream and an NTRIP (v1/v2 over HTTP/1.x) client.

Both are read-mostly `ByteStream`s for the real-time RTK service: `read` returns what arrived (b"" after the
timeout), raises `LinkLost` when the server closes or the connection fails; opening refuses a caster answer
other than 200 with a `LinkLost` naming the status line (wrong mountpoint, bad credentials).
`open_base_stream(spec)` turns a settings string into a factory:

    serial:/dev/ttyUSB0[@57600]   tcp://HOST:PORT   ntrip://[USER:PASSWORD@]HOST[:PORT]/MOUNTPOINT
"""

from __future__ import annotations

import base64
import logging
import socket
from collections.abc import Callable
from urllib.parse import unquote, urlsplit

from onboard.errors import LinkLost
from onboard.hw.ports import ByteStream

log = logging.getLogger(__name__)

NTRIP_DEFAULT_PORT = 2101
MAX_HEADER_BYTES = 8192


class TcpByteStream:
    """A TCP client connection as a ByteStream (`read_timeout_s` per read)."""

    def __init__(self, host: str, port: int, read_timeout_s: float = 0.1, connect_timeout_s: float = 5.0) -> None:
        self.host, self.port = host, port
        try:
            self._sock: socket.socket | None = socket.create_connection((host, port), timeout=connect_timeout_s)
        except OSError as exc:
            raise LinkLost(f"cannot connect to {host}:{port}: {exc}") from exc
        self._sock.settimeout(read_timeout_s)
        self._pending = b""

    def read(self, max_bytes: int) -> bytes:
        """Up to `max_bytes`; b"" on timeout; LinkLost when the peer closed or the connection broke."""
        if self._pending:
            out, self._pending = self._pending[:max_bytes], self._pending[max_bytes:]
            return out
        sock = self._require()
        try:
            data = sock.recv(max_bytes)
        except TimeoutError:
            return b""
        except OSError as exc:
            self.close()
            raise LinkLost(f"{self.host}:{self.port}: {exc}") from exc
        if not data:
            self.close()
            raise LinkLost(f"{self.host}:{self.port} closed the connection")
        return data

    def write(self, data: bytes) -> int:
        """Send all of `data` (NMEA GGA to a caster, for instance); LinkLost on failure."""
        sock = self._require()
        try:
            sock.sendall(data)
        except OSError as exc:
            self.close()
            raise LinkLost(f"{self.host}:{self.port}: {exc}") from exc
        return len(data)

    def close(self) -> None:
        """Close the connection (idempotent)."""
        if self._sock is not None:
            try:
                self._sock.close()
            except OSError as exc:
                log.debug("closing %s:%s: %s", self.host, self.port, exc)
            self._sock = None

    def _require(self) -> socket.socket:
        if self._sock is None:
            raise LinkLost(f"{self.host}:{self.port} is not connected")
        return self._sock


class NtripByteStream(TcpByteStream):
    """NTRIP client: requests `mountpoint` from a caster and streams the corrections that follow the header."""

    def __init__(self, host: str, port: int, mountpoint: str, user: str | None = None,
                 password: str | None = None, read_timeout_s: float = 0.1, header_timeout_s: float = 5.0) -> None:
        super().__init__(host, port, read_timeout_s)
        lines = [f"GET /{mountpoint} HTTP/1.1", f"Host: {host}:{port}", "Ntrip-Version: Ntrip/2.0",
                 "User-Agent: NTRIP directgeo/1.0", "Connection: close"]
        if user is not None:
            token = base64.b64encode(f"{user}:{password or ''}".encode()).decode()
            lines.append(f"Authorization: Basic {token}")
        self.write(("\r\n".join(lines) + "\r\n\r\n").encode())
        sock = self._require()
        sock.settimeout(header_timeout_s)
        head = b""
        try:
            while b"\r\n\r\n" not in head and len(head) < MAX_HEADER_BYTES:
                chunk = sock.recv(1024)
                if not chunk:
                    break
                head += chunk
        except OSError as exc:
            self.close()
            raise LinkLost(f"NTRIP {host}:{port}/{mountpoint}: no answer ({exc})") from exc
        status = head.split(b"\r\n", 1)[0].decode("latin-1").strip()
        if not (status.startswith(("ICY 200", "HTTP/1.1 200", "HTTP/1.0 200"))) or b"\r\n\r\n" not in head:
            self.close()
            raise LinkLost(f"NTRIP {host}:{port}/{mountpoint} refused: {status or 'no status line'}")
        sock.settimeout(read_timeout_s)
        self._pending = head.split(b"\r\n\r\n", 1)[1]  # corrections that came with the header
        log.info("NTRIP %s:%d/%s: %s", host, port, mountpoint, status)


def open_base_stream(spec: str, read_timeout_s: float = 0.1) -> Callable[[], ByteStream]:
    """A factory for the base-correction stream named by `spec` (see module doc); ValueError if malformed.
    ("mavlink", the autopilot's GPS_RTCM_DATA, is no stream of its own: `onboard.recorder.app.recorder_for`
    connects the autopilot link's reassembled RTCM to the RTK service.)"""
    if spec == "mavlink":
        raise ValueError("base stream 'mavlink' comes from the autopilot link (set autopilot.link); the "
                         "recorder's composition root connects it")
    if spec.startswith("serial:"):
        device, _, baud = spec[len("serial:"):].partition("@")
        rate = int(baud) if baud else 57600

        def open_serial() -> ByteStream:
            from onboard.hw.serial_port import SerialByteStream

            return SerialByteStream(device, rate, read_timeout_s)

        return open_serial
    url = urlsplit(spec)
    if url.scheme == "tcp" and url.hostname and url.port:
        host, port = url.hostname, url.port
        return lambda: TcpByteStream(host, port, read_timeout_s)
    if url.scheme == "ntrip" and url.hostname and url.path.strip("/"):
        h, p, mount = url.hostname, url.port or NTRIP_DEFAULT_PORT, url.path.strip("/")
        user = unquote(url.username) if url.username else None
        password = unquote(url.password) if url.password else None
        return lambda: NtripByteStream(h, p, mount, user, password, read_timeout_s)
    raise ValueError(f"base stream {spec!r}: expected serial:DEVICE[@BAUD], tcp://HOST:PORT or "
                     "ntrip://[USER:PASSWORD@]HOST[:PORT]/MOUNTPOINT")
