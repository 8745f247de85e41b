"""The recorder daemon: the composition root of `python -m onboard run`.

One process, one asyncio loop, one reader/writer thread:

    reader thread:  port.read → journal.append (bytes are on their way to disk before anything parses them)
                    → maybe_sync; hands the bytes to the loop; reopens a vanished port with backoff
    asyncio loop:   framer → decoder → status counters, configuration link frames, time marks (→ fsync now,
                    events.jsonl); configuration task after every (re)connection; status snapshot every
                    ~1 s; disk floor; sd_notify READY / STATUS / WATCHDOG.

Parsing and configuration are best effort: an exception there is logged and counted, never stops the reader.
Threads hand work to the loop through one ordered queue with at most one pending loop wake-up (`_post`): a
wake-up per serial read filled asyncio's self-pipe when the loop lagged behind a burst, and a full self-pipe
drops the SIGTERM wake-up (CPython writes signals to the same socket), so the daemon ignored `systemctl stop`.
Features (`onboard.recorder.feature`: real-time RTK, the base station's sender, ...) get the flight's lifecycle
and the stream's bytes, frames and decoded items through explicit hooks; their failures are logged and counted.

One recorder per data directory: `<data_dir>/.lock` is held (`fcntl.flock`) for the recorder's life; a second
recorder on the same directory refuses before touching anything (exit 2: systemd does not restart on it).
Exit codes: 0 clean stop (SIGTERM/SIGINT), 1 journal I/O failure, 2 data directory in use, 3 disk below the floor
(at start: nothing recorded; while recording: the flight is closed cleanly first).
"""

from __future__ import annotations

import asyncio
import errno
import fcntl
import functools
import logging
import os
import shutil
import signal
import threading
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from onboard.errors import ConfigRejected, DiskFull, InputError, LinkLost, OnboardError, ReceiverError
from onboard.gnsstime import GpsTime
from onboard.hw.ports import ByteStream, Clock, Edge, EdgeSource, SystemClock
from onboard.logger.events import EventLog, read_events
from onboard.logger.files import FileLayer, OsFileLayer
from onboard.logger.journal import EVENTS_NAME, Journal, JournalOptions, flight_name, read_manifest
from onboard.receiver.framing import Frame, StreamFramer
from onboard.recorder.feature import FlightContext, RecorderFeature, is_rollover
from onboard.recorder.sdnotify import SdNotifier, WatchdogGate
from onboard.recorder.settings import Settings, receiver_options
from onboard.recorder.status import SatelliteStatus, StatusSnapshot, write_status
from onboard.rtk.types import CameraMark
from onboard.timepulse.marks import (
    EVENT_FORMAT_VERSION,
    FLASH_CHANNEL,
    TRIGGER_CHANNEL,
    PairingOptions,
    PairingRecorder,
    TickAnchor,
    gpio_mark,
    parse_records,
    pps_anchors,
    timepulse_record,
)
from onboard.upload.queue import UploadQueue

log = logging.getLogger(__name__)

EXIT_OK = 0
EXIT_IO_ERROR = 1
EXIT_IN_USE = 2
EXIT_DISK_FULL = 3
LOCK_NAME = ".lock"
"""The data directory's advisory lock file (holds the pid of the recorder that owns the directory)."""
READ_CHUNK_BYTES = 4096
TIM_TM2 = (0x0D, 0x03)


def disk_free_bytes(path: Path) -> int:
    """Free bytes available to this user on the file system holding `path`."""
    return shutil.disk_usage(path).free


@dataclass
class RecorderDeps:
    """What the composition root passes in (fakes in tests, real hardware in production)."""

    open_port: Callable[[], ByteStream]
    clock: Clock = field(default_factory=SystemClock)
    files: FileLayer = field(default_factory=OsFileLayer)
    disk_free: Callable[[Path], int] = disk_free_bytes
    notifier: SdNotifier = field(default_factory=lambda: SdNotifier({}))
    # Edge sources named by `Edge.line`: "trigger" (camera trigger pulses, when receiver.trigger = "gpio"),
    # "flash" (hot-shoe input, when gpio.flash_pin is set) and "pps" (receiver 1 PPS, the time anchor).
    # Built by the composition root from gpiozero pins.
    edge_sources: Callable[[], Sequence[EdgeSource]] | None = None


class DataDirInUse(OnboardError):
    """Another recorder holds the data directory's lock (`pid` its process id, None when unreadable)."""

    def __init__(self, data_dir: Path, pid: int | None) -> None:
        who = f"pid {pid}" if pid is not None else "pid unknown"
        super().__init__(f"{data_dir} is in use by another recorder ({who})")
        self.pid = pid


class DataDirLock:
    """`<data_dir>/.lock` held with `fcntl.flock` (advisory, exclusive, released by the kernel when the process
    dies, so a crash leaves no stale lock). The holder's pid is written into the file for the error message."""

    def __init__(self, data_dir: Path) -> None:
        self.data_dir = Path(data_dir)
        self.path = self.data_dir / LOCK_NAME
        self._fd: int | None = None

    def acquire(self) -> None:
        """Take the lock; raises DataDirInUse when another process (or recorder) holds it, OSError when the lock
        file cannot be created (a read-only or foreign data directory)."""
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            try:
                text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
            finally:
                os.close(fd)
            raise DataDirInUse(self.data_dir, int(text) if text.isdigit() else None) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)
        self._fd = fd

    def release(self) -> None:
        """Release the lock (the file stays: removing it would race with a recorder that just opened it)."""
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor releases the flock
            self._fd = None


def _flights(data_dir: Path) -> list[Path]:
    return sorted(p for p in data_dir.iterdir() if p.is_dir() and p.name.startswith("flight-"))


def choose_flight_dir(data_dir: Path, wall_ns: int) -> Path:
    """The flight to record into: the latest flight if it was not closed cleanly (resume after a crash or
    power cut, in a new segment), else a new `flight-YYYYmmddTHHMMSSZ` directory."""
    flights = _flights(data_dir)
    if flights:
        last = flights[-1]
        manifest = read_manifest(last)
        if manifest is None or not manifest.closed:
            return last
    return new_flight_dir(data_dir, wall_ns)


def new_flight_dir(data_dir: Path, wall_ns: int) -> Path:
    """A new flight directory named after `wall_ns` (not created) that sorts after every existing flight: two
    flights in the same second, or a wall clock stepped back (a Pi without RTC), get a `-NN` suffix."""
    flights = _flights(data_dir)
    name = flight_name(wall_ns)
    if flights and name <= flights[-1].name:
        name = flights[-1].name  # the newest flight's name plus a suffix still sorts after it
    candidate = data_dir / name
    n = 1
    while candidate.exists():
        candidate = data_dir / f"{name}-{n:02d}"
        n += 1
    return candidate


class GpioTiming:
    """GPIO trigger/flash edges → GPS-timed `CameraMark`s (pure): PPS edges on another GPIO anchor the host
    clock. Line "trigger" gives channel 1 (TRIGGER_CHANNEL) marks, line "flash" channel 0 (FLASH_CHANNEL:
    the hot-shoe's falling edge is the flash); each line counts its own edges.

    `set_coarse(tick, time)` relates the host clock to GPS time roughly (the host tick at which an epoch's
    bytes arrived, and its time tag); PPS ticks then snap to whole GPS seconds (`pps_anchors`). An edge waits until a PPS edge after it arrived, so it is interpolated between two anchors, or until
    `wait_ns` passed (then extrapolated; without anchors it gets no time and `valid` False).
    `acc_est_ns` is what we vouch for: interrupt latency and chrony-free host clock over one second.
    """

    def __init__(self, wait_ns: int = 2_500_000_000, acc_est_ns: int = 20_000, max_pps: int = 16) -> None:
        self.wait_ns = wait_ns
        self.acc_est_ns = acc_est_ns
        self.coarse: TickAnchor | None = None
        self.pps: deque[int] = deque(maxlen=max_pps)
        self.pending: list[Edge] = []
        self.counts: dict[str, int] = {"trigger": 0, "flash": 0}

    def set_coarse(self, tick_ns: int, time: GpsTime) -> None:
        """Latest coarse host-tick ↔ GPS-time correspondence."""
        self.coarse = TickAnchor(tick_ns, time)

    def add(self, edge: Edge, now_ns: int) -> list[tuple[CameraMark, int]]:
        """Take one edge; returns trigger marks (with their host ticks) that can be timed now."""
        if edge.line == "pps":
            if edge.rising:
                self.pps.append(edge.monotonic_ns)
        elif edge.line in self.counts:
            self.pending.append(edge)
        return self.release(now_ns)

    def release(self, now_ns: int) -> list[tuple[CameraMark, int]]:
        """Trigger/flash marks whose time can be fixed now (a PPS after them, or waited long enough)."""
        anchors = pps_anchors(self.pps, self.coarse) if self.coarse is not None else []
        latest_pps = self.pps[-1] if self.pps else None
        out, keep = [], []
        for e in self.pending:
            if (latest_pps is not None and latest_pps > e.monotonic_ns) or now_ns - e.monotonic_ns >= self.wait_ns:
                self.counts[e.line] += 1
                channel = TRIGGER_CHANNEL if e.line == "trigger" else FLASH_CHANNEL
                mark = gpio_mark(channel, e.rising, e.monotonic_ns, self.counts[e.line], anchors, self.acc_est_ns)
                out.append((mark, e.monotonic_ns))
            else:
                keep.append(e)
        self.pending = keep
        return out


class Recorder:
    """The recorder: owns the journal, event log, port thread, decoder hook-up and status, and calls its
    `features` (`onboard.recorder.feature.RecorderFeature`) at the points that module names."""

    def __init__(self, settings: Settings, deps: RecorderDeps, features: Sequence[RecorderFeature] = ()) -> None:
        self.settings = settings
        self.deps = deps
        self.features: tuple[RecorderFeature, ...] = tuple(features)
        names = [f.name for f in self.features]
        if len(set(names)) != len(names):
            raise ValueError(f"recorder features must have distinct names, got {names}")
        self.refused: str | None = None
        """Why the recorder refused to start (the data directory is in use), for the command line's error."""
        self._lock = DataDirLock(settings.data_dir)
        self._logged_feature_errors: set[tuple[str, str]] = set()
        self._features_open = False
        self.clock = deps.clock
        self.status = StatusSnapshot(
            pid=os.getpid(),
            started_wall_ns=self.clock.wall_ns(),
            port_device=settings.port_device,
            disk_floor_bytes=int(settings.disk_floor_mb * 1e6),
            config_state="pending" if settings.receiver_configure else "disabled",
        )
        self.journal: Journal | None = None
        self.events: EventLog | None = None
        self._journal_options = JournalOptions()
        self._queue = UploadQueue(settings.data_dir) if settings.upload_url else None
        """Closed flights are queued for the uploader (`onboard.upload`) when `upload.url` is set."""
        self.flights_closed = 0
        """Flights closed by a roll-over while recording went on (the autopilot saw the flight end)."""
        self.exit_code = EXIT_OK
        self.stop_reason: str | None = None
        self._stop_thread = threading.Event()
        self._stopped: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._journal_lock = threading.Lock()
        self._posted: deque[tuple[Callable[..., Any], tuple[Any, ...]]] = deque()
        self._post_lock = threading.Lock()
        self._post_scheduled = False
        self._mark_sync = threading.Event()  # set by the loop on a TIM-TM2: the reader thread fsyncs at once
        self._port: ByteStream | None = None
        self._reopen_request: tuple[int, asyncio.Future[None]] | None = None
        self._framer = StreamFramer()
        self._frames_this_connection = 0
        self._link: Any = None
        self._config_task: asyncio.Task[None] | None = None
        self._gate = WatchdogGate(int(settings.watchdog_writer_stall_s * 1e9))
        self._decode_stats: Any = None
        self._decode: Callable[..., Any] | None = None
        self._pairer = PairingRecorder(self._pairing_options())
        self._gpio = GpioTiming()
        self._last_rx_mono_ns = 0
        self._aid_eph_poll_s = float(receiver_options(settings).aid_eph_poll_s)
        self._aid_eph_due_ns: int | None = None  # None: poll at the next fix
        self._aid_eph_task: asyncio.Task[None] | None = None  # held: the loop keeps only weak references

    def _resume_pairing(self, events_path: Path) -> None:
        """After a crash, seed the pairer with the marks already logged so pairing indices continue."""
        found = read_events(events_path)
        if not found.records:
            return
        try:
            marks, pairings, _ = parse_records(found.records)
        except InputError as exc:
            log.warning("event log %s not resumable (%s): pairing starts afresh", events_path, exc)
            return
        # Replaying the logged marks rebuilds the pairer's state, so image indices continue; the records it
        # returns now are already in the log (a pairing cut off by a power loss is recomputable from the marks).
        self._pairer.add(marks)
        log.info("resumed pairing: %d marks, %d pairings already logged", len(marks), len(pairings))

    def _pairing_options(self) -> PairingOptions:
        opts = receiver_options(self.settings)
        return PairingOptions(
            trigger_measured=opts.trigger == "extint1"
            or (opts.trigger == "gpio" and self.deps.edge_sources is not None),
            trigger_edge="rising" if opts.pulse_rising else "falling",
            max_delay_ns=min(1_000_000_000, round(opts.camera_period_s * 1e9) // 2),
            flash_source="gpio" if self._gpio_flash() else None,
        )

    def _gpio_flash(self) -> bool:
        """True when flashes are measured on a GPIO input (gpio.flash_pin) rather than TIM-TM2 EXTINT0."""
        return self.settings.gpio_flash_pin >= 0 and self.deps.edge_sources is not None

    # -- lifecycle --------------------------------------------------------------------------------------
    def check_disk(self) -> int:
        """Free bytes of the data directory; raises DiskFull when below the floor."""
        free = self.deps.disk_free(self.settings.data_dir)
        self.status.disk_free_bytes = free
        if free < self.status.disk_floor_bytes:
            raise DiskFull(
                f"{self.settings.data_dir}: {free / 1e6:.1f} MB free, below the floor of "
                f"{self.settings.disk_floor_mb:.1f} MB"
            )
        return free

    async def run(self) -> int:
        """Record until stopped; returns the process exit code."""
        self._loop = asyncio.get_running_loop()
        self._stopped = asyncio.Event()
        s = self.settings
        s.data_dir.mkdir(parents=True, exist_ok=True)
        try:
            self._lock.acquire()
        except DataDirInUse as exc:
            # Before anything else: the other recorder's flight, manifest and status snapshot stay untouched.
            self.refused = str(exc)
            log.error("refusing to record: %s", exc)
            return EXIT_IN_USE
        except OSError as exc:
            log.error("cannot lock the data directory %s: %s", s.data_dir, exc)
            self.status.state = "error"
            self.status.message = f"cannot lock the data directory {s.data_dir}: {exc}"
            s.status_path.parent.mkdir(parents=True, exist_ok=True)
            self._write_status()
            self.deps.notifier.notify(STATUS=self.status.message)
            return EXIT_IO_ERROR
        try:
            return await self._run_locked()
        finally:
            if self._features_open:  # run() failed between flight opened and closed: stop the features' threads
                self._close_features(self.stop_reason or "recorder failed")
            self._lock.release()

    async def _run_locked(self) -> int:
        assert self._loop is not None and self._stopped is not None
        s = self.settings
        s.status_path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self.check_disk()
        except DiskFull as exc:
            log.error("refusing to record: %s", exc)
            self.status.state = "disk_full"
            self.status.message = f"refusing to start: {exc}"
            self._write_status()
            self.deps.notifier.notify(STATUS=self.status.message)
            return EXIT_DISK_FULL
        flight_dir = choose_flight_dir(s.data_dir, self.clock.wall_ns())
        options = JournalOptions(
            sync_interval_s=s.journal_sync_interval_s,
            segment_max_bytes=int(s.journal_segment_max_mb * 1e6),
            segment_max_s=s.journal_segment_max_s,
        )
        try:
            self.journal = Journal(flight_dir, self.clock, options, self.deps.files)
            self.events = EventLog(flight_dir / EVENTS_NAME, self.clock, s.journal_sync_interval_s,
                                   self.deps.files)
        except OSError as exc:
            log.error("cannot open the flight %s: %s", flight_dir, exc)
            self.status.state = "error"
            self.status.message = f"cannot open the flight {flight_dir}: {exc}"
            self._write_status()
            self.deps.notifier.notify(STATUS=self.status.message)
            return EXIT_DISK_FULL if exc.errno in (errno.ENOSPC, errno.EDQUOT) else EXIT_IO_ERROR
        self._resume_pairing(flight_dir / EVENTS_NAME)
        self.status.flight = flight_dir.name
        self.status.flight_dir = str(flight_dir)
        self._journal_options = options
        self._setup_decoder()
        if self._queue is not None:
            try:
                for name in self._queue.promote_closed(flight_dir.name):
                    log.info("upload queue: %s was closed before a crash: ready to upload", name)
            except OSError as exc:
                log.warning("upload queue not readable: %s", exc)
        manifest = self.journal.manifest
        resumed = manifest.restarts > 0 or any(seg.recovered for seg in manifest.segments)
        self._features_open = True
        self._open_features(flight_dir, resumed, None)
        for sig in (signal.SIGTERM, signal.SIGINT):
            try:
                self._loop.add_signal_handler(sig, self.request_stop, f"signal {sig.name}", EXIT_OK)
            except (NotImplementedError, RuntimeError):  # not the main thread (tests run us in a thread)
                pass
        thread = threading.Thread(target=self._reader_thread, name="recorder-reader", daemon=True)
        thread.start()
        edge_threads = self._start_edge_threads()
        self.status.state = "recording"
        self._write_status()
        self.deps.notifier.notify(READY=1, STATUS=f"recording {flight_dir.name}")
        log.info("recording into %s", flight_dir)
        tasks = [asyncio.create_task(self._status_task()), asyncio.create_task(self._watchdog_task())]
        await self._stopped.wait()
        self._stop_thread.set()
        await asyncio.to_thread(thread.join)
        for t in edge_threads:
            await asyncio.to_thread(t.join)
        for task in [*tasks, self._config_task]:
            if task is not None:
                task.cancel()
        await asyncio.gather(*[t for t in [*tasks, self._config_task] if t is not None], return_exceptions=True)
        self._close_flight()
        return self.exit_code

    def request_stop(self, reason: str, exit_code: int = EXIT_OK) -> None:
        """Stop recording (first reason wins); safe to call from the loop only."""
        if self.stop_reason is None:
            self.stop_reason = reason
            self.exit_code = exit_code
            log.info("stopping: %s", reason)
        if self._stopped is not None:
            self._stopped.set()

    def _request_stop_threadsafe(self, reason: str, exit_code: int) -> None:
        if self._loop is not None:
            self._loop.call_soon_threadsafe(self.request_stop, reason, exit_code)

    def _open_features(self, flight_dir: Path, resumed: bool, previous: Path | None) -> None:
        context = FlightContext(flight_dir=flight_dir, clock=self.clock, journal_options=self._journal_options,
                                status_path=self.settings.status_path, post=self._post,
                                request_stop=self.request_stop, append_event=self._append_event,
                                close_flight=self.close_flight, resumed=resumed, previous_flight_dir=previous)
        for feature in self.features:
            self._feature_call(feature, feature.on_flight_opened, context)

    def _enqueue(self, flight_dir: Path, ready: bool) -> None:
        """Queue a closing (`ready` False) or closed flight for the uploader; a failure is logged, never stops
        recording (the flight stays on disk and can be queued by hand)."""
        if self._queue is None:
            return
        try:
            self._queue.enqueue(flight_dir.name, ready, self.clock.wall_ns())
        except OSError as exc:
            log.error("upload queue: %s not queued: %s", flight_dir.name, exc)

    def close_flight(self, reason: str) -> None:
        """Close the current flight and continue recording into a new one without a gap (loop only).

        The new journal and event log are opened first; the features' `on_flight_closing(reason)` append their last
        records to the old flight's event log; the reader thread's next append goes to the new journal
        (the swap happens under the journal lock, between two appends); then the old flight is closed (segment
        fsync'd and hashed, final manifest with `reason`), the features get `on_flight_closed(reason)` and
        `on_flight_opened(next)`, and the old flight is queued for upload. If the new flight cannot be opened,
        recording goes on in the old one."""
        if self.journal is None or self.journal.closed or (self._stopped is not None and self._stopped.is_set()):
            return
        reason = reason if is_rollover(reason) else f"rollover: {reason}"
        started_ns = self.clock.monotonic_ns()
        old_dir = self.journal.flight_dir
        new_dir = new_flight_dir(self.settings.data_dir, self.clock.wall_ns())
        try:
            journal = Journal(new_dir, self.clock, self._journal_options, self.deps.files)
            events = EventLog(new_dir / EVENTS_NAME, self.clock, self.settings.journal_sync_interval_s,
                              self.deps.files)
        except OSError as exc:
            log.error("cannot open the next flight %s (%s): recording goes on in %s", new_dir, exc, old_dir.name)
            return
        self._enqueue(old_dir, ready=False)
        self._features_closing(reason)  # their last records go into the old flight's event log, still current
        with self._journal_lock:
            old_journal, self.journal = self.journal, journal
        old_events, self.events = self.events, events
        close_record = {"type": "flight", "event": "closed", "reason": reason, "next_flight": new_dir.name,
                        "host_wall_ns": self.clock.wall_ns(), "host_monotonic_ns": self.clock.monotonic_ns(),
                        "bytes": old_journal.bytes_written}
        try:
            if old_events is not None:
                for rec in self._pairer.flush():
                    old_events.append(rec)
                old_events.append(close_record)
                old_events.close()
            old_journal.close(reason)
        except OSError as exc:
            log.error("closing the flight %s failed: %s (the next start recovers it)", old_dir.name, exc)
        self._pairer = PairingRecorder(self._pairing_options())
        self.flights_closed += 1
        self.status.flight = new_dir.name
        self.status.flight_dir = str(new_dir)
        self.status.events = events.records
        log.info("flight %s closed (%s); recording into %s", old_dir.name, reason, new_dir.name)
        for feature in self.features:
            self._feature_call(feature, feature.on_flight_closed, reason)
        self._open_features(new_dir, False, old_dir)
        self._append_event({"type": "flight", "event": "opened", "previous_flight": old_dir.name,
                            "host_wall_ns": self.clock.wall_ns(), "host_monotonic_ns": self.clock.monotonic_ns()})
        self._enqueue(old_dir, ready=True)
        self._write_status()
        log.info("roll-over done in %.1f ms (the journal lock was held only for the swap)",
                 (self.clock.monotonic_ns() - started_ns) / 1e6)

    def _close_flight(self) -> None:
        reason = self.stop_reason or "stopped"
        if self.journal is not None:
            self._enqueue(self.journal.flight_dir, ready=False)
        if self._features_open:
            self._features_closing(reason)
        try:
            if self.events is not None:
                for rec in self._pairer.flush():
                    self.events.append(rec)
                self.status.events = self.events.records
                self.events.close()
            if self.journal is not None:
                with self._journal_lock:
                    self.journal.close(reason)
        except OSError as exc:
            # Even a full disk leaves the fsync'd segment intact; the next start recovers the manifest.
            log.error("closing the flight failed: %s", exc)
            self.status.message = f"{reason}; closing failed: {exc}"
        self._close_features(reason)
        if self.journal is not None and self.journal.closed:
            self._enqueue(self.journal.flight_dir, ready=True)
        if self._port is not None:
            self._port.close()
            self._port = None
        if self.status.state not in ("disk_full", "error"):
            self.status.state = "stopped"
        if self.status.message is None:
            self.status.message = reason
        self.status.port_open = False
        self._write_status()
        self.deps.notifier.notify(STOPPING=1, STATUS=f"stopped: {reason}")

    def _features_closing(self, reason: str) -> None:
        """`on_flight_closing(reason)` of every feature, while the flight's event log is open."""
        for feature in self.features:
            self._feature_call(feature, feature.on_flight_closing, reason)

    def _close_features(self, reason: str) -> None:
        self._features_open = False
        for feature in self.features:
            self._feature_call(feature, feature.on_flight_closed, reason)

    # -- reader/writer thread ---------------------------------------------------------------------------
    def _reader_thread(self) -> None:
        s = self.settings
        backoff_s = s.port_reopen_min_s
        assert self.journal is not None
        while not self._stop_thread.is_set():
            self._gate.writer_beat(self.clock.monotonic_ns())
            port = self._port
            if port is None:
                try:
                    port = self.deps.open_port()
                except LinkLost as exc:
                    self._post(self._on_port_error, str(exc))
                    self._idle_sync()
                    # Wait in short steps so the writer heartbeat stays fresh while unplugged.
                    waited = 0.0
                    while waited < backoff_s and not self._stop_thread.is_set():
                        self._gate.writer_beat(self.clock.monotonic_ns())
                        step = min(0.2, backoff_s - waited)
                        self._stop_thread.wait(step)
                        waited += step
                    backoff_s = min(backoff_s * 2, s.port_reopen_max_s)
                    continue
                self._port = port
                backoff_s = s.port_reopen_min_s
                self._post(self._on_port_open)
            try:
                data = port.read(READ_CHUNK_BYTES)
            except LinkLost as exc:
                port.close()
                self._port = None
                self._post(self._on_port_error, str(exc))
                continue
            if data:
                mono, wall = self.clock.monotonic_ns(), self.clock.wall_ns()
                if not self._journal_op(functools.partial(Journal.append, data=data, rx_monotonic_ns=mono,
                                                          rx_wall_ns=wall)):
                    return
                self._post(self._on_bytes, data, mono)
            if not self._sync_for_marks() or not self._journal_op(Journal.maybe_sync):
                return
            request = self._reopen_request
            if request is not None:
                self._reopen_request = None
                self._do_reopen(port, *request)

    def _do_reopen(self, port: ByteStream, baud: int, fut: asyncio.Future[None]) -> None:
        reopen = getattr(port, "reopen", None)
        try:
            if reopen is not None:
                reopen(baud)
            self._post(_set_future, fut, None)
        except LinkLost as exc:
            self._port = None
            self._post(_set_future, fut, exc)

    def _idle_sync(self) -> None:
        assert self.journal is not None
        if self._sync_for_marks():
            self._journal_op(Journal.maybe_sync)

    def _sync_for_marks(self) -> bool:
        """fsync now if the loop saw a time mark since the last call (reader thread); False if that failed."""
        if not self._mark_sync.is_set():
            return True
        self._mark_sync.clear()
        return self._journal_op(Journal.sync_now)

    def _journal_op(self, op: Callable[[Journal], Any]) -> bool:
        """Run a journal write/sync `op(journal)` on the current journal, resolved under the journal lock (a
        roll-over swaps it between two ops); on an OS error stop the recorder (ENOSPC → disk full). False if
        failed."""
        try:
            with self._journal_lock:
                journal = self.journal
                assert journal is not None
                op(journal)
            return True
        except OSError as exc:
            if exc.errno in (errno.ENOSPC, errno.EDQUOT):
                self._post(self._set_state, "disk_full", f"disk full while recording: {exc}")
                self._request_stop_threadsafe("disk full", EXIT_DISK_FULL)
            else:
                self._post(self._set_state, "error", f"journal write failed: {exc}")
                self._request_stop_threadsafe(f"journal write failed: {exc}", EXIT_IO_ERROR)
            log.error("journal: %s", exc)
            return False

    def _post(self, fn: Callable[..., Any], *args: Any) -> None:
        """Run `fn(*args)` on the loop, in posting order; at most one loop wake-up is pending at a time."""
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        with self._post_lock:
            self._posted.append((fn, args))
            if self._post_scheduled:
                return
            self._post_scheduled = True
        try:
            loop.call_soon_threadsafe(self._run_posted)
        except RuntimeError:  # loop closing at shutdown
            pass

    def _run_posted(self) -> None:
        """Loop side of `_post`: schedule everything queued, in order, each as its own callback (an exception in
        one is logged by asyncio and does not drop the others)."""
        assert self._loop is not None
        with self._post_lock:
            items = list(self._posted)
            self._posted.clear()
            self._post_scheduled = False
        for fn, args in items:
            self._loop.call_soon(fn, *args)

    # -- GPIO trigger / PPS edges ----------------------------------------------------------------------
    def _start_edge_threads(self) -> list[threading.Thread]:
        if self.deps.edge_sources is None or not (receiver_options(self.settings).trigger == "gpio"
                                                  or self._gpio_flash()):
            return []
        threads = []
        for source in self.deps.edge_sources():
            t = threading.Thread(target=self._edge_thread, args=(source,), name="recorder-edges", daemon=True)
            t.start()
            threads.append(t)
        return threads

    def _edge_thread(self, source: EdgeSource) -> None:
        try:
            while not self._stop_thread.is_set():
                edge = source.get(0.2)
                if edge is not None:
                    self._post(self._on_edge, edge)
        finally:
            source.close()

    def _on_edge(self, edge: Edge) -> None:
        for mark, tick in self._gpio.add(edge, self.clock.monotonic_ns()):
            self._on_gpio_mark(mark, tick)

    def _on_gpio_mark(self, mark: CameraMark, tick_ns: int) -> None:
        self.status.time_marks += 1
        if mark.time is not None:
            self.status.last_mark_gpst = str(mark.time)
        for rec in self._pairer.add([mark], tick_ns):
            self._append_event(rec)
        if self.events is not None:
            self._sync_events()  # a GPIO mark exists only in events.jsonl: durable now, like a TIM-TM2 mark

    # -- loop side: port state --------------------------------------------------------------------------
    def _set_state(self, state: str, message: str) -> None:
        self.status.state = state
        self.status.message = message

    def _on_port_error(self, message: str) -> None:
        was_open = self.status.port_open
        self.status.port_open = False
        self.status.port_error = message
        if self.status.state == "recording" or was_open:
            self.status.state = "port_lost"
            self.status.message = f"receiver port unavailable: {message}"
        if was_open:
            log.warning("port lost: %s", message)
        if self._config_task is not None:
            self._config_task.cancel()
            self._config_task = None
        self._link = None

    def _on_port_open(self) -> None:
        from onboard.receiver.configure import FrameQueueLink

        if self.status.port_error is not None or self.status.state == "port_lost":
            self.status.port_reconnects += 1
        self.status.port_open = True
        self.status.port_error = None
        if self.status.state == "port_lost":
            self.status.state = "recording"
            self.status.message = None
        self._framer = StreamFramer()  # bytes of the old connection never complete a frame of the new one
        self._frames_this_connection = 0
        self._aid_eph_due_ns = None  # the receiver may have been power-cycled: poll again at its next fix
        self._link = FrameQueueLink(self._link_write, self._link_reopen)
        if self.settings.receiver_configure:
            self._config_task = asyncio.create_task(self._configure(self._link))

    async def _link_write(self, raw: bytes) -> None:
        port = self._port
        if port is None:
            raise LinkLost("receiver port is not open")
        await asyncio.to_thread(port.write, raw)

    async def _link_reopen(self, baud: int) -> None:
        assert self._loop is not None
        fut: asyncio.Future[None] = self._loop.create_future()
        self._reopen_request = (baud, fut)
        await asyncio.wait_for(fut, 5.0)

    # -- loop side: configuration -----------------------------------------------------------------------
    async def _configure(self, link: Any) -> None:
        """Detect the receiver, apply and verify the profile; failures go to the status, never stop recording."""
        from onboard.receiver.configure import apply_profile, detect_receiver, probe_baud
        from onboard.receiver.profiles import build_profile

        s = self.settings
        st = self.status
        try:
            opts = receiver_options(s)
            st.config_state = "detecting"
            st.config_error = None
            try:
                info = await detect_receiver(link, opts.ack_timeout_s, opts.retries)
            except ConfigRejected:
                # Valid frames at this rate prove the baud is right: the receiver just does not answer.
                # Only a port that yields no valid frame at all is worth a baud probe.
                if self._frames_this_connection:
                    raise
                baud = await probe_baud(link)
                if baud is None:
                    raise
                info = await detect_receiver(link, opts.ack_timeout_s, opts.retries)
            st.receiver_model = info.model
            st.receiver_sw_version = info.sw_version
            st.receiver_hw_version = info.hw_version
            st.receiver_extensions = list(info.extensions)
            model = info.model if s.receiver_model == "auto" else s.receiver_model
            if s.receiver_model != "auto" and info.model != s.receiver_model:
                raise ConfigRejected("MON-VER", f"receiver identifies as {info.model!r}, configured model is "
                                     f"{s.receiver_model!r}", "hwVersion")
            if model not in ("lea6t", "m8t"):
                raise ConfigRejected("MON-VER", f"unsupported receiver (hw {info.hw_version}, sw {info.sw_version})",
                                     "hwVersion")
            st.config_state = "configuring"
            profile = build_profile(model, opts)
            current_baud = getattr(self._port, "baud", None)  # after a probe, the rate that answered
            report = await apply_profile(link, profile, opts, receiver=info, current_baud=current_baud)
            st.config_report = report.to_json()
            self._append_event(self._timepulse_event(report.to_json(), opts))
            if report.ok:
                st.config_state = "verified"
            else:
                st.config_state = "failed"
                st.config_error = "; ".join(str(e) for e in report.errors)
            self._record_config(info.to_json(), report.to_json())
        except (ConfigRejected, ReceiverError, ValueError) as exc:
            st.config_state = "failed"
            st.config_error = str(exc)
            log.error("receiver configuration failed: %s", exc)
            self._record_config(None, {"ok": False, "errors": [str(exc)]})
        except (TimeoutError, OSError) as exc:
            st.config_state = "failed"
            st.config_error = f"link: {exc}"
            log.error("receiver configuration interrupted: %s", exc)

    @staticmethod
    def _timepulse_event(report: dict[str, Any], opts: Any) -> dict[str, Any]:
        """The `timepulse` record: what the receiver applied to the camera pulse (as polled back)."""
        align: int | None = None
        for msg in report.get("messages", []):
            if msg.get("name") == "CFG-TP5" and "camera" in msg.get("label", "").lower():
                value = msg.get("applied", {}).get("alignToTow")
                align = None if value is None else int(value)
        return timepulse_record(
            report.get("camera_timepulse", ""), round(opts.camera_period_s * 1e6), round(opts.pulse_len_ms * 1e3),
            bool(opts.pulse_rising), align, report.get("trigger", opts.trigger),
        )

    def _record_config(self, receiver: dict[str, Any] | None, report: dict[str, Any]) -> None:
        if self.journal is not None and not self.journal.closed:
            with self._journal_lock:
                try:
                    self.journal.set_receiver(receiver, report)
                except OSError as exc:
                    log.error("manifest write failed: %s", exc)
        if self.events is not None:
            self._append_event({"v": EVENT_FORMAT_VERSION, "kind": "config", "host_wall_ns": self.clock.wall_ns(), "receiver": receiver,
                                "ok": bool(report.get("ok")), "errors": report.get("errors", [])})

    # -- loop side: bytes → frames → decoded ------------------------------------------------------------
    def _setup_decoder(self) -> None:
        from onboard.receiver.decode import DecodeStats, decode_frame

        self._decode = decode_frame
        self._decode_stats = DecodeStats()

    def _on_bytes(self, data: bytes, rx_monotonic_ns: int) -> None:
        self._last_rx_mono_ns = rx_monotonic_ns
        st = self.status
        st.bytes_recorded += len(data)
        # No try/except here on purpose: this runs as a loop callback, so even an unexpected parser bug is
        # logged by asyncio and never reaches the reader thread, which journaled these bytes already.
        skipped_before = self._framer.skipped_bytes
        frames = self._framer.feed(data)
        st.frames += len(frames)
        st.skipped_bytes += self._framer.skipped_bytes - skipped_before
        self._frames_this_connection += len(frames)
        for feature in self.features:
            self._feature_call(feature, feature.on_bytes, data, rx_monotonic_ns)
        for frame in frames:
            self._on_frame(frame)

    def _on_frame(self, frame: Frame) -> None:
        if self._link is not None:
            self._link.feed(frame)
        if (frame.msg_class, frame.msg_id) == TIM_TM2:
            # The time mark is already in the journal: the reader thread fsyncs it after its current read
            # (≤ port.read_timeout_s), with no executor callback waking the loop per mark.
            self._mark_sync.set()
        for feature in self.features:
            self._feature_call(feature, feature.on_frame, frame)
        if self._decode is None:
            return
        item = self._decode(frame, self._decode_stats)  # never raises on content (decode.py contract)
        self.status.decode_failures = self._decode_stats.failures
        if item is not None:
            self._on_decoded(item)

    def _on_decoded(self, item: Any) -> None:
        from onboard.receiver.decode import NavFix, TimeMarks
        from onboard.rtk.types import ObsEpoch

        st = self.status
        if isinstance(item, ObsEpoch):
            # The epoch's bytes arrived (serial latency: tens of ms) at this host tick: a coarse clock anchor.
            self._gpio.set_coarse(self._last_rx_mono_ns, item.time)
            st.epochs += 1
            st.last_epoch_gpst = str(item.time)
            st.last_epoch_week = item.time.week
            st.last_epoch_tow_s = item.time.tow_s
            st.satellites = [
                SatelliteStatus(int(g), int(sv), round(float(c), 1))
                for g, sv, c in zip(item.gnss_id, item.sv_id, item.cn0_dbhz)
            ]
        elif isinstance(item, TimeMarks):
            st.time_marks += len(item.marks)
            for mark in item.marks:
                if mark.time is not None:
                    st.last_mark_gpst = str(mark.time)
            for rec in self._pairer.add(item.marks):
                self._append_event(rec)
            if self.events is not None:
                self._sync_events()
        elif isinstance(item, NavFix) and item.fix_type in (2, 3, 4):
            self._maybe_poll_aid_eph()
        for feature in self.features:
            self._feature_call(feature, feature.on_decoded, item)

    def _feature_call(self, feature: RecorderFeature, hook: Callable[..., Any], *args: Any) -> Any:
        """Call one hook of `feature`; any exception is logged (traceback the first time per feature and hook)
        and counted in `status.feature_errors`, and never reaches the recording path."""
        try:
            return hook(*args)
        except Exception as exc:  # a feature's bug must not stop recording: the raw bytes come first
            errors = self.status.feature_errors
            errors[feature.name] = errors.get(feature.name, 0) + 1
            key = (feature.name, hook.__name__)
            if key not in self._logged_feature_errors:
                self._logged_feature_errors.add(key)
                log.exception("feature %s: %s failed (counted in feature_errors; recording goes on)", *key)
            else:
                log.debug("feature %s: %s failed: %s", *key, exc)
            return None

    def _maybe_poll_aid_eph(self) -> None:
        """Backup ephemeris path (ublox.md): RXM-SFRB(X) are logged continuously; AID-EPH is polled after the
        first fix and every `aid_eph_poll_s`, so a flight whose subframes were damaged still has orbits. Only
        when we configure the receiver, and never while configuration owns the link."""
        if self._aid_eph_poll_s <= 0 or not self.settings.receiver_configure or self._link is None:
            return
        if self._config_task is not None and not self._config_task.done():
            return
        now = self.clock.monotonic_ns()
        if self._aid_eph_due_ns is not None and now < self._aid_eph_due_ns:
            return
        self._aid_eph_due_ns = now + round(self._aid_eph_poll_s * 1e9)
        self._aid_eph_task = asyncio.get_running_loop().create_task(self._poll_aid_eph())

    async def _poll_aid_eph(self) -> None:
        from onboard.receiver.ubx_tables import poll_frame

        try:
            await self._link_write(poll_frame("AID-EPH"))
            self.status.aid_eph_polls += 1
        except (LinkLost, OSError) as exc:
            log.warning("AID-EPH poll not sent: %s", exc)

    def _append_event(self, record: dict[str, Any]) -> None:
        if self.events is None:
            return
        try:
            self.events.append(record)
            self.status.events = self.events.records
        except OSError as exc:
            self._journal_error(exc)

    def _sync_events(self) -> None:
        assert self.events is not None
        try:
            self.events.sync_now()
        except OSError as exc:
            self._journal_error(exc)

    def _journal_error(self, exc: OSError) -> None:
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            self._set_state("disk_full", f"disk full while recording: {exc}")
            self.request_stop("disk full", EXIT_DISK_FULL)
        else:
            self._set_state("error", f"event log write failed: {exc}")
            self.request_stop(f"event log write failed: {exc}", EXIT_IO_ERROR)

    # -- loop side: periodic work -----------------------------------------------------------------------
    async def _status_task(self) -> None:
        s = self.settings
        last_disk_ns = 0
        while True:
            now = self.clock.monotonic_ns()
            self._gate.loop_beat(now)
            if now - last_disk_ns >= s.disk_check_interval_s * 1e9:
                last_disk_ns = now
                try:
                    self.check_disk()
                except DiskFull as exc:
                    log.error("%s: closing the flight", exc)
                    self._set_state("disk_full", f"disk full: {exc}; flight closed")
                    self.request_stop("disk full", EXIT_DISK_FULL)
                    return
                except OSError as exc:
                    log.warning("cannot read free space: %s", exc)
            for mark, tick in self._gpio.release(now):
                self._on_gpio_mark(mark, tick)
            if self.events is not None:
                try:
                    self.events.maybe_sync()
                except OSError as exc:
                    self._journal_error(exc)
            self._write_status()
            await asyncio.sleep(s.status_interval_s)

    async def _watchdog_task(self) -> None:
        notifier = self.deps.notifier
        usec = notifier.watchdog_usec
        period_s = min(1.0, usec / 2e6) if usec else 1.0
        last_text = ""
        while True:
            now = self.clock.monotonic_ns()
            self._gate.loop_beat(now)
            if usec and self._gate.should_pet(now):
                notifier.notify(WATCHDOG=1)
            text = self._status_line()
            if text != last_text:
                notifier.notify(STATUS=text)
                last_text = text
            await asyncio.sleep(period_s)

    def _status_line(self) -> str:
        st = self.status
        parts = [st.state, f"{st.bytes_recorded} B", f"{st.epochs} epochs", f"config {st.config_state}"]
        if st.port_error:
            parts.append(f"port: {st.port_error}")
        return ", ".join(parts)

    def _write_status(self) -> None:
        st = self.status
        st.updated_wall_ns = self.clock.wall_ns()
        if self.journal is not None:
            st.journal_syncs = self.journal.syncs
            seg = self.journal.current_segment
            st.segment = seg.name if seg is not None else None
        try:
            write_status(self.settings.status_path, st)
        except OSError as exc:
            log.warning("status snapshot not written: %s", exc)
        for feature in self.features:
            if feature.status_name is None:
                continue
            snapshot = self._feature_call(feature, feature.status)
            if snapshot is None:
                continue
            try:
                write_status(self.settings.status_path.with_name(feature.status_name), snapshot)
            except (OSError, TypeError, ValueError) as exc:  # a full /run, or a snapshot that is not JSON
                log.warning("%s snapshot not written: %s", feature.status_name, exc)


def _set_future(fut: asyncio.Future[None], exc: BaseException | None) -> None:
    if fut.done():
        return
    if exc is None:
        fut.set_result(None)
    else:
        fut.set_exception(exc)
