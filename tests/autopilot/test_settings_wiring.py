"""`[autopilot]` settings, the link strings, the composition root's wiring, and the cores' purity."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from onboard.errors import ConfigFileError
from onboard.hw.mavlink_link import LinkSpec, UdpByteStream, parse_link_spec
from onboard.recorder.daemon import RecorderDeps
from onboard.recorder.settings import load_settings

PROJECT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(("spec", "parsed"), [
    ("serial:/dev/ttyAMA0", LinkSpec("serial", device="/dev/ttyAMA0", baud=921600)),
    ("serial:/dev/ttyS0@57600", LinkSpec("serial", device="/dev/ttyS0", baud=57600)),
    ("udpin:0.0.0.0:14540", LinkSpec("udpin", host="0.0.0.0", port=14540)),
    ("udpout:127.0.0.1:14550", LinkSpec("udpout", host="127.0.0.1", port=14550)),
])
def test_link_specs(spec: str, parsed: LinkSpec) -> None:
    assert parse_link_spec(spec) == parsed


@pytest.mark.parametrize(("text", "match"), [
    ('[autopilot]\nlink = "tcp:1.2.3.4:5760"\n', r"autopilot.link 'tcp:1.2.3.4:5760': expected serial:DEVICE"),
    ('[autopilot]\nlink = "udpin:0.0.0.0:99999"\n', r"autopilot.link 'udpin:0.0.0.0:99999': expected udpin:HOST:PORT"),
    ('[autopilot]\nlink = "serial:/dev/ttyS0@fast"\n', r"line rate 'fast' must be a whole number"),
    ('[autopilot]\nsystem_id = 256\n', r"autopilot.system_id 256: must be"),
    ('[autopilot]\nlink_timeout_s = 0\n', r"autopilot.link_timeout_s 0: must be"),
    ('[rtk]\nbase_stream = "mavlink"\n', r'rtk.base_stream = "mavlink" needs autopilot.link'),
    ('[autopilot]\nlnk = ""\n', r"unknown key 'autopilot.lnk'"),
])
def test_bad_autopilot_settings_name_the_key(tmp_path: Path, text: str, match: str) -> None:
    cfg = tmp_path / "r.toml"
    cfg.write_text(text)
    with pytest.raises(ConfigFileError, match=match):
        load_settings(cfg, environ={})


def test_composition_root_adds_the_link_and_mavlink_corrections(tmp_path: Path) -> None:
    from onboard.autopilot.feature import AutopilotFeature
    from onboard.realtime.service import RtkFeature
    from onboard.recorder.app import recorder_for

    deps = RecorderDeps(open_port=lambda: None)  # type: ignore[arg-type,return-value]
    env = {"ONBOARD_JOURNAL_DATA_DIR": str(tmp_path), "ONBOARD_AUTOPILOT_LINK": "udpin:127.0.0.1:14540"}
    only_link = load_settings(None, environ=env)
    (feature,) = recorder_for(only_link, deps, only_link.rtk_base_stream or None).features
    assert isinstance(feature, AutopilotFeature) and feature.corrections is None
    both = load_settings(None, environ={**env, "ONBOARD_RTK_BASE_STREAM": "mavlink"})
    autopilot, rtk = recorder_for(both, deps, both.rtk_base_stream).features
    assert isinstance(autopilot, AutopilotFeature) and isinstance(rtk, RtkFeature)
    assert autopilot.corrections is not None
    # the RTK service reads what the link thread puts in the pipe
    assert rtk.rtk._open_radio is not None
    stream = rtk.rtk._open_radio()
    autopilot.corrections.put(b"\xd3\x00\x00abc")
    assert stream.read(4096) == b"\xd3\x00\x00abc" and stream.write(b"x") == 0


def test_udpin_answers_the_last_sender() -> None:
    import socket

    link = UdpByteStream(LinkSpec("udpin", host="127.0.0.1", port=0))
    assert link.write(b"nobody yet") == 0
    port = link._require().getsockname()[1]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as peer:
        peer.settimeout(2)
        peer.sendto(b"hello", ("127.0.0.1", port))
        assert link.read(4096) == b"hello"
        assert link.write(b"back") == 4
        assert peer.recv(100) == b"back"
    link.close()


def test_cores_import_no_io_and_the_recorder_no_pymavlink() -> None:
    """The pure cores pull in no serial, socket or pymavlink; importing the recorder's composition root does
    not import pymavlink either (the link imports it in its own thread)."""
    code = (
        "import sys\n"
        "import onboard.autopilot.rtcm_reassembly, onboard.autopilot.lifecycle\n"
        "bad = [m for m in ('serial', 'socket', 'pymavlink') if m in sys.modules]\n"
        "import onboard.recorder.app, onboard.autopilot.feature\n"
        "print(bad, 'pymavlink' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=PROJECT,
                         env={"PYTHONPATH": str(PROJECT)}, timeout=60)
    assert out.stdout.split() == ["[]", "False"]
