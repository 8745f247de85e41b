"""TCP and NTRIP base-correction streams against real sockets on 127.0.0.1 (a minimal caster thread)."""

from __future__ import annotations

import base64
import socket
import threading

import pytest

from onboard.errors import LinkLost
from onboard.hw.net_stream import NtripByteStream, TcpByteStream, open_base_stream

pytestmark = pytest.mark.timeout(30)
RTCM = bytes.fromhex("d300133ed7d30202980edeef34b4bd62ac0941986f33") * 3  # any bytes: the stream is opaque


class Caster:
    """Accepts one client per `serve` call; answers NTRIP requests (or serves raw TCP) with RTCM bytes."""

    def __init__(self, mount: str = "BASE", auth: str | None = None, ntrip: bool = True) -> None:
        self.srv = socket.create_server(("127.0.0.1", 0))
        self.port = self.srv.getsockname()[1]
        self.mount, self.auth, self.ntrip = mount, auth, ntrip
        self.requests: list[bytes] = []
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        conn, _ = self.srv.accept()
        with conn:
            if self.ntrip:
                req = b""
                while b"\r\n\r\n" not in req:
                    req += conn.recv(1024)
                self.requests.append(req)
                ok = req.startswith(f"GET /{self.mount} ".encode())
                if self.auth is not None:
                    ok = ok and f"Authorization: Basic {base64.b64encode(self.auth.encode()).decode()}".encode() in req
                if not ok:
                    conn.sendall(b"HTTP/1.1 401 Unauthorized\r\n\r\n")
                    return
                conn.sendall(b"ICY 200 OK\r\n\r\n" + RTCM[:10])  # corrections right behind the header
                conn.sendall(RTCM[10:])
            else:
                conn.sendall(RTCM)

    def close(self) -> None:
        self.thread.join(5)
        self.srv.close()


def _read_until_closed(stream) -> bytes:  # type: ignore[no-untyped-def]
    got = b""
    with pytest.raises(LinkLost, match="closed"):
        for _ in range(200):
            got += stream.read(7)
    return got


def test_ntrip_client_streams_the_corrections_after_the_header_then_reports_the_close() -> None:
    caster = Caster(auth="pilot:s3cret")
    stream = open_base_stream(f"ntrip://pilot:s3cret@127.0.0.1:{caster.port}/BASE")()
    assert isinstance(stream, NtripByteStream)
    assert _read_until_closed(stream) == RTCM  # nothing lost, nothing of the header leaked
    caster.close()
    assert b"Ntrip-Version: Ntrip/2.0" in caster.requests[0]


def test_ntrip_refusal_names_the_status_line() -> None:
    caster = Caster(auth="pilot:s3cret")
    with pytest.raises(LinkLost, match="401 Unauthorized"):
        NtripByteStream("127.0.0.1", caster.port, "BASE", "pilot", "wrong")
    caster.close()


def test_tcp_stream_and_connection_refused() -> None:
    caster = Caster(ntrip=False)
    stream = open_base_stream(f"tcp://127.0.0.1:{caster.port}")()
    assert _read_until_closed(stream) == RTCM
    caster.close()
    port = caster.port  # closed now: nobody listens
    with pytest.raises(LinkLost, match="cannot connect"):
        TcpByteStream("127.0.0.1", port)


def test_malformed_specs_are_refused() -> None:
    for spec in ("ntrip://host", "tcp://host", "udp://h:1", "/dev/ttyUSB0"):
        with pytest.raises(ValueError, match="expected"):
            open_base_stream(spec)
    assert callable(open_base_stream("serial:/dev/ttyUSB0@115200"))


def test_recorder_for_adds_rtk_only_when_a_base_stream_is_named(tmp_path) -> None:
    from onboard.hw.fake import FakeByteStream
    from onboard.realtime.service import RtkFeature
    from onboard.recorder.app import recorder_for
    from onboard.recorder.daemon import Recorder, RecorderDeps
    from tests.daemon.helpers import make_settings

    settings, deps = make_settings(tmp_path), RecorderDeps(open_port=FakeByteStream)
    plain = recorder_for(settings, deps, None)
    assert type(plain) is Recorder and plain.features == ()
    with_rtk = recorder_for(settings, deps, "ntrip://u:p@127.0.0.1:2101/BASE")
    assert type(with_rtk) is Recorder and [type(f) for f in with_rtk.features] == [RtkFeature]
    with pytest.raises(ValueError, match="base stream"):
        recorder_for(settings, deps, "radio0")
