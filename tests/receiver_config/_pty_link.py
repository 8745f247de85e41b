"""A minimal asyncio ConfigLink over a pty slave, for tests and benches against the hil_sim emulator."""

from __future__ import annotations

import asyncio
import os
import termios

from onboard.receiver.configure import FrameQueueLink
from onboard.receiver.framing import Frame, StreamFramer

_BAUD = {9600: termios.B9600, 38400: termios.B38400, 57600: termios.B57600, 115200: termios.B115200,
         230400: termios.B230400}


class PtyLink:
    """A minimal asyncio ConfigLink over a pty slave: add_reader → framer → FrameQueueLink; reopen = termios."""

    def __init__(self, path: str, baud: int) -> None:
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        self.framer = StreamFramer()
        self.raw = bytearray()  # every byte received, as the recorder would journal it
        self.frames: list[Frame] = []
        self.link = FrameQueueLink(self._write, self._reopen)
        self._set_baud(baud)
        termios.tcflush(self.fd, termios.TCIFLUSH)
        asyncio.get_running_loop().add_reader(self.fd, self._readable)

    def _set_baud(self, baud: int) -> None:
        attrs = termios.tcgetattr(self.fd)
        attrs[0] = attrs[1] = attrs[3] = 0
        attrs[2] = termios.CS8 | termios.CREAD | termios.CLOCAL
        attrs[4] = attrs[5] = _BAUD[baud]
        termios.tcsetattr(self.fd, termios.TCSADRAIN, attrs)

    def _readable(self) -> None:
        try:
            data = os.read(self.fd, 65536)
        except BlockingIOError:
            return
        self.raw += data
        for frame in self.framer.feed(data):
            self.frames.append(frame)
            self.link.feed(frame)

    async def _write(self, raw: bytes) -> None:
        os.write(self.fd, raw)
        termios.tcdrain(self.fd)

    async def _reopen(self, baud: int) -> None:
        # No sleep here: apply_profile's baud_settle_s lets the emulator read the CFG-PRT at the old rate.
        self._set_baud(baud)
        self.framer = StreamFramer()

    def close(self) -> None:
        asyncio.get_running_loop().remove_reader(self.fd)
        os.close(self.fd)
