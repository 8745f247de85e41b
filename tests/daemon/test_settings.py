"""Settings: documented defaults, layering file → env → CLI, unknown keys and bad values are errors."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from onboard.errors import ConfigFileError
from onboard.recorder.settings import (
    BOUNDS,
    KEYS,
    Settings,
    default_config_path,
    load_settings,
    load_toml,
    receiver_options,
)

UNITS = {"_ms": r"\bms\b", "_s": r"\bs\b", "_mb": r"\bMB\b", "_ns": r"\bns\b", "baud": r"bit/s"}
INTERNAL = r"issue \d|RTKLIB|onboard[./]|ReceiverOptions|RtkOptions|Daakir|hil_sim|MON-VER|CFG-|TIM-TM2|AID-EPH|seed"


def _key_comments(text: str) -> dict[str, str]:
    """`section.key` → the comment lines right above it (its own: a key line directly above ends the comment)."""
    out: dict[str, str] = {}
    section, comment = "", []
    for line in text.splitlines():
        if line.startswith("["):
            section, comment = line.strip("[]"), []
        elif line.startswith("#"):
            comment.append(line.lstrip("# "))
        elif "=" in line:
            out[f"{section}.{line.split('=')[0].strip()}"] = " ".join(comment)
            comment = []
        else:
            comment = []
    return out


def test_default_file_speaks_to_users() -> None:
    """No names of our code, papers or tickets in the comments: what each key does, in the user's words."""
    text = default_config_path().read_text()
    found = re.findall(INTERNAL, text)
    assert not found, found


def test_default_file_documents_every_key_with_the_real_default() -> None:
    """The packaged TOML holds every key, each preceded by a comment, with the dataclass's default value."""
    path = default_config_path()
    flat = load_toml(path)
    from onboard.receiver.profiles import ReceiverOptions

    option_keys = {f"receiver.{f.name}" for f in dataclasses.fields(ReceiverOptions)}
    assert set(flat) == set(KEYS) | option_keys
    defaults = Settings()
    for key, name in KEYS.items():
        got = flat[key]
        want = getattr(defaults, name)
        assert (str(want) if isinstance(want, Path) else want) == got, key
    for f in dataclasses.fields(ReceiverOptions):
        assert flat[f"receiver.{f.name}"] == f.default, f.name
    for key, comment in _key_comments(path.read_text()).items():
        assert comment, f"key without a comment of its own: {key}"
        unit = next((u for suffix, u in UNITS.items() if key.endswith(suffix)), None)
        if unit is not None:
            assert re.search(unit, comment), f"{key}: comment does not give the unit ({unit}): {comment}"
        bound = BOUNDS.get(key)
        if bound is not None and bound.maximum is not None:
            assert f"{bound.maximum:g}" in comment, f"{key}: comment does not give the range: {comment}"
    # and loading the default file changes nothing
    s = load_settings(path, environ={})
    assert s.port_device == defaults.port_device and s.data_dir == defaults.data_dir


def test_layering_file_env_cli(tmp_path: Path) -> None:
    cfg = tmp_path / "r.toml"
    cfg.write_text('[port]\ndevice = "/dev/ttyACM0"\nbaud = 38400\n[journal]\ndata_dir = "/data"\n'
                   '[receiver]\nmeas_rate_ms = 1000\n')
    env = {"ONBOARD_PORT_BAUD": "9600", "ONBOARD_RECEIVER_CAMERA_PERIOD_S": "2.0", "HOME": "/x"}
    s = load_settings(cfg, environ=env, overrides={"journal.data_dir": "/cli", "port.device": None})
    assert s.port_device == "/dev/ttyACM0"  # file (CLI left it unset)
    assert s.port_baud == 9600  # env beats file
    assert s.data_dir == Path("/cli")  # CLI beats file
    opts = receiver_options(s)
    assert opts.meas_rate_ms == 1000 and opts.camera_period_s == 2.0
    assert opts.baud == 9600  # follows port.baud unless set


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[port]\ndevise = 'x'\n", "unknown key 'port.devise'"),
        ("[nonsense]\na = 1\n", "unknown key 'nonsense.a'"),
        ("[port]\nbaud = 'fast'\n", "port.baud 'fast': must be a number"),
        ("[journal]\nsync_interval_s = 5.0\n", r"journal.sync_interval_s 5.0: must be > 0 and ≤ 1 s \(received"),
        ("[journal]\nsegment_max_mb = nan\n", "journal.segment_max_mb nan: must be a finite number"),
        ("[journal]\nsegment_max_mb = -1\n", "journal.segment_max_mb -1: must be 0–4000 MB"),
        ("[journal]\ndisk_floor_mb = inf\n", "journal.disk_floor_mb inf: must be a finite number"),
        ("[port]\nbaud = 1e400\n", "port.baud inf: must be a finite number"),
        ("[status]\ninterval_s = 10\n", "status.interval_s 10: must be > 0 and ≤ 2.5 s"),
        ("[gpio]\npps_pin = 40\n", "gpio.pps_pin 40: must be -1–27 \\(a BCM GPIO number"),
        ("[receiver]\nant_cable_delay_ns = 40000\n", "receiver.ant_cable_delay_ns 40000: must be -32768–32767 ns"),
        ("[rtk.engine]\nratio_threshold = nan\n", "rtk.engine.ratio_threshold nan: must be a finite number"),
        ("[rtk.engine]\nratio_threshold = 0.5\n", "rtk.engine.ratio_threshold 0.5: ratio_threshold must be ≥ 1"),
        ("[rtk.engine]\nfloat_fix_gate_scale = 0.5\n", "rtk.engine.float_fix_gate_scale 0.5: float_fix_gate_scale must be ≥ 1"),
        ("[rtk.engine]\nfloat_fix_gate_min_dd = -1\n", "rtk.engine.float_fix_gate_min_dd -1: float_fix_gate_min_dd must be ≥ 0"),
        ("[watchdog]\nwriter_stall_s = 0.05\n", "watchdog.writer_stall_s 0.05: must be > port.read_timeout_s"),
        ("[receiver]\nmodel = 'zed'\n", "receiver.model"),
        ("[receiver]\nmeas_rate_ms = 5\n", "receiver.meas_rate_ms 5: meas_rate_ms must be within 25–65535 ms"),
        ("[port]\nbaud = 1200\n", r"port.baud \(receiver.baud follows it unless set\) 1200: baud must be one of"),
        ("[receiver]\npulse_len_ms = 2500\ncamera_period_s = 2.0\n", "receiver: pulse_len_ms must be > 0 and shorter"),
        ("[port\n", "not valid TOML"),
        ("[rtk]\nbase_stream = '/dev/ttyUSB0'\n", "rtk.base_stream: expected serial:DEV"),
    ],
)
def test_bad_files_name_the_key(tmp_path: Path, text: str, match: str) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text(text)
    with pytest.raises(ConfigFileError, match=match):
        load_settings(cfg, environ={})


def test_unknown_env_variable_and_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigFileError, match="ONBOARD_PORT_DEV"):
        load_settings(None, environ={"ONBOARD_PORT_DEV": "/dev/x"})
    with pytest.raises(ConfigFileError, match="bool|true or false"):
        load_settings(None, environ={"ONBOARD_RECEIVER_CONFIGURE": "maybe"})
    with pytest.raises(ConfigFileError, match="cannot read"):
        load_settings(tmp_path / "absent.toml", environ={})
    # test hooks are not settings
    assert load_settings(None, environ={"ONBOARD_TEST_SYNC_LOG": "/tmp/x"}).port_baud == 115200


def test_gpio_trigger_needs_both_pins() -> None:
    with pytest.raises(ConfigFileError, match="gpio.trigger_pin and gpio.pps_pin"):
        load_settings(None, environ={"ONBOARD_RECEIVER_TRIGGER": "gpio", "ONBOARD_GPIO_TRIGGER_PIN": "23"})
    s = load_settings(None, environ={"ONBOARD_RECEIVER_TRIGGER": "gpio", "ONBOARD_GPIO_TRIGGER_PIN": "23",
                                     "ONBOARD_GPIO_PPS_PIN": "24"})
    assert s.gpio_trigger_pin == 23 and s.gpio_pps_pin == 24


def test_gpio_flash_pin_needs_pps_and_distinct_pins() -> None:
    with pytest.raises(ConfigFileError, match="gpio.flash_pin needs gpio.pps_pin"):
        load_settings(None, environ={"ONBOARD_GPIO_FLASH_PIN": "25"})
    with pytest.raises(ConfigFileError, match="must be different pins"):
        load_settings(None, environ={"ONBOARD_GPIO_FLASH_PIN": "24", "ONBOARD_GPIO_PPS_PIN": "24"})
    s = load_settings(None, environ={"ONBOARD_GPIO_FLASH_PIN": "25", "ONBOARD_GPIO_PPS_PIN": "24"})
    assert s.gpio_flash_pin == 25 and receiver_options(s).trigger == "extint1"


def test_rtk_base_stream_selects_the_real_time_rtk_recorder(tmp_path: Path) -> None:
    """`rtk.base_stream` (file or ONBOARD_RTK_BASE_STREAM) is what makes the composition root add the RTK service."""
    import socket

    from onboard.realtime.service import RtkFeature
    from onboard.recorder.app import recorder_for
    from onboard.recorder.daemon import RecorderDeps

    cfg = tmp_path / "r.toml"
    cfg.write_text("[rtk]\nbase_stream = 'serial:/dev/ttyUSB0@57600'\n")
    assert load_settings(cfg, environ={}).rtk_base_stream == "serial:/dev/ttyUSB0@57600"
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        stream = f"tcp://127.0.0.1:{server.getsockname()[1]}"
        s = load_settings(None, environ={"ONBOARD_RTK_BASE_STREAM": stream, "ONBOARD_JOURNAL_DATA_DIR": str(tmp_path)})
        deps = RecorderDeps(open_port=lambda: None)  # type: ignore[arg-type,return-value]
        assert [type(f) for f in recorder_for(s, deps, s.rtk_base_stream or None).features] == [RtkFeature]
    plain = load_settings(None, environ={"ONBOARD_JOURNAL_DATA_DIR": str(tmp_path)})
    assert recorder_for(plain, deps, plain.rtk_base_stream or None).features == ()
