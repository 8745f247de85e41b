"""A live ground API: uvicorn serving `create_app` on a free 127.0.0.1 port, a real SQLite file in tmp_path."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest
import uvicorn

from ground.api.app import create_app
from ground.api.settings import ApiSettings
from tests.postgres_cluster import postgres_cluster, postgres_url  # noqa: F401 - fixtures for this folder

TOKEN = "test-token-0123456789abcdef"


@dataclass
class LiveServer:
    """A running server: its base URL and settings; `restart()` stops it and starts a new one on the same data."""

    url: str
    settings: ApiSettings
    server: uvicorn.Server
    thread: threading.Thread

    def client(self, token: str | None = TOKEN) -> httpx.Client:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        return httpx.Client(base_url=self.url, headers=headers, timeout=30)

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=20)
        assert not self.thread.is_alive(), "uvicorn did not stop"


def start_server(settings: ApiSettings) -> LiveServer:
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    config = uvicorn.Config(create_app(settings), log_level="warning", lifespan="on")
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    deadline = time.monotonic() + 20
    while not server.started:
        if time.monotonic() > deadline or not thread.is_alive():
            raise RuntimeError("uvicorn did not start")
        time.sleep(0.02)
    return LiveServer(f"http://127.0.0.1:{port}", settings, server, thread)


@pytest.fixture
def api_settings(tmp_path: Path) -> ApiSettings:
    return ApiSettings(data_dir=tmp_path / "data", token=TOKEN, max_chunk_bytes=64 * 1024,
                       max_file_bytes=4 * 1024 * 1024, max_flight_bytes=16 * 1024 * 1024)


@pytest.fixture
def live(api_settings: ApiSettings) -> Iterator[LiveServer]:
    srv = start_server(api_settings)
    try:
        yield srv
    finally:
        srv.stop()


__all__ = ["TOKEN", "LiveServer", "start_server"]
