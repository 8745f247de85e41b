"""Fixtures for the receiver-emulator tests: a pty client speaking UBX, and the World the emulator runs on.

`make_world` builds A1's `hil_sim.world.World` when it is importable; otherwise a deliberately small
stand-in (geometric ranges from the real broadcast orbits, no error model) so the protocol tests can run.
Both use the real broadcast file shipped with the simulator (hil_sim/data/broadcast-nav-20100701/brdc1820.10n).
"""

from __future__ import annotations

import os
import select
import termios
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from hil_sim.scenario import DEFAULT_NAV_PATH

# The shipped broadcast file, absolute: other folders' tests call shared_file(NAV), which then finds it (a path
# joined to an absolute one is that one) and runs on a clone without ../shared.
NAV = str(DEFAULT_NAV_PATH)
from onboard.formats.rinex_nav import read_rinex_nav
from onboard.gnsstime import GpsTime
from onboard.receiver.framing import Frame, Protocol, StreamFramer, ubx_frame
from onboard.rtk.consts import LAMBDA_L1_M
from onboard.rtk.ephemeris import eph_position, geometric_range
from onboard.rtk.geodesy import azimuth_elevation, llh_to_ecef
from onboard.rtk.types import Ephemeris, ObsEpoch

T0 = GpsTime(1590, 4 * 86400 * 10**9 + 2 * 3600 * 10**9)  # 2010-07-01 02:00 GPST


@dataclass
class CameraEvent:
    """Stand-in camera event (pulse and flash GPS times) with the attribute names the emulator reads."""

    pulse_time: GpsTime
    flash_time: GpsTime | None
    bounce_time: GpsTime | None = None


@dataclass
class StandInWorld:
    """Minimal World for protocol tests: static rover, geometric ranges only, scripted camera events."""

    ephs: list[Ephemeris]
    start: GpsTime = T0
    site_ecef_m: np.ndarray = field(default_factory=lambda: llh_to_ecef(np.radians(35.0), np.radians(139.0), 50.0))
    events: list[CameraEvent] = field(default_factory=list)
    rx_clock_offset_ns: int = -1_000_000  # tags at …999 ms like a u-blox 6

    @property
    def scenario(self) -> Any:
        return type("S", (), {"start": self.start})()

    def _eph(self, prn: int, t: GpsTime) -> Ephemeris:
        cands = [e for e in self.ephs if e.prn == prn]
        return min(cands, key=lambda e: abs(e.toe.diff_s(t)))

    def observe(self, receiver: str, t_rx_nominal: GpsTime) -> ObsEpoch:
        prns, prs = [], []
        for prn in sorted({e.prn for e in self.ephs}):
            pos, _ = eph_position(self._eph(prn, t_rx_nominal), t_rx_nominal)
            _, el = azimuth_elevation(self.site_ecef_m, pos)
            if float(np.ravel(el)[0]) > np.radians(10.0):
                r, _ = geometric_range(pos[None, :], self.site_ecef_m)
                prns.append(prn)
                prs.append(float(r[0]))
        n = len(prns)
        pr = np.array(prs)
        return ObsEpoch(time=t_rx_nominal.add_ns(self.rx_clock_offset_ns), gnss_id=np.zeros(n, np.int8),
                        sv_id=np.array(prns, np.int16), pr_m=pr, cp_cyc=pr / LAMBDA_L1_M, dop_hz=np.zeros(n),
                        cn0_dbhz=np.full(n, 45.0), lock_ms=np.full(n, 30000.0), lli=np.zeros(n, np.uint8),
                        half_cyc_sub=np.zeros(n, np.uint8), pr_std_m=np.full(n, 0.32),
                        cp_std_cyc=np.full(n, 0.004))

    def add_event(self, pulse_time: GpsTime, flash_time: GpsTime | None, bounce_time: GpsTime | None = None) -> None:
        self.events.append(CameraEvent(pulse_time, flash_time, bounce_time))

    def ephemerides(self) -> list[Ephemeris]:
        return self.ephs

    def camera_events(self, t0: GpsTime, t1: GpsTime) -> list[CameraEvent]:
        return [e for e in self.events if t0 < e.pulse_time <= t1]

    def truth(self, t: GpsTime) -> dict[str, Any]:
        return {"rover_ecef_m": self.site_ecef_m, "rover_vel_ecef_m_s": np.zeros(3)}


@pytest.fixture(scope="session")
def broadcast_ephemerides() -> list[Ephemeris]:
    return read_rinex_nav(DEFAULT_NAV_PATH).ephemerides


@pytest.fixture
def standin_world(broadcast_ephemerides: list[Ephemeris]) -> StandInWorld:
    return StandInWorld(broadcast_ephemerides)


_BAUD = {9600: termios.B9600, 38400: termios.B38400, 57600: termios.B57600, 115200: termios.B115200,
         230400: termios.B230400}


class PtyClient:
    """A raw pty client like the daemon's: sets its line rate, writes frames, collects UBX/NMEA frames."""

    def __init__(self, path: str, baud: int = 9600) -> None:
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        self.set_baud(baud)
        termios.tcflush(self.fd, termios.TCIFLUSH)
        self.framer = StreamFramer()
        self.frames: list[Frame] = []
        self.raw = bytearray()

    def set_baud(self, baud: int) -> None:
        attrs = termios.tcgetattr(self.fd)
        attrs[0] = attrs[1] = attrs[3] = 0  # raw: no echo, no translation
        attrs[2] = termios.CS8 | termios.CREAD | termios.CLOCAL
        attrs[4] = attrs[5] = _BAUD[baud]
        termios.tcsetattr(self.fd, termios.TCSANOW, attrs)

    def send(self, msg_class: int, msg_id: int, payload: bytes = b"") -> None:
        os.write(self.fd, ubx_frame(msg_class, msg_id, payload))

    def pump(self, timeout_s: float) -> None:
        """Read whatever arrives within `timeout_s`."""
        end = time.monotonic() + timeout_s
        while (left := end - time.monotonic()) > 0:
            r, _, _ = select.select([self.fd], [], [], left)
            if r:
                try:
                    data = os.read(self.fd, 65536)
                except BlockingIOError:
                    continue
                self.raw += data
                self.frames += self.framer.feed(data)

    def wait_for(self, pred: Callable[[Frame], bool], timeout_s: float = 2.0, start: int | None = None) -> Frame | None:
        """The first collected frame (from index `start`) matching `pred`, reading up to `timeout_s`."""
        i = len(self.frames) if start is None else start
        end = time.monotonic() + timeout_s
        while True:
            for f in self.frames[i:]:
                if pred(f):
                    return f
            i = len(self.frames)
            left = end - time.monotonic()
            if left <= 0:
                return None
            self.pump(min(0.05, left))

    def request(self, msg_class: int, msg_id: int, payload: bytes = b"", timeout_s: float = 1.0,
                reply: tuple[int, int] | None = None) -> tuple[Frame | None, Frame | None]:
        """Send a message; return (reply frame of class/id `reply` or None, ACK/NAK frame or None)."""
        start = len(self.frames)
        self.send(msg_class, msg_id, payload)
        got_reply = None
        if reply is not None:
            got_reply = self.wait_for(lambda f: f.protocol is Protocol.UBX and (f.msg_class, f.msg_id) == reply,
                                      timeout_s, start)
        ack = self.wait_for(lambda f: f.protocol is Protocol.UBX and f.msg_class == 0x05
                            and f.payload[:2] == bytes((msg_class, msg_id)), timeout_s, start)
        return got_reply, ack

    def ubx(self, msg_class: int, msg_id: int) -> list[Frame]:
        return [f for f in self.frames if f.protocol is Protocol.UBX and (f.msg_class, f.msg_id) == (msg_class, msg_id)]

    def close(self) -> None:
        os.close(self.fd)


@pytest.fixture
def pty_client_factory() -> Iterator[Callable[..., PtyClient]]:
    clients: list[PtyClient] = []

    def make(path: str, baud: int = 9600) -> PtyClient:
        c = PtyClient(path, baud)
        clients.append(c)
        return c

    yield make
    for c in clients:
        try:
            c.close()
        except OSError:
            pass
