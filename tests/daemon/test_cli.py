"""`python -m onboard` as a process: help, bad configuration (exit 2), disk below the floor (exit 3)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from onboard.__main__ import build_parser

PROJECT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.timeout(60)


def onboard(*args: str, cwd: Path = PROJECT) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, PYTHONPATH=str(PROJECT))
    env.pop("NOTIFY_SOCKET", None)
    return subprocess.run([sys.executable, "-m", "onboard", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=60, check=False)


def test_help_lists_commands() -> None:
    out = onboard("--help")
    assert out.returncode == 0 and all(c in out.stdout for c in ("run", "convert", "check", "rtk"))
    out = onboard("run", "--help")
    assert out.returncode == 0 and "--data-dir" in out.stdout and "--port" in out.stdout


def test_parser_registers_run_with_flags() -> None:
    args = build_parser().parse_args(["run", "--port", "/dev/ttyACM0", "--data-dir", "/d", "--no-configure"])
    assert args.port == "/dev/ttyACM0" and args.data_dir == Path("/d") and args.no_configure


def test_unknown_config_key_exits_2(tmp_path: Path) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[journal]\ndata_dri = '/x'\n")
    out = onboard("run", "--config", str(cfg))
    assert out.returncode == 2 and "unknown key 'journal.data_dri'" in out.stderr


def test_disk_below_floor_exits_3_without_recording(tmp_path: Path) -> None:
    cfg = tmp_path / "r.toml"
    cfg.write_text("[journal]\ndisk_floor_mb = 1e12\n")  # a petabyte: no disk here has that free
    out = onboard("run", "--config", str(cfg), "--port", str(tmp_path / "no-tty"), "--data-dir",
                  str(tmp_path / "data"), "--status", str(tmp_path / "status.json"))
    assert out.returncode == 3, out.stderr
    assert "disk" in out.stderr and "floor" in out.stderr
    assert list((tmp_path / "data").glob("flight-*")) == []
