"""Recorder figures, each next to a peer run in the same process:

1. decode µs per raw epoch, RXM-RAW and RXM-RAWX (ours = StreamFramer + decode_frame) vs plain pyubx2
   `UBXReader` over the same bytes;
2. recorder CPU seconds per hour of 5 Hz RXM-RAWX: a synthetic hour (the real NEO-M8T epochs re-timed to 5 Hz,
   plus a TIM-TM2 every 3 s) through journal append + fsync policy (real `Journal` on a temp dir, data-time
   clock) + framer + decode, vs the same with pyubx2 parsing instead of our decoder;
3. peak RSS: this process after the hour, and the real daemon (`python -m onboard run --no-configure`) fed the
   same hour through a pseudo-terminal (CPU and peak RSS from `os.wait4`).

Run: `.venv/bin/python bench/bench_recorder.py [--hours 1] [--repeat 5] [--no-daemon]`. Prints a table.
Real captures are read in place from ../shared/data (the bench stops with a message when they are absent).
"""

from __future__ import annotations

import argparse
import io
import os
import platform
import resource
import signal
import struct
import subprocess
import sys
import tempfile
import time
import tty
from collections.abc import Callable, Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
sys.path.insert(0, str(ROOT))

from pyubx2 import UBXReader

from onboard.hw.fake import ManualClock
from onboard.logger.journal import Journal, JournalOptions, list_segments
from onboard.receiver.decode import DecodeStats, decode_frame
from onboard.receiver.framing import Frame, Protocol, StreamFramer, iter_frames, ubx_frame

RAW_CAPTURES = ("ubx/rtklib_ubx_20080526.ubx", "ubx/pyublox_6P-raw-PPP.ubx")
RAWX_CAPTURES = ("ubx/gpsd_ublox-neo-m8t.log", "ubx/pyubx2_pygpsdata-RXMRAWX.log")
M8T_TEMPLATE = "ubx/gpsd_ublox-neo-m8t.log"
RATE_HZ = 5
READ_BYTES = 512  # what one serial read returns at 115200 Bd with a 0.1 s timeout, roughly one epoch


def _capture(name: str) -> bytes:
    path = SHARED / name
    if not path.exists():
        sys.exit(f"bench_recorder: real capture ../shared/data/{name} is not available on this machine")
    return path.read_bytes()


def _raw_frames(names: tuple[str, ...], msg_id: int) -> tuple[bytes, int]:
    frames = [f.raw for n in names for f in iter_frames(_capture(n), frozenset({Protocol.UBX}))
              if (f.msg_class, f.msg_id) == (0x02, msg_id)]
    return b"".join(frames), len(frames)


def _best_s(fn: Callable[[], object], repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def ours(data: bytes) -> int:
    """Framer + decoder over `data`; returns the epochs decoded."""
    stats = DecodeStats()
    for frame in StreamFramer().feed(data):
        decode_frame(frame, stats)
    return stats.decoded


def pyubx2_reader(data: bytes) -> int:
    """Plain pyubx2 reading the same bytes; returns the messages parsed."""
    n = 0
    for _raw, parsed in UBXReader(io.BytesIO(data), protfilter=7, quitonerror=0):
        n += parsed is not None
    return n


def decode_table(repeat: int) -> list[tuple[str, int, float, float, float]]:
    """Rows: label, epochs, ours µs (framer + decode), of which decode µs, pyubx2 µs."""
    rows = []
    for label, names, msg_id in (("RXM-RAW", RAW_CAPTURES, 0x10), ("RXM-RAWX", RAWX_CAPTURES, 0x15)):
        data, n = _raw_frames(names, msg_id)
        assert ours(data) == n and pyubx2_reader(data) == n
        frames = StreamFramer().feed(data)

        def decode_only(frames: list[Frame] = frames) -> None:
            stats = DecodeStats()
            for frame in frames:
                decode_frame(frame, stats)

        t_ours = _best_s(lambda d=data: ours(d), repeat) / n * 1e6
        t_dec = _best_s(decode_only, repeat) / n * 1e6
        t_peer = _best_s(lambda d=data: pyubx2_reader(d), repeat) / n * 1e6
        rows.append((f"{label} ({len(data) // n} B/epoch)", n, t_ours, t_dec, t_peer))
    return rows


def synthetic_hour(hours: float) -> Iterator[tuple[bytes, float]]:
    """(bytes, data time s) of `hours` of 5 Hz RXM-RAWX: the real M8T epochs re-timed, + TIM-TM2 every 3 s."""
    template = [f.payload for f in iter_frames(_capture(M8T_TEMPLATE), frozenset({Protocol.UBX}))
                if (f.msg_class, f.msg_id) == (0x02, 0x15)]
    tow0, week = struct.unpack_from("<dH", template[0])
    n_epochs = int(hours * 3600 * RATE_HZ)
    for k in range(n_epochs):
        payload = bytearray(template[k % len(template)])
        tow = (tow0 + k / RATE_HZ) % 604800.0
        struct.pack_into("<d", payload, 0, tow)
        out = ubx_frame(0x02, 0x15, bytes(payload))
        if k % (3 * RATE_HZ) == 7:
            ms = int(tow * 1000) - 150
            out += ubx_frame(0x0D, 0x03, struct.pack("<BBHHHIIIII", 0, 0x75 & ~0x18 | 0x08, k, week, week,
                                                     ms, 1234, ms, 5678, 20))
        yield out, k / RATE_HZ


def _chunks(hours: float) -> list[tuple[bytes, float]]:
    """The synthetic stream cut into serial-read-sized chunks, each with its arrival (data) time."""
    buf = bytearray()
    out: list[tuple[bytes, float]] = []
    for data, t in synthetic_hour(hours):
        buf += data
        while len(buf) >= READ_BYTES:
            out.append((bytes(buf[:READ_BYTES]), t))
            del buf[:READ_BYTES]
    if buf:
        out.append((bytes(buf), hours * 3600))
    return out


def run_pipeline(chunks: list[tuple[bytes, float]], journal_on: bool, parse: str | None, workdir: Path) -> float:
    """Process CPU seconds for journal (+ fsync policy) and/or framer + parser over the chunks."""
    clock = ManualClock()
    journal = Journal(workdir / f"flight-{time.monotonic_ns()}", clock, JournalOptions()) if journal_on else None
    framer = StreamFramer()
    stats = DecodeStats()
    start_ns = clock.monotonic_ns()
    cpu0 = time.process_time()
    for data, t in chunks:
        if journal is not None:
            clock.advance_ns(start_ns + int(t * 1e9) - clock.monotonic_ns())
            journal.append(data, clock.monotonic_ns(), clock.wall_ns())
            journal.maybe_sync()
        if parse is None:
            continue
        for frame in framer.feed(data):
            if parse == "ours":
                decode_frame(frame, stats)
            elif frame.protocol is Protocol.UBX:
                UBXReader.parse(frame.raw)
    if journal is not None:
        journal.close()
    return time.process_time() - cpu0


def daemon_run(
    chunks: list[tuple[bytes, float]] | None, workdir: Path, stall_s: float = 30.0
) -> tuple[float, int, int, int]:
    """Run the real recorder on a pty, feed `chunks` (None: start and stop only), stop it with SIGTERM.

    Returns (CPU s user+sys, peak RSS kB, bytes journaled, signals needed to stop it).
    """
    master, slave = os.openpty()
    tty.setraw(slave)
    data_dir = workdir / f"daemon-{time.monotonic_ns()}"
    status = data_dir / "status.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(
        [sys.executable, "-m", "onboard", "run", "--no-configure", "--port", os.ttyname(slave), "--data-dir",
         str(data_dir), "--status", str(status)],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    total = 0
    try:
        deadline = time.monotonic() + 30
        while not status.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        os.set_blocking(master, True)
        for data, _t in chunks or ():
            view = memoryview(data)
            while view:
                view = view[os.write(master, view):]
            total += len(data)
        # Wait until everything is journaled, or the journal stops growing for `stall_s`.
        last, last_change = -1, time.monotonic()
        while time.monotonic() - last_change < stall_s:
            written = sum(p.stat().st_size for d in data_dir.glob("flight-*") for p in list_segments(d))
            if written >= total:
                break
            if written != last:
                last, last_change = written, time.monotonic()
            time.sleep(0.1)
    finally:
        usage, terms = _stop(proc)
        os.close(master)
        os.close(slave)
    written = sum(p.stat().st_size for d in data_dir.glob("flight-*") for p in list_segments(d))
    return usage.ru_utime + usage.ru_stime, usage.ru_maxrss, written, terms


def _stop(proc: subprocess.Popen[bytes], grace_s: float = 20.0) -> tuple[resource.struct_rusage, int]:
    """SIGTERM, again after `grace_s` if it is still running, SIGKILL after three tries.

    Returns the child's resource usage and how many signals it took (1 = clean stop on the first SIGTERM).
    """
    for attempt in range(1, 4):
        proc.send_signal(signal.SIGTERM if attempt < 3 else signal.SIGKILL)
        deadline = time.monotonic() + grace_s
        while time.monotonic() < deadline:
            pid, _status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                proc.returncode = _status
                return usage, attempt
            time.sleep(0.05)
    _pid, _status, usage = os.wait4(proc.pid, 0)
    return usage, 4


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hours", type=float, default=1.0, help="length of the synthetic 5 Hz RAWX stream (h)")
    ap.add_argument("--repeat", type=int, default=5, help="best of N for the per-epoch timings")
    ap.add_argument("--no-daemon", action="store_true", help="skip the real-daemon run")
    args = ap.parse_args(argv)

    print(f"host: {platform.machine()} {platform.processor() or ''} Python {platform.python_version()} "
          f"(figures scale to a Pi; compare ratios)")
    print(f"\n1. decode time per raw epoch (best of {args.repeat})")
    print(f"{'message':<26}{'epochs':>8}{'ours µs':>10}{'(decode)':>10}{'pyubx2 µs':>11}{'pyubx2/ours':>13}")
    for label, n, t_ours, t_dec, t_peer in decode_table(args.repeat):
        print(f"{label:<26}{n:>8}{t_ours:>10.1f}{t_dec:>10.1f}{t_peer:>11.1f}{t_peer / t_ours:>12.1f}x")
    print("   ours = StreamFramer (checksums) + decode_frame; pyubx2 = UBXReader over the same bytes")

    chunks = _chunks(args.hours)
    n_bytes = sum(len(c) for c, _ in chunks)
    per_h = 1.0 / args.hours
    print(f"\n2. recorder CPU for {args.hours:g} h of {RATE_HZ} Hz RXM-RAWX ({n_bytes / 1e6:.1f} MB in "
          f"{len(chunks)} reads of ≤{READ_BYTES} B), process CPU s per hour")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        run_pipeline(chunks[:2000], True, "ours", work)  # warm-up (imports, page cache)
        rows = [
            (label, min(run_pipeline(chunks, j, p, work) for _ in range(2)))
            for label, j, p in (
                ("journal + fsync policy only", True, None),
                ("framer + our decode only", False, "ours"),
                ("framer + pyubx2 parse only", False, "pyubx2"),
                ("journal + framer + our decode", True, "ours"),
                ("journal + framer + pyubx2 parse", True, "pyubx2"),
            )
        ]
        ref = rows[3][1]
        print(f"{'pipeline':<34}{'CPU s/h':>9}{'% core':>8}{'vs ours':>9}")
        for label, cpu in rows:
            cpu_h = cpu * per_h
            print(f"{label:<34}{cpu_h:>9.2f}{100 * cpu_h / 3600:>8.3f}{cpu / ref:>8.2f}x")
        rss_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        print(f"\n3. peak RSS\n{'this bench process (imports + hour replays)':<46}{rss_kb / 1024:>8.1f} MB")
        if not args.no_daemon:
            idle_cpu, idle_rss, _, idle_terms = daemon_run(None, work)
            cpu, rss, written, terms = daemon_run(chunks, work)
            ok = "all bytes journaled" if written == n_bytes else f"only {written} of {n_bytes} B journaled"
            for label, n in (("start + stop", idle_terms), ("fed run", terms)):
                if n > 1:
                    print(f"   WARNING: daemon {label}: the first SIGTERM did not stop it within 20 s "
                          f"({'a second SIGTERM did' if n == 2 else 'needed SIGKILL'}); CPU below includes the wait")
            print(f"{'daemon, start + stop only':<46}{idle_rss / 1024:>8.1f} MB   CPU {idle_cpu:.2f} s")
            print(f"{'daemon, fed the stream as fast as the pty goes':<46}{rss / 1024:>8.1f} MB   CPU {cpu:.2f} s "
                  f"({ok}); minus start/stop: {(cpu - idle_cpu) * per_h:.2f} CPU s per hour of data")
            print("   (accelerated replay: the daemon's wall-clock fsync and status timers fire less often than "
                  "in a real hour; section 2 runs the fsync policy on data time)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
