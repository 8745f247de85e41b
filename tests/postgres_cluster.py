"""A throw-away PostgreSQL cluster for tests and benches: `initdb` + `pg_ctl` from the machine's PostgreSQL, in a
fresh temporary folder, on 127.0.0.1 and a free port, trust authentication, run as the unprivileged `nobody`
when we are root (PostgreSQL refuses root). `restart()` stops and starts it on the same data (the
database-restart fault); `stop()` removes everything.

Fixtures (registered by `tests/ground_api/conftest.py`; another test folder imports them into its conftest):
`postgres_cluster` (the object) and `postgres_url` (its SQLAlchemy URL). Both skip, with the reason, when the
server binaries or the psycopg driver are absent.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest


def pg_tool(name: str) -> str | None:
    """Path of a PostgreSQL server binary (PATH, else the newest /usr/lib/postgresql/*/bin)."""
    found = shutil.which(name)
    if found:
        return found
    for d in sorted(Path("/usr/lib/postgresql").glob("*/bin"), reverse=True):
        if (d / name).exists():
            return str(d / name)
    return None


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class PostgresCluster:
    """A running cluster; `url` (SQLAlchemy, psycopg 3 driver) and `dsn` (libpq) of its `postgres` database."""

    def __init__(self) -> None:
        initdb, pg_ctl = pg_tool("initdb"), pg_tool("pg_ctl")
        if not initdb or not pg_ctl:
            raise FileNotFoundError("PostgreSQL server binaries (initdb, pg_ctl) not installed")
        self.pg_ctl = pg_ctl
        self.as_user: list[str] = []
        # not under pytest's tmp_path: its base folder is private to the current user, the server runs as nobody
        self.root = Path(tempfile.mkdtemp(prefix="directgeo-pg-"))
        if os.geteuid() == 0:
            runuser = shutil.which("runuser")
            if not runuser:
                shutil.rmtree(self.root)
                raise PermissionError("running as root without runuser: cannot start PostgreSQL unprivileged")
            self.as_user = [runuser, "-u", "nobody", "--"]
            shutil.chown(self.root, "nobody")
        self.data = self.root / "data"
        self.port = free_port()
        self.env = {"PATH": os.environ.get("PATH", ""), "LC_ALL": "C"}
        subprocess.run([*self.as_user, initdb, "-D", str(self.data), "-U", "directgeo", "--auth=trust", "-E",
                        "UTF8"], check=True, capture_output=True, env=self.env, timeout=60)
        self.start()

    @property
    def dsn(self) -> str:
        """libpq connection string."""
        return f"postgresql://directgeo@127.0.0.1:{self.port}/postgres"

    @property
    def url(self) -> str:
        """SQLAlchemy URL."""
        return f"postgresql+psycopg://directgeo@127.0.0.1:{self.port}/postgres"

    def start(self) -> None:
        """Start the server and wait until it accepts connections."""
        opts = f"-h 127.0.0.1 -p {self.port} -k {self.root} -c max_connections=200"
        subprocess.run([*self.as_user, self.pg_ctl, "-D", str(self.data), "-o", opts, "-l", str(self.root / "log"),
                        "-w", "start"], check=True, capture_output=True, env=self.env, timeout=60)

    def stop_server(self, mode: str = "fast") -> None:
        """Stop the server (data kept): `fast` ends the sessions, `immediate` is a crash."""
        subprocess.run([*self.as_user, self.pg_ctl, "-D", str(self.data), "-m", mode, "-w", "stop"], check=False,
                       capture_output=True, env=self.env, timeout=60)

    def restart(self, mode: str = "fast") -> None:
        """Stop and start again on the same data and port."""
        self.stop_server(mode)
        self.start()

    def stop(self) -> None:
        """Stop the server and remove its folder."""
        self.stop_server()
        shutil.rmtree(self.root, ignore_errors=True)


@pytest.fixture
def postgres_cluster() -> Iterator[PostgresCluster]:
    """A running PostgreSQL cluster for one test; removed afterwards."""
    pytest.importorskip("psycopg", reason="psycopg (PostgreSQL driver) not installed: PostgreSQL test skipped")
    try:
        cluster = PostgresCluster()
    except (FileNotFoundError, PermissionError) as exc:
        pytest.skip(f"{exc}: PostgreSQL test skipped")
    try:
        yield cluster
    finally:
        cluster.stop()


@pytest.fixture
def postgres_url(postgres_cluster: PostgresCluster) -> str:
    """SQLAlchemy URL of a running throw-away PostgreSQL cluster."""
    return postgres_cluster.url
