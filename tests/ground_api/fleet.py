"""Helpers for tests and benches of the ground app with real worker processes: tokens made through the admin
route, `python -m ground worker` (or the test worker) started in its own process group, killed or stopped."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import httpx

REPO = Path(__file__).resolve().parents[2]


def make_token(url: str, admin_token: str, role: str, name: str) -> str:
    """A new API token of `role` (POST /tokens with the bootstrap admin token); the clear secret."""
    r = httpx.post(f"{url}/tokens", json={"role": role, "name": name},
                   headers={"Authorization": f"Bearer {admin_token}"}, timeout=30)
    r.raise_for_status()
    return str(r.json()["token"])


def write_token_file(path: Path, token: str) -> Path:
    """The token in a file only its owner reads."""
    path.write_text(token + "\n")
    path.chmod(0o600)
    return path


def start_worker(args: list[str], log: Path, test_mode: str | None = None) -> subprocess.Popen[bytes]:
    """`python -m ground worker ARGS` (or `python -m tests.ground_api.queue_worker MODE ARGS`) in a new process
    group (so a kill reaches its job's child process too), output to `log`."""
    module = ["-m", "ground", "worker"] if test_mode is None else ["-m", "tests.ground_api.queue_worker", test_mode]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    with open(log, "ab") as fh:
        return subprocess.Popen([sys.executable, *module, *args], stdout=fh, stderr=subprocess.STDOUT, env=env,
                                cwd=REPO, start_new_session=True)


def kill_worker(proc: subprocess.Popen[bytes]) -> None:
    """SIGKILL the worker and its job process (no clean-up: a machine lost mid-job)."""
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)


def stop_worker(proc: subprocess.Popen[bytes], timeout_s: float = 30.0) -> None:
    """SIGTERM to the worker alone (as systemd's KillMode=mixed: it finishes its job and unregisters; the job
    process is not signalled), SIGKILL to the group if it does not stop in time."""
    if proc.poll() is not None:
        return
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        kill_worker(proc)


def wait_job(c: httpx.Client, flight_id: str, job_id: str, statuses: tuple[str, ...] = ("done", "failed"),
             timeout_s: float = 120.0, procs: tuple[subprocess.Popen[bytes], ...] = ()) -> dict[str, Any]:
    """Poll the job until its status is one of `statuses`; fails early when a worker process died."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        job: dict[str, Any] = c.get(f"/flights/{flight_id}/jobs/{job_id}").json()
        if job["status"] in statuses:
            return job
        dead = [p.args for p in procs if p.poll() is not None]
        if dead:
            raise AssertionError(f"a worker exited: {dead}")
        time.sleep(0.1)
    raise AssertionError(f"job {job_id} not {statuses} after {timeout_s} s: {job}")
