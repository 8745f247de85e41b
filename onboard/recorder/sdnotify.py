"""sd_notify spoken directly on `$NOTIFY_SOCKET` (no libsystemd), and the watchdog petting rule.

The watchdog is petted only when both the asyncio loop and the reader/writer thread went round recently:
an unplugged receiver leaves the writer idle but alive (it still pets), a wedged writer (stuck in a write or
fsync) does not, so systemd restarts a stuck recorder and never a merely disconnected one.
"""

from __future__ import annotations

import logging
import os
import socket
from collections.abc import Mapping

log = logging.getLogger(__name__)


class SdNotifier:
    """Datagram sender to the service manager; does nothing when `$NOTIFY_SOCKET` is unset.

    `@name` addresses the abstract namespace (sent as a leading NUL byte).
    """

    def __init__(self, environ: Mapping[str, str] | None = None) -> None:
        env = os.environ if environ is None else environ
        addr = env.get("NOTIFY_SOCKET", "")
        self.address: str | bytes | None = None
        if addr.startswith("@"):
            self.address = b"\0" + addr[1:].encode()
        elif addr.startswith("/"):
            self.address = addr
        elif addr:
            log.warning("NOTIFY_SOCKET=%r is neither a path nor an abstract name: not notifying", addr)
        self.watchdog_usec = _watchdog_usec(env)
        self._sock: socket.socket | None = None
        self.sent = 0
        self.errors = 0

    @property
    def enabled(self) -> bool:
        """True when a notify socket was given."""
        return self.address is not None

    def notify(self, **fields: str | int) -> bool:
        """Send `KEY=value` lines (e.g. `notify(READY=1, STATUS="recording")`); False if not sent."""
        if self.address is None:
            return False
        msg = "\n".join(f"{k}={v}" for k, v in fields.items()).encode()
        try:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.sendto(msg, self.address)
        except OSError as exc:
            self.errors += 1
            log.warning("sd_notify failed: %s", exc)
            return False
        self.sent += 1
        return True

    def close(self) -> None:
        """Close the socket."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None


def _watchdog_usec(env: Mapping[str, str]) -> int | None:
    """WATCHDOG_USEC when it is meant for this process (WATCHDOG_PID absent or ours), else None."""
    usec = env.get("WATCHDOG_USEC")
    pid = env.get("WATCHDOG_PID")
    if not usec:
        return None
    if pid and pid.isdigit() and int(pid) != os.getpid():
        return None
    try:
        value = int(usec)
    except ValueError:
        return None
    return value if value > 0 else None


class WatchdogGate:
    """Decides whether to pet the watchdog from two heartbeats (monotonic ns).

    `loop_beat` is called by an asyncio task, `writer_beat` by the reader/writer thread every time it goes
    round (a read that timed out on silence, or a reconnection attempt, counts: idle is alive).
    """

    def __init__(self, stale_ns: int) -> None:
        self.stale_ns = stale_ns
        self.loop_ns: int | None = None
        self.writer_ns: int | None = None

    def loop_beat(self, now_ns: int) -> None:
        """The event loop ran."""
        self.loop_ns = now_ns

    def writer_beat(self, now_ns: int) -> None:
        """The reader/writer went round."""
        self.writer_ns = now_ns

    def should_pet(self, now_ns: int) -> bool:
        """True only when both heartbeats are fresher than `stale_ns`."""
        return (
            self.loop_ns is not None
            and self.writer_ns is not None
            and now_ns - self.loop_ns <= self.stale_ns
            and now_ns - self.writer_ns <= self.stale_ns
        )
