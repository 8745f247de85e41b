"""The new keys: autopilot.settle_s and [upload], checked at load with messages naming the key."""

from __future__ import annotations

from pathlib import Path

import pytest

from onboard.errors import ConfigFileError
from onboard.recorder.settings import default_config_path, load_settings


def load(tmp_path: Path, text: str) -> object:
    cfg = tmp_path / "c.toml"
    cfg.write_text(text)
    return load_settings(cfg, environ={})


def test_documented_defaults() -> None:
    s = load_settings(default_config_path(), environ={})
    assert s.autopilot_settle_s == 20.0 and s.upload_url == "" and s.upload_delete_after_upload is False
    text = default_config_path().read_text()
    for key in ("settle_s = 20.0", 'url = ""', 'token_file = ""', "delete_after_upload = false", "chunk_mib = 4.0",
                "backoff_min_s = 5.0", "backoff_max_s = 300.0", "poll_s = 5.0"):
        assert key in text, key
    # issue 15's keys, each with its comment: the autopilot connection, "mavlink" beside the other base
    # sources, the pre-flight page's no-go age of the corrections
    autopilot = text.split("[autopilot]")[1].split("\n[")[0]
    assert 'link = ""' in autopilot and '"serial:/dev/ttyAMA0@921600"' in autopilot and "udpin:" in autopilot
    rtk = text.split("[rtk]")[1].split("\n[")[0]
    assert all(src in rtk for src in ('"serial:', '"tcp://', '"ntrip://', '"mavlink"', 'base_stream = ""'))
    assert "preflight_base_timeout_s = 10.0" in rtk and s.rtk_preflight_base_timeout_s == 10.0


@pytest.mark.parametrize(("text", "message"), [
    ("[autopilot]\nsettle_s = 0\n", "autopilot.settle_s 0: must be > 0 and ≤ 3600 s"),
    ("[autopilot]\nsettle_s = \"20\"\n", "autopilot.settle_s '20': must be a number"),
    ('[upload]\nurl = "ground:8600"\ntoken_file = "/t"\n', "upload.url ground:8600: must be an http:// or https://"),
    ('[upload]\nurl = "http://ground:8600"\n', "upload.url needs upload.token_file"),
    ("[upload]\nbackoff_min_s = 10.0\nbackoff_max_s = 5.0\n", "upload.backoff_max_s 5: must be ≥ upload.backoff_min_s"),
    ("[upload]\nchunk_mib = 0.001\n", "upload.chunk_mib 0.001: must be"),
    ("[upload]\ndelete_after_upload = 1\n", "upload.delete_after_upload 1: must be true or false"),
    ("[upload]\nurll = \"x\"\n", "unknown key 'upload.urll'"),
])
def test_bad_values_are_refused_naming_the_key(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ConfigFileError, match=None) as info:
        load(tmp_path, text)
    assert message in str(info.value)


def test_environment(tmp_path: Path) -> None:
    s = load_settings(None, environ={"ONBOARD_UPLOAD_URL": "https://ground.example:8600",
                                     "ONBOARD_UPLOAD_TOKEN_FILE": "/etc/directgeo/token",
                                     "ONBOARD_AUTOPILOT_SETTLE_S": "5"})
    assert s.upload_url == "https://ground.example:8600" and s.autopilot_settle_s == 5.0
