"""Upload throughput of the ground API over loopback, next to peers measured in the same process.

Peers: SHA-256 hashing of the same bytes (the work the uploader and server must both do) and a plain local
file copy (the disk floor). Our figure: `onboard.upload.client.Uploader` against a live uvicorn server on
127.0.0.1 with a real SQLite file, for several chunk sizes, plus one interrupted-and-resumed upload.

Run: `.venv/bin/python bench/bench_ground_api.py [--mib 64]`
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import socket
import tempfile
import threading
import time
from pathlib import Path

import httpx
import uvicorn

from ground.api.app import create_app
from ground.api.settings import ApiSettings
from onboard.logger.journal import Manifest, SegmentInfo
from onboard.upload.client import Uploader, UploaderOptions, UploadError

TOKEN = "bench-token-0123456789abcdef"


def _serve(settings: ApiSettings) -> tuple[str, uvicorn.Server, threading.Thread]:
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    server = uvicorn.Server(uvicorn.Config(create_app(settings), log_level="warning"))
    th = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    th.start()
    while not server.started:
        time.sleep(0.01)
    return f"http://127.0.0.1:{sock.getsockname()[1]}", server, th


def _flight(root: Path, total_bytes: int, segment_bytes: int, name: str = "flight-bench") -> Path:
    """A recorded flight folder `root/name`: random segments and the onboard manifest naming them."""
    d = root / name
    d.mkdir(parents=True)
    segs = []
    for i in range(max(1, total_bytes // segment_bytes)):
        b = os.urandom(segment_bytes)
        (d / f"{i:06d}.ubx").write_bytes(b)
        segs.append(SegmentInfo(f"{i:06d}.ubx", len(b), hashlib.sha256(b).hexdigest()))
    (d / "manifest.json").write_text(json.dumps(Manifest(name, 1, segs, closed=True).to_json()))
    return d


class _CutAfter(httpx.HTTPTransport):
    def __init__(self, n: int) -> None:
        super().__init__()
        self.n, self.puts = n, 0

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        self.puts += request.method == "PUT"
        if self.puts > self.n:
            raise httpx.ConnectError("cut", request=request)
        return super().handle_request(request)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--mib", type=int, default=64, help="flight size (MiB)")
    args = ap.parse_args()
    total = args.mib * 1024 * 1024
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        folder = _flight(root, total, 16 * 1024 * 1024)
        data = b"".join(p.read_bytes() for p in sorted(folder.glob("*.ubx")))
        t = time.perf_counter()
        hashlib.sha256(data).hexdigest()
        sha_s = time.perf_counter() - t
        t = time.perf_counter()
        for p in folder.glob("*.ubx"):
            shutil.copyfile(p, root / f"copy-{p.name}")
        copy_s = time.perf_counter() - t
        print(f"flight: {len(data) / 2**20:.0f} MiB in {len(list(folder.glob('*.ubx')))} segments")
        print(f"{'peer: sha256 (hashlib)':44s} {len(data) / 2**20 / sha_s:8.1f} MiB/s")
        print(f"{'peer: local file copy (shutil)':44s} {len(data) / 2**20 / copy_s:8.1f} MiB/s")
        for chunk_mib in (1, 4, 16):
            settings = ApiSettings(data_dir=root / f"srv-{chunk_mib}", token=TOKEN,
                                   max_chunk_bytes=chunk_mib * 2**20)
            url, server, th = _serve(settings)
            up = Uploader(url, TOKEN, UploaderOptions(chunk_bytes=chunk_mib * 2**20))
            t = time.perf_counter()
            rep = up.upload_flight(folder)
            dt = time.perf_counter() - t
            up.close()
            server.should_exit = True
            th.join()
            print(f"{f'ours: uploader → API, {chunk_mib} MiB chunks':44s} {rep.bytes_sent / 2**20 / dt:8.1f} MiB/s")
        settings = ApiSettings(data_dir=root / "srv-resume", token=TOKEN, max_chunk_bytes=4 * 2**20)
        url, server, th = _serve(settings)
        opts = UploaderOptions(chunk_bytes=4 * 2**20, max_retries=0)
        cut = Uploader(url, TOKEN, opts, client=httpx.Client(base_url=url, transport=_CutAfter(5), timeout=60))
        t = time.perf_counter()
        try:
            cut.upload_flight(folder)
        except UploadError:
            pass
        rep = Uploader(url, TOKEN, opts).upload_flight(folder)
        dt = time.perf_counter() - t
        server.should_exit = True
        th.join()
        print(f"{'ours: cut after 5 chunks, then resumed':44s} {len(data) / 2**20 / dt:8.1f} MiB/s "
              f"(second run sent {rep.bytes_sent / 2**20:.0f} MiB)")


if __name__ == "__main__":
    main()
