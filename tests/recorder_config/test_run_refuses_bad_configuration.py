"""`python -m onboard run` with a configuration it cannot record with: one error line naming the key or path,
exit 2 (systemd does not restart on it), no traceback, and nothing recorded."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PREFIX = "directgeo: run: error: "

pytestmark = pytest.mark.timeout(120)


def _run(args: list[str], tmp_path: Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    base = {k: v for k, v in os.environ.items() if not k.startswith("ONBOARD_")}
    return subprocess.run([sys.executable, "-m", "onboard", "run", "--port", str(tmp_path / "no-such-tty"),
                           "--no-configure", *args], cwd=ROOT, env={**base, **(env or {})}, capture_output=True,
                          text=True, timeout=60, check=False)


def _refused(out: subprocess.CompletedProcess[str], *words: str) -> str:
    """The one error line of a refused start (exit 2, our prefix, no traceback), checked to hold `words`."""
    assert out.returncode == 2, (out.returncode, out.stderr)
    assert "Traceback" not in out.stderr, out.stderr
    lines = [line for line in out.stderr.splitlines() if line.startswith(PREFIX)]
    assert len(lines) == 1, out.stderr
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


def _nothing_recorded(data: Path) -> None:
    assert not data.exists() or not any(p.name.startswith("flight-") for p in data.iterdir())


def test_non_utf8_configuration_file(tmp_path: Path) -> None:
    cfg = tmp_path / "recorder.toml"
    cfg.write_bytes(b"[port]\ndevice = \"/dev/tty\xe9\"\n")  # Latin-1 é
    line = _refused(_run(["--config", str(cfg), "--data-dir", str(tmp_path / "d")], tmp_path),
                    str(cfg), "not UTF-8", "0xe9")
    assert "must" not in line or "UTF-8" in line
    _nothing_recorded(tmp_path / "d")


@pytest.mark.parametrize(("text", "words"), [
    ("[journal]\nsegment_max_mb = nan\n", ("journal.segment_max_mb nan: must be a finite number",)),
    ("[journal]\nsegment_max_mb = 1e9\n", ("journal.segment_max_mb 1000000000.0: must be 0–4000 MB (0 = never by size",)),
    ("[journal]\nsync_interval_s = -0.5\n", ("journal.sync_interval_s -0.5: must be > 0 and ≤ 1 s",)),
    ("[port]\nreopen_max_s = inf\n", ("port.reopen_max_s inf: must be a finite number",)),
    ("[port]\nbaud = 115200.5\n", ("port.baud 115200.5: must be a whole number",)),
    ("[rtk]\nmax_base_age_s = -inf\n", ("rtk.max_base_age_s -inf: must be a finite number",)),
])
def test_bad_numbers(tmp_path: Path, text: str, words: tuple[str, ...]) -> None:
    cfg = tmp_path / "recorder.toml"
    cfg.write_text(text)
    _refused(_run(["--config", str(cfg), "--data-dir", str(tmp_path / "d")], tmp_path), *words)
    _nothing_recorded(tmp_path / "d")


def test_data_dir_that_is_a_file(tmp_path: Path) -> None:
    data = tmp_path / "data"
    data.write_text("not a folder")
    _refused(_run(["--data-dir", str(data), "--status", str(tmp_path / "s.json")], tmp_path),
             f"journal.data_dir {data}: must be a folder, but a file of that name exists")
    assert data.read_text() == "not a folder"
    # a file on the way to it
    _refused(_run(["--data-dir", str(data / "flights"), "--status", str(tmp_path / "s.json")], tmp_path),
             f"journal.data_dir {data / 'flights'}: cannot create the folder: Not a directory")


@contextlib.contextmanager
def _read_only_dir(path: Path) -> Iterator[Path]:
    """A folder this process cannot write: a read-only tmpfs when root (permissions do not stop root; 512 MB so
    that the disk floor is not what refuses it), else
    mode 0555."""
    path.mkdir()
    if os.geteuid() == 0:
        subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=512m", "tmpfs", str(path)], check=True)
        try:
            yield path
        finally:
            subprocess.run(["umount", str(path)], check=True)
    else:
        path.chmod(0o555)
        try:
            yield path
        finally:
            path.chmod(0o755)


def test_read_only_data_dir(tmp_path: Path) -> None:
    with _read_only_dir(tmp_path / "ro") as data:
        _refused(_run(["--data-dir", str(data), "--status", str(tmp_path / "s.json")], tmp_path),
                 f"journal.data_dir {data}: must be a folder this process can write")
        assert not any(data.iterdir())


@pytest.mark.slow
def test_status_path_that_cannot_be_written(tmp_path: Path) -> None:
    data = tmp_path / "d"
    _refused(_run(["--data-dir", str(data), "--status", "/proc/directgeo/status.json"], tmp_path),
             "status.path /proc/directgeo: cannot create the folder (the folder of /proc/directgeo/status.json)")
    _refused(_run(["--data-dir", str(data), "--status", "/proc/status.json"], tmp_path),
             "status.path /proc: must be a folder this process can write")
    _refused(_run(["--data-dir", str(data), "--status", str(tmp_path)], tmp_path),
             f"status.path {tmp_path}: must be a file name, not a folder")
    _nothing_recorded(data)


@pytest.mark.slow
def test_missing_serial_port_is_a_console_warning_once(tmp_path: Path) -> None:
    """The port that does not exist: one WARNING on the console (the journal under systemd) naming it, however
    often the recorder retries, and the recorder keeps running (the receiver may be plugged in later)."""
    base = {k: v for k, v in os.environ.items() if not k.startswith("ONBOARD_")}
    env = {**base, "ONBOARD_PORT_REOPEN_MIN_S": "0.05", "ONBOARD_PORT_REOPEN_MAX_S": "0.1"}
    port = tmp_path / "ttyNOPE"
    proc = subprocess.Popen([sys.executable, "-m", "onboard", "run", "--port", str(port), "--no-configure",
                             "--data-dir", str(tmp_path / "d"), "--status", str(tmp_path / "status.json")],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        while not (tmp_path / "status.json").exists():
            assert proc.poll() is None and time.monotonic() < deadline, "recorder did not start"
            time.sleep(0.1)
        time.sleep(2.0)  # ≥ 20 open attempts at 0.05–0.1 s back-off
        assert proc.poll() is None
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    warnings = [line for line in err.splitlines() if "WARNING" in line and f"cannot open {port}" in line]
    assert len(warnings) == 1, err
    assert "No such file or directory" in warnings[0]
    assert proc.returncode == 0, err
