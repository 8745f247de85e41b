"""Journal cost next to a plain file in the same process: append (+ sidecar index + SHA-256), fsync, read back.

Usage: python bench/bench_journal.py [--mb 32] [--chunk 512]
Prints MB/s and µs per append for `Journal.append` and for bare `os.write` of the same chunks, the fsync
latency of the data directory's file system, and the framing read-back rate of a flight vs a plain file.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

from onboard.hw.ports import SystemClock
from onboard.logger.journal import Journal, JournalOptions, iter_journal_frames
from onboard.receiver.framing import StreamFramer, ubx_frame


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--mb", type=float, default=32.0)
    ap.add_argument("--chunk", type=int, default=512, help="bytes per append (a serial read)")
    ap.add_argument("--dir", type=Path, default=None, help="where to write (default: a temp dir)")
    args = ap.parse_args()
    frame = ubx_frame(0x02, 0x15, bytes(range(256)) * 2)  # a ~520-byte RXM-RAWX-sized frame
    stream = frame * (int(args.mb * 1e6) // len(frame))
    chunks = [stream[i : i + args.chunk] for i in range(0, len(stream), args.chunk)]
    clock = SystemClock()
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        root = Path(tmp)
        # peer: bare os.write of the same chunks, no index, no hash
        fd = os.open(root / "plain.ubx", os.O_WRONLY | os.O_CREAT | os.O_APPEND)
        t0 = time.perf_counter()
        for c in chunks:
            os.write(fd, c)
        t_plain = time.perf_counter() - t0
        os.fsync(fd)
        os.close(fd)
        # journal: append (segment + index record + running SHA-256), rotation every 16 MB, no interval fsync
        j = Journal(root / "flight", clock, JournalOptions(sync_interval_s=1.0, segment_max_bytes=16_000_000))
        t0 = time.perf_counter()
        for c in chunks:
            j.append(c, clock.monotonic_ns(), clock.wall_ns())
        t_journal = time.perf_counter() - t0
        j.close()
        # fsync latency of small appends on this file system
        fd = os.open(root / "sync.bin", os.O_WRONLY | os.O_CREAT | os.O_APPEND)
        lat = []
        for _ in range(50):
            os.write(fd, frame)
            t0 = time.perf_counter()
            os.fsync(fd)
            lat.append(time.perf_counter() - t0)
        os.close(fd)
        # read back through the framer: flight (segments in order) vs the plain file
        t0 = time.perf_counter()
        n_journal = sum(1 for _ in iter_journal_frames(root / "flight"))
        t_read_j = time.perf_counter() - t0
        t0 = time.perf_counter()
        n_plain = len(StreamFramer().feed((root / "plain.ubx").read_bytes()))
        t_read_p = time.perf_counter() - t0
    mb = len(stream) / 1e6
    print(f"data: {mb:.1f} MB in {len(chunks)} appends of {args.chunk} B")
    print(f"append  plain os.write : {mb / t_plain:8.1f} MB/s  {t_plain / len(chunks) * 1e6:6.2f} µs/append")
    print(f"append  Journal        : {mb / t_journal:8.1f} MB/s  {t_journal / len(chunks) * 1e6:6.2f} µs/append")
    print(f"fsync   median / max   : {statistics.median(lat) * 1e3:.2f} / {max(lat) * 1e3:.2f} ms")
    print(f"read    plain framer   : {mb / t_read_p:8.1f} MB/s ({n_plain} frames)")
    print(f"read    journal frames : {mb / t_read_j:8.1f} MB/s ({n_journal} frames)")
    print("needed at 5 Hz RXM-RAWX with 24 measurements: 0.004 MB/s")


if __name__ == "__main__":
    main()
