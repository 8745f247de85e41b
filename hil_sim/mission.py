"""`python -m hil_sim flight`: the whole product on one simulated survey flight, through the real code paths.

Simulated hardware in this process: the rover and base u-blox receivers on pseudo-terminals, the base
station's telemetry radio (dropouts, air budget) and an ArduCopter stand-in on a raw pty, which flies the
receivers' mission, stays disarmed until the pre-flight page says go and injects what comes out of the radio
as GPS_RTCM_DATA, as a ground station does. Real product processes: the ground server (`ground serve`, SQLite
and a generated token in the output folder), the base station (`onboard base`: RTCM3 into the radio), the rover
companion (`onboard run`: raw journal, pulse/flash pairing, autopilot link with .tlog and lifecycle events,
real-time RTK with its corrections only from GPS_RTCM_DATA) and the pre-flight page (`onboard web`). After
landing: the flight's upload to the ground server (`onboard.upload`, compared byte for byte), the ground's RTK
re-processing (a cold start) and adjustment jobs through the API, their report fetched, and RINEX conversion.
Each stage is checked against the simulator's truth; the summary says what was measured and where everything is.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from onboard.gnsstime import GpsTime

PROJECT_ROOT = Path(__file__).resolve().parents[1]


@dataclass
class StageResult:
    """What one stage of the mission produced: `ok`, a one-line summary, figures and output paths."""

    name: str
    ok: bool
    summary: str
    figures: dict[str, Any] = field(default_factory=dict)
    outputs: dict[str, str] = field(default_factory=dict)


def _wait(predicate: Callable[[], Any], timeout_s: float, what: str, poll_s: float = 0.2) -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(poll_s)
    raise TimeoutError(f"timed out after {timeout_s:.0f} s waiting for {what}")


def _status(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def _progress(label: str, done_s: float, total_s: float) -> None:
    if not sys.stderr.isatty():
        return
    frac = min(1.0, max(0.0, done_s / total_s)) if total_s > 0 else 1.0
    bar = "#" * int(frac * 30)
    sys.stderr.write(f"\r{label} [{bar:<30}] {done_s:6.0f}/{total_s:.0f} s simulated")
    sys.stderr.flush()
    if frac >= 1.0:
        sys.stderr.write("\n")


def _free_tcp_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _popen(cmd: list[str], log_path: Path) -> subprocess.Popen[bytes]:
    """A product command as a child process (this tree on PYTHONPATH, no systemd socket), logging to `log_path`."""
    env = dict(os.environ, PYTHONPATH=str(PROJECT_ROOT))
    env.pop("NOTIFY_SOCKET", None)
    log_file = open(log_path, "wb")  # noqa: SIM115 - handed to the child process
    return subprocess.Popen([sys.executable, *cmd], cwd=PROJECT_ROOT, env=env, stdout=log_file,
                            stderr=subprocess.STDOUT)


def _recorder_config(out: Path, name: str, camera_period_s: float, meas_rate_ms: int, extra: str = "") -> Path:
    cfg = out / f"{name}.toml"
    cfg.write_text(
        "# written by python -m hil_sim flight\n"
        f'[receiver]\ncamera_period_s = {camera_period_s}\ntrigger = "extint1"\nmeas_rate_ms = {meas_rate_ms}\n'
        "[journal]\ndisk_floor_mb = 50.0\n[status]\ninterval_s = 0.5\n" + extra
    )
    return cfg


def _start_recorder(name: str, port: str, out: Path, camera_period_s: float, meas_rate_ms: int,
                    extra_config: str = "", base_args: list[str] | None = None,
                    ) -> tuple[subprocess.Popen[bytes], Path, Path]:
    """The real recorder daemon on `port`: `onboard run` (the drone), or `onboard base BASE_ARGS` (the base
    station: the same recorder plus the RTCM3 sender)."""
    cfg = _recorder_config(out, name, camera_period_s, meas_rate_ms, extra_config)
    data_dir, status_path = out / name, out / f"{name}-status.json"
    command = ["-m", "onboard", "run"] if base_args is None else ["-m", "onboard", "base", *base_args]
    proc = _popen([*command, "--config", str(cfg), "--port", port, "--baud", "115200", "--data-dir", str(data_dir),
                   "--status", str(status_path)], out / f"{name}-recorder.log")
    return proc, data_dir, status_path


def _stop(proc: subprocess.Popen[bytes], timeout_s: float = 30.0) -> int:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return int(proc.returncode)


def _ground_token(data_dir: Path, role: str, name: str, token_file: Path) -> str:
    """A `role` token made by `python -m ground token create` (its stdout is the token), kept in `token_file`
    (mode 0600)."""
    from onboard.formats.atomic import write_atomic

    made = subprocess.run([sys.executable, "-m", "ground", "token", "create", "--role", role, "--name", name,
                           "--data-dir", str(data_dir)], cwd=PROJECT_ROOT, capture_output=True, text=True,
                          timeout=120, check=True, env=dict(os.environ, PYTHONPATH=str(PROJECT_ROOT)))
    token = made.stdout.strip()
    write_atomic(token_file, token + "\n")
    token_file.chmod(0o600)
    return token


class GroundServer:
    """`python -m ground serve` on a free local port: SQLite and flight files in `data_dir`, a generated
    bootstrap (admin) token in `token_file`, a drone token for the companion in `drone_token_file` and an
    engineer token for the office's reads and jobs in `engineer_token_file` (mode 0600)."""

    def __init__(self, out: Path) -> None:
        import secrets

        from onboard.formats.atomic import write_atomic

        self.data_dir = out / "ground-server"
        self.token_file = out / "ground-token"
        self.token = secrets.token_urlsafe(32)
        write_atomic(self.token_file, self.token + "\n")
        self.token_file.chmod(0o600)
        self.drone_token_file, self.engineer_token_file = out / "drone-token", out / "engineer-token"
        _ground_token(self.data_dir, "drone", "companion", self.drone_token_file)
        self.engineer_token = _ground_token(self.data_dir, "engineer", "office", self.engineer_token_file)
        self.port = _free_tcp_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.proc = _popen(["-m", "ground", "serve", "--host", "127.0.0.1", "--port", str(self.port), "--data-dir",
                            str(self.data_dir), "--token-file", str(self.token_file)], out / "ground-server.log")
        self.log = out / "ground-server.log"

    def client(self) -> Any:
        import httpx

        return httpx.Client(base_url=self.url, headers={"Authorization": f"Bearer {self.engineer_token}"},
                            timeout=60.0)

    def wait_ready(self, timeout_s: float = 60.0) -> None:
        import httpx

        def up() -> bool:
            if self.proc.poll() is not None:
                raise RuntimeError(f"ground serve exited with {self.proc.returncode} (see {self.log})")
            try:
                return httpx.get(f"{self.url}/health", timeout=2.0).status_code == 200
            except httpx.HTTPError:
                return False

        _wait(up, timeout_s, "the ground server")

    def stop(self) -> int:
        return _stop(self.proc)


def _preflight(url: str) -> dict[str, Any]:
    import httpx

    try:
        return dict(httpx.get(url, timeout=2.0).json())
    except (httpx.HTTPError, ValueError):
        return {}


SETTLE_S = 3.0
"""The demo's `autopilot.settle_s` (wall s): the companion closes the flight this long after the disarm."""


def record_flight(args: argparse.Namespace, out: Path, standin_options: Any = None, radio_options: Any = None,
                  server: GroundServer | None = None) -> tuple[list[StageResult], dict[str, Any]]:
    """Stage 1: the system on the ground and in the air.

    Simulated hardware (this process): the rover and base receivers on ptys, the base station's radio (two
    ptys with dropouts), and the autopilot stand-in on a raw pty, flying the receivers' mission on their clock,
    held disarmed until the pre-flight page says go, and injecting as GPS_RTCM_DATA what comes out of the radio
    (a ground station on the base's radio, as Mission Planner / QGroundControl do).
    Real product processes: the base station (`onboard base`, RTCM3 1004/1006/1019 into the radio), the rover
    companion (`onboard run`, real-time RTK with `rtk.base_stream = "mavlink"` and the autopilot link), the
    pre-flight page (`onboard web`), read over HTTP until its overall state is "ok".
    `standin_options` (`hil_sim.autopilot.AutopilotSimOptions`, e.g. with dropped fragments or extra RTCM
    messages) and `radio_options` (`hil_sim.radio.RadioOptions`) replace the defaults; the go gate stays on.
    With a `server`, the companion closes the flight itself after landing (disarmed and on the ground for
    `SETTLE_S`) and its upload daemon (`onboard upload-daemon`) sends the closed flight to the server; the stage
    waits for both and times the upload from the close.
    """
    from hil_sim.autopilot import AutopilotSim, AutopilotSimOptions, MissionFlight
    from hil_sim.pty_server import ReceiverEmulator
    from hil_sim.radio import RadioLink, RadioOptions
    from hil_sim.receiver import ReceiverOptions
    from hil_sim.scenario import CameraPlan, FlightPlan, Scenario
    from hil_sim.world import World
    from onboard.hw.net_stream import open_base_stream

    camera = CameraPlan(period_s=args.camera_period, valid_after_s=20.0,
                        missed_flash_probability=args.missed_flash, bounce_probability=args.bounce)
    scenario = Scenario.default(model=args.model, seed=args.seed, camera=camera,
                                flight=FlightPlan(static_s=args.ground_s))
    world = World(scenario)
    flight_s = world.trajectory.duration_s + 10.0
    if args.flight_s:
        flight_s = min(flight_s, args.flight_s)
    opts = ReceiverOptions(trigger_extint=True, time_valid_after_s=camera.valid_after_s)
    rover = ReceiverEmulator(args.model, opts, world, speed=args.speed, receiver="rover")
    base = ReceiverEmulator(args.model, opts, world, speed=args.speed, receiver="base")
    radio = RadioLink(radio_options or RadioOptions(mean_interval_s=args.radio_gap_interval, seed=args.seed),
                      speed=args.speed)
    t0 = scenario.start

    def sim_s() -> float:
        return rover.sim_time().diff_s(t0)

    mission = MissionFlight(scenario)
    options = dataclasses.replace(standin_options or AutopilotSimOptions(seed=args.seed), hold_until_go=True)
    standin = AutopilotSim(options, speed=args.speed,
                           flight=mission, time_source=sim_s, report_path=out / "autopilot-standin.json")
    procs: dict[str, subprocess.Popen[bytes]] = {}
    dirs: dict[str, Path] = {}
    statuses: dict[str, Path] = {}
    meas_rate_ms = 1000 if args.model == "lea6t" else 500
    web_port = _free_tcp_port()
    preflight_url = f"http://127.0.0.1:{web_port}/api/preflight"
    go: dict[str, Any] = {"url": preflight_url, "arm_planned_s": mission.arm_s}
    base_pos = ",".join(f"{v:.4f}" for v in world.base_ecef_m)
    try:
        rover_port, base_port = rover.start(), base.start()
        radio_tx, radio_rx = radio.start()
        standin.rtcm_stream = open_base_stream(f"serial:{radio_rx}@57600")
        autopilot_port = standin.start()
        procs["base"], dirs["base"], statuses["base"] = _start_recorder(
            "base", base_port, out, args.camera_period, meas_rate_ms,
            base_args=["--radio", radio_tx, "--radio-baud", "57600", "--position", base_pos])
        procs["rover"], dirs["rover"], statuses["rover"] = _start_recorder(
            "rover", rover_port, out, args.camera_period, meas_rate_ms,
            extra_config=f'[rtk]\nbase_stream = "mavlink"\n[autopilot]\nlink = "serial:{autopilot_port}@921600"\n'
                         f"settle_s = {SETTLE_S}\n" + ("" if server is None else
                         f'[upload]\nurl = "{server.url}"\ntoken_file = "{server.drone_token_file}"\npoll_s = 0.5\n'))
        if server is not None:
            # the drone's automatic upload, a process of its own as on the Pi (directgeo-upload.service)
            procs["upload"] = _popen(["-m", "onboard", "upload-daemon", "--config", str(out / "rover.toml"),
                                      "--data-dir", str(dirs["rover"]), "--status", str(statuses["rover"])],
                                     out / "rover-upload.log")
        procs["web"] = _popen(["-m", "onboard", "web", "--status", str(statuses["rover"]), "--host", "127.0.0.1",
                               "--port", str(web_port)], out / "preflight-web.log")
        for name in ("rover", "base"):
            def configured(n: str = name) -> bool:
                return _status(statuses[n]).get("config_state") in ("verified", "failed")

            _wait(configured, 90, f"{name} receiver configuration")
        next_poll = 0.0
        while (done := sim_s()) < flight_s:
            _progress("flying", done, flight_s)
            for name, proc in procs.items():
                if proc.poll() is not None:
                    raise RuntimeError(f"the {name} process exited early (see {out}/{name}*.log)")
            if "go_s" not in go and time.monotonic() >= next_poll:
                # The go/no-go: the pre-flight page's verdict ("ok" = go), as the pilot reads its top line.
                next_poll = time.monotonic() + 0.5
                page = _preflight(preflight_url)
                if page.get("overall") == "ok":
                    standin.give_go()
                    go.update(go_s=round(done, 1), checks=page.get("checks"), headline=page.get("headline"))
                elif page:
                    go["last_no_go"] = [f"{c['name']}: {c['detail']}" for c in page.get("checks", [])
                                        if c.get("level") != "ok"]
            if standin.error is not None:
                raise RuntimeError(f"the autopilot stand-in failed: {standin.error}")
            time.sleep(0.2)
        _progress("flying", flight_s, flight_s)
        end = rover.sim_time()
        if server is not None:
            auto = _wait_close_and_upload(statuses["rover"], procs, 120.0)
            go["auto_upload"] = auto
    finally:
        # the upload daemon first (it would upload the flight the companion closes at SIGTERM too)
        codes = {name: _stop(procs.pop(name)) for name in ("upload",) if name in procs}
        codes |= {name: _stop(p) for name, p in procs.items()}
        standin.stop()
        radio.stop()
        rover.stop()
        base.stop()
    stages = [_recording_result(name, dirs[name], statuses[name], codes.get(name, -1)) for name in ("rover", "base")]
    stages.append(_go_result(go, standin.report()))
    ch = radio.channel
    radio_figures = {"bytes_in": ch.bytes_in, "bytes_out": ch.bytes_out, "lost_in_dropouts": ch.bytes_lost_dropout,
                     "lost_over_budget": ch.bytes_lost_budget}
    return stages, {"world": world, "scenario": scenario, "start": scenario.start, "end": end, "dirs": dirs,
                    "statuses": statuses, "radio": radio_figures, "standin": standin.report(), "go": go}


def _wait_close_and_upload(status_path: Path, procs: dict[str, subprocess.Popen[bytes]],
                           timeout_s: float) -> dict[str, Any]:
    """Wait until the companion has closed the flight by itself (autopilot.json `flights_closed`) and its upload
    daemon reports it uploaded (upload.json `done`); returns the wall times (s) of both from the call."""
    t0 = time.monotonic()
    autopilot_json, upload_json = status_path.with_name("autopilot.json"), status_path.with_name("upload.json")
    times: dict[str, Any] = {}

    def closed_and_uploaded() -> bool:
        for name, proc in procs.items():
            if proc.poll() is not None:
                raise RuntimeError(f"the {name} process exited early (exit {proc.returncode})")
        if "closed_s" not in times and int(_status(autopilot_json).get("flights_closed") or 0) >= 1:
            times["closed_s"] = round(time.monotonic() - t0, 2)
        up = _status(upload_json)
        if "closed_s" in times and int(up.get("done") or 0) >= 1:
            times["uploaded_s"] = round(time.monotonic() - t0, 2)
            times["upload"] = {k: up.get(k) for k in ("done", "queued", "last_result", "last_error", "bytes_sent")}
            return True
        return False

    _wait(closed_and_uploaded, timeout_s, "the companion to close the flight and upload it by itself")
    return times


def _go_result(go: dict[str, Any], standin: dict[str, Any]) -> StageResult:
    """The pre-flight go: when the page said "ok" against when the mission arms."""
    arm = float(go["arm_planned_s"])
    if "go_s" not in go:
        return StageResult("pre-flight go", False, "the pre-flight page never said go: the autopilot stayed "
                           f"disarmed (last no-go: {'; '.join(go.get('last_no_go', [])) or 'page unreachable'})",
                           {"arm_planned_s": arm}, {"preflight": go["url"]})
    late = standin.get("go_late_s") or 0.0
    ok = late == 0.0
    summary = (f"go at {go['go_s']:.0f} s (mission arms at {arm:.0f} s"
               + (")" if ok else f", go {late:.0f} s late: the receivers' world took off without it)")
               + f": {', '.join(c['name'] for c in go.get('checks') or [])} all ok")
    return StageResult("pre-flight go", ok, summary, {"go_s": go["go_s"], "arm_planned_s": arm, "go_late_s": late},
                       {"preflight": go["url"].removesuffix("api/preflight")})


def _recording_result(name: str, data_dir: Path, status_path: Path, code: int) -> StageResult:
    from onboard.logger.check import check_flight
    from onboard.logger.journal import read_manifest
    from onboard.receiver.decode import iter_journal
    from onboard.recorder.feature import is_rollover
    from onboard.rtk.types import ObsEpoch

    st = _status(status_path)
    flights = sorted(data_dir.glob("flight-*"))
    if not flights:
        return StageResult(f"record {name}", False, f"no flight directory under {data_dir}")
    # the flight the companion closed by itself after landing (recording went on into a next one), else the last
    manifests = {f: read_manifest(f) for f in flights}
    flown = [f for f, m in manifests.items() if m is not None and m.close_reason and is_rollover(m.close_reason)]
    flight = flown[0] if flown else flights[-1]
    manifest = manifests[flight]
    # what `onboard check` reports: segment sizes and SHA-256 against the manifest, index, event log
    problems = check_flight(flight).problems
    epochs = sum(isinstance(e, ObsEpoch) for e in iter_journal(flight))
    figures = {
        "receiver": f"{st.get('receiver_model')} {st.get('receiver_sw_version')}",
        "configuration": st.get("config_state"), "config_error": st.get("config_error"),
        "segments": len(manifest.segments) if manifest else 0,
        "bytes": st.get("bytes_recorded"), "frames": st.get("frames"), "raw_epochs": epochs,
        "time_marks": st.get("time_marks"), "daemon_exit_code": code, "manifest_problems": problems,
    }
    ok = code == 0 and st.get("config_state") == "verified" and epochs > 0 and not problems
    summary = (f"{figures['receiver']}, configuration {figures['configuration']}, {epochs} raw epochs, "
               f"{figures['bytes']} bytes in {figures['segments']} segment(s), onboard check "
               f"{'passed (SHA-256 verified)' if not problems else 'FAILED: ' + '; '.join(problems)}")
    return StageResult(f"record {name}", ok, summary, figures, {"flight": str(flight)})


def check_pairing(rover_flight: Path, ctx: dict[str, Any]) -> StageResult:
    """Stage 2: every simulated camera event paired (or flagged) in events.jsonl, delays vs truth."""
    from onboard.logger.events import read_events
    from onboard.timepulse.marks import parse_records

    world, start, end = ctx["world"], ctx["start"], ctx["end"]
    _marks, pairings, _other = parse_records(read_events(rover_flight / "events.jsonl").records)
    with_pulse = [p for p in pairings if p.pulse_time is not None]
    if not with_pulse:
        return StageResult("pair pulses and flashes", False, "no trigger pulse recorded")
    first = min(p.pulse_time.total_ns for p in with_pulse)  # type: ignore[union-attr]
    last = max(p.pulse_time.total_ns for p in with_pulse)  # type: ignore[union-attr]
    truth = [ev for ev in world.camera_events(start, end) if first - 10**6 <= ev.pulse_time.total_ns <= last + 10**6]
    by_pulse = {round(p.pulse_time.total_ns / 1e6): p for p in with_pulse}  # type: ignore[union-attr]
    errors_ns, measured_ns, true_ns, missing, flagged, clean = [], [], [], 0, 0, 0
    for ev in truth:
        p = by_pulse.get(round(ev.pulse_time.total_ns / 1e6))
        if p is None:
            missing += 1
        elif p.flags:
            flagged += 1
        elif p.delay_ns is not None and ev.delay_s is not None:
            clean += 1
            errors_ns.append(abs(p.delay_ns - round(ev.delay_s * 1e9)))
            measured_ns.append(p.delay_ns)
            true_ns.append(round(ev.delay_s * 1e9))
    worst = max(errors_ns) if errors_ns else None
    ok = missing == 0 and clean > 0 and worst is not None and worst <= 1000
    figures = {"camera_events": len(truth), "paired": clean, "flagged": flagged, "missing": missing,
               "max_delay_error_ns": worst,
               "mean_delay_ms": sum(measured_ns) / max(1, clean) / 1e6,
               "true_mean_delay_ms": sum(true_ns) / max(1, clean) / 1e6}
    summary = (f"{clean} images with a measured shutter delay, mean {figures['mean_delay_ms']:.3f} ms (simulated "
               f"{figures['true_mean_delay_ms']:.3f} ms), worst error vs simulator {worst} ns; {flagged} flagged (missed/bounced "
               f"flash), {missing} pulses not recorded")
    return StageResult("pair pulses and flashes", ok, summary, figures, {"events": str(rover_flight / "events.jsonl")})


def convert_rinex(flight: Path, out: Path) -> StageResult:
    """Stage 3: the flight's journal to RINEX 3.04 with the real `onboard convert` command."""
    rinex = out / "rinex"
    proc = subprocess.run([sys.executable, "-m", "onboard", "convert", str(flight), "-o", str(rinex)],
                          cwd=PROJECT_ROOT, capture_output=True, text=True, timeout=300, check=False)
    files = sorted(str(p) for p in rinex.glob("*")) if rinex.exists() else []
    ok = proc.returncode == 0 and any(f.endswith(".obs") for f in files)
    summary = (proc.stdout.strip().splitlines() or [proc.stderr.strip()[-300:]])[-1] if proc.stdout or proc.stderr else ""
    return StageResult("RINEX conversion", ok, summary, {"files": len(files)}, {"rinex": str(rinex)})


def _segment(flight: Path) -> Path:
    segments = sorted(flight.glob("*.ubx"))
    if len(segments) == 1:
        return segments[0]
    joined = flight.parent / f"{flight.name}.ubx"  # several segments: the same bytes, concatenated in order
    with open(joined, "wb") as dst:
        dst.writelines(seg.read_bytes() for seg in segments)
    return joined


RTK_COLD = "post-processed RTK (ground job, cold start)"
"""Stage name of the ground's re-processing, a cold start: what a user gets (no position known before the first
fix)."""
RTK_SEEDED = "RTK seeded with the surveyed take-off point (simulator truth)"
"""Stage name of the second run, started from the take-off point as a surveyor would measure it (here: exact)."""


def process_rtk(rover: Path, base: Path, out: Path, ctx: dict[str, Any], seeded: bool = False) -> StageResult:
    """Stage 4: post-processed fix-and-hold RTK of the rover journal against the base journal, vs truth.

    A cold start by default: the engine is given the base position and that the drone stands still before
    take-off, nothing else. `seeded` adds the take-off point as `--init-pos` (a surveyed start, Daakir 2015:
    ambiguities computed from a known position); here it is the simulator's exact truth, so it is the best case.
    """
    world = ctx["world"]
    name = RTK_SEEDED if seeded else RTK_COLD
    pos_path = out / ("rover-seeded.pos" if seeded else "rover.pos")
    base_pos = ",".join(f"{v:.4f}" for v in world.base_ecef_m)
    seed_args: list[str] = []
    if seeded:
        init_pos = ",".join(f"{v:.4f}" for v in world.truth(ctx["start"])["antenna_ecef_m"])
        seed_args = [f"--init-pos={init_pos}"]
    proc = subprocess.run(
        [sys.executable, "-m", "onboard", "rtk", "--rover", str(_segment(rover)), "--base", str(_segment(base)),
         f"--base-pos={base_pos}", *seed_args, "--static-start", "--velocity", "--no-progress", "-o", str(pos_path)],
        cwd=PROJECT_ROOT, capture_output=True, text=True, timeout=900, check=False)
    if proc.returncode != 0 or not pos_path.exists():
        return StageResult(name, False, f"onboard rtk failed: {proc.stderr.strip()[-400:]}")
    figures, summary = track_figures(pos_path, world)
    return StageResult(name, figures["epochs"] > 0 and figures["wrong_fixes"] == 0, summary, figures,
                       {"trajectory": str(pos_path)})


WRONG_FIX_M = 0.10
"""A fixed epoch farther than this from the truth (3D, m) is a wrong fix."""


def track_figures(pos_path: Path, world: Any, t_first: GpsTime | None = None) -> tuple[dict[str, Any], str]:
    """Fix ratio, fixed-epoch 3D RMS and worst error against the simulator's truth, wrong fixes (> 10 cm),
    first fix (s after `t_first`, default the first solution) and the airborne fix ratio, of a .pos file."""
    import numpy as np

    from onboard.formats.pos import read_pos

    track = read_pos(pos_path)
    q = np.asarray(track.q)
    times = list(track.time)
    n = len(q)
    if n == 0:
        return {"epochs": 0, "fix_ratio": 0.0, "wrong_fixes": 0}, "no solution"
    truth = np.array([world.truth(t)["antenna_ecef_m"] for t in times])
    err = np.linalg.norm(np.asarray(track.pos_ecef_m) - truth, axis=1)
    fixed = q == 1
    airborne = np.array([world.trajectory.state_at_s(t.diff_s(world.scenario.start)).phase != "ground"
                         for t in times])
    wrong = int(np.sum(fixed & (err > WRONG_FIX_M)))
    rms = float(np.sqrt(np.mean(err[fixed] ** 2))) if fixed.any() else float("nan")
    worst = float(err[fixed].max()) if fixed.any() else float("nan")
    ref = t_first or times[0]
    first_fix = next((times[i].diff_s(ref) for i in range(n) if fixed[i]), None)
    figures = {"epochs": n, "fix_ratio": float(fixed.mean()), "fixed_3d_rms_m": rms, "fixed_3d_max_m": worst,
               "wrong_fixes": wrong, "first_fix_s": first_fix,
               "airborne_epochs": int(airborne.sum()),
               "airborne_fix_ratio": float(fixed[airborne].mean()) if airborne.any() else None}
    air = "" if not airborne.any() else f" ({100 * float(fixed[airborne].mean()):.1f} % of {int(airborne.sum())} airborne)"
    summary = (f"{n} epochs, {100 * float(fixed.mean()):.1f} % fixed{air}, fixed-epoch 3D RMS vs truth "
               f"{100 * rms:.1f} cm (worst {100 * worst:.1f} cm), {wrong} wrong fixes (> 10 cm), first fix after "
               f"{'never' if first_fix is None else f'{first_fix:.0f} s'}")
    return figures, summary


def simulate_block(rover: Path, out: Path, ctx: dict[str, Any], seed: int) -> dict[str, Path]:
    """The photogrammetric block a bundle adjustment would return for the photos of this flight.

    Camera centres and rotations at each flash (exposure) in an arbitrary relative frame (random similarity of
    the local ENU frame) with 1 cm / 0.01° noise, written as COLMAP images.txt; one GCP and check points on the
    ground (CSV name,role,x_rel,y_rel,z_rel,X,Y,Z with ECEF ground coordinates); the camera's capture times
    (whole seconds, like EXIF) so the ground app matches photos to the event log.
    """
    import numpy as np
    from scipy.spatial.transform import Rotation

    from onboard.logger.events import read_events
    from onboard.rtk.geodesy import enu_to_ecef
    from onboard.timepulse.marks import parse_records

    world = ctx["world"]
    rng = np.random.default_rng(seed + 1000)
    scale = float(rng.uniform(0.3, 3.0))
    rot = Rotation.random(random_state=int(rng.integers(1 << 31))).as_matrix()
    shift = rng.normal(0.0, 50.0, 3)
    origin = world.truth(ctx["start"])["enu_origin_ecef_m"]

    def to_rel(enu: np.ndarray) -> np.ndarray:
        return scale * (rot @ enu) + shift

    _m, pairings, _o = parse_records(read_events(rover / "events.jsonl").records)
    flashes = [p for p in pairings if p.flash_time is not None]
    lines, captures = [], ["image,capture_time"]
    for k, p in enumerate(flashes, start=1):
        assert p.flash_time is not None
        name = f"IMG_{k:04d}.JPG"
        tr = world.truth(p.flash_time)
        c_rel = to_rel(tr["camera_enu_m"] + rng.normal(0.0, 0.01, 3))
        wobble = Rotation.from_rotvec(rng.normal(0.0, np.radians(0.01), 3)).as_matrix()
        r_cam_to_rel = rot @ wobble @ tr["r_cam_to_enu"]
        r_rel_to_cam = r_cam_to_rel.T
        qx, qy, qz, qw = Rotation.from_matrix(r_rel_to_cam).as_quat()
        tx, ty, tz = -r_rel_to_cam @ c_rel
        lines.append(f"{k} {qw:.12f} {qx:.12f} {qy:.12f} {qz:.12f} {tx:.6f} {ty:.6f} {tz:.6f} 1 {name}\n")
        utc = p.flash_time.to_utc()
        captures.append(f"{name},{utc.replace(microsecond=0).isoformat()}")
    images = out / "block" / "images.txt"
    images.parent.mkdir(parents=True, exist_ok=True)
    images.write_text("# simulated bundle adjustment (hil_sim): IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME\n"
                      + "".join(lines))
    capture = out / "block" / "capture_times.csv"
    capture.write_text("\n".join(captures) + "\n")
    gcp_rows = ["name,role,x_rel,y_rel,z_rel,X,Y,Z"]
    flight_s = ctx["end"].diff_s(ctx["start"])
    for j in range(7):
        # ground points under the survey lines (the drone's ground track), a few metres of relief
        above = world.truth(ctx["start"].add_s(float(rng.uniform(0.3, 0.9)) * flight_s))["antenna_enu_m"]
        enu = np.array([above[0] + rng.uniform(-10, 10), above[1] + rng.uniform(-10, 10), rng.uniform(-1.0, 3.0)])
        rel = to_rel(enu + rng.normal(0.0, 0.01, 3))
        ecef = enu_to_ecef(enu, origin)
        gcp_rows.append(f"P{j + 1},{'gcp' if j == 0 else 'check'},{rel[0]:.5f},{rel[1]:.5f},{rel[2]:.5f},"
                        f"{ecef[0]:.4f},{ecef[1]:.4f},{ecef[2]:.4f}")
    gcp = out / "block" / "gcp.csv"
    gcp.write_text("\n".join(gcp_rows) + "\n")
    return {"images": images, "capture_times": capture, "gcp": gcp}


def realtime_rtk(rover: Path, ctx: dict[str, Any]) -> StageResult:
    """The rover companion's real-time RTK (`<flight>/solution.pos`, corrections only through the autopilot's
    GPS_RTCM_DATA) against the simulator's truth: a cold start, as a user gets it."""
    pos = rover / "solution.pos"
    # rtk.json describes the flight being recorded: after the automatic close that is the next one
    rolled_over = bool(ctx.get("go", {}).get("auto_upload"))
    rtk = {} if rolled_over else _status(ctx["statuses"]["rover"].with_name("rtk.json"))
    if not pos.exists():
        return StageResult("real-time RTK (onboard, corrections over MAVLink)", False, f"no {pos}")
    figures, summary = track_figures(pos, ctx["world"])
    figures.update(rtk_epochs=rtk.get("epochs"), base_epochs=rtk.get("base_epochs"),
                   corrections_bytes=rtk.get("radio_bytes"), ttff_s=rtk.get("ttff_s"),
                   dropped_epochs=rtk.get("dropped_epochs"), engine_ms_max=rtk.get("engine_ms_max"))
    ok = figures["epochs"] > 0 and figures["wrong_fixes"] == 0 and figures["fix_ratio"] > 0
    return StageResult("real-time RTK (onboard, corrections over MAVLink)", ok,
                       summary + ("" if rolled_over else f"; {rtk.get('base_epochs')} base epochs received"), figures,
                       {"solution": str(pos), "corrections_journal": str(rover / "radio")})


def corrections_chain(rover: Path, base: Path, ctx: dict[str, Any]) -> StageResult:
    """Base station → radio → ground station inject → GPS_RTCM_DATA → companion: bytes at each hop."""
    from onboard.logger.journal import iter_journal_bytes
    from onboard.receiver.framing import StreamFramer

    sent = b"".join(p.read_bytes() for p in sorted(base.glob("radio-tx.rtcm3")))
    got = b"".join(iter_journal_bytes(rover / "radio")) if (rover / "radio").exists() else b""
    framer = StreamFramer()
    sent_msgs = {bytes(f.raw) for f in framer.feed(sent)}
    framer = StreamFramer()
    got_msgs = [bytes(f.raw) for f in framer.feed(got)]
    foreign = sum(m not in sent_msgs for m in got_msgs)  # a message the base never sent: must be none
    live = ctx["standin"].get("rtcm_live", {})
    ap = _status(ctx["statuses"]["rover"].with_name("autopilot.json")).get("rtcm", {})
    figures = {"base_sent_bytes": len(sent), "radio": ctx["radio"], "injected_messages": live.get("messages"),
               "injected_fragments": ctx["standin"].get("rtcm_fragments"),
               "reassembled_messages": ap.get("messages"), "reassembly_dropped": ap.get("dropped"),
               "companion_bytes": len(got), "companion_messages": len(got_msgs), "foreign_messages": foreign}
    ok = len(got_msgs) > 0 and foreign == 0
    summary = (f"base sent {len(sent)} B; radio passed {ctx['radio']['bytes_out']} B "
               f"({ctx['radio']['lost_in_dropouts']} B lost in dropouts); the ground station injected "
               f"{live.get('messages')} messages as {ctx['standin'].get('rtcm_fragments')} GPS_RTCM_DATA; the "
               f"companion reassembled {len(got_msgs)} ({len(got)} B), {foreign} not sent by the base")
    return StageResult("corrections: base → radio → GPS_RTCM_DATA → companion", ok, summary, figures,
                       {"base_sent": str(base / "radio-tx.rtcm3")})


def autopilot_events(rover: Path, ctx: dict[str, Any]) -> StageResult:
    """The autopilot link: lifecycle events in events.jsonl (GPS time) and the .tlog."""
    from onboard.logger.events import read_events

    events = [r for r in read_events(rover / "events.jsonl").records if r.get("type") == "autopilot"]
    names = [e.get("event") for e in events]
    snap = _status(ctx["statuses"]["rover"].with_name("autopilot.json"))
    start = ctx["start"]
    at = {e["event"]: (e["gps_week"] * 604800 + e["gps_tow_ns"] / 1e9) - (start.week * 604800 + start.tow_s)
          for e in events if isinstance(e.get("gps_week"), int)}
    truth = {"takeoff": ctx["world"].trajectory.takeoff_s, "landed": ctx["world"].trajectory.landing_s}
    # flight_over: the companion closed the flight by itself after the settle time (the demo's automatic close)
    ok = names[:4] == ["armed", "takeoff", "landed", "disarmed"] and names[4:] in ([], ["flight_over"])
    tlog = rover / "autopilot.tlog"
    tlog_bytes = tlog.stat().st_size if tlog.exists() else 0  # autopilot.json describes the current flight
    listed = ", ".join(f"{n} at {at.get(n, float('nan')):.0f} s" for n in names)
    summary = (f"events {listed} "
               f"(mission: take-off {truth['takeoff']:.0f} s, touchdown {truth['landed']:.0f} s); "
               f"{tlog_bytes} B of .tlog, {snap.get('camera_feedback')} CAMERA_FEEDBACK, packet loss "
               f"{snap.get('packet_loss')}")
    return StageResult("autopilot link", ok, summary, {"events": at, "truth_s": truth, "tlog_bytes": tlog_bytes,
                                                       "camera_feedback": snap.get("camera_feedback")},
                       {"tlog": str(rover / "autopilot.tlog")})


def _server_flight(client: Any, name: str) -> dict[str, Any] | None:
    for f in client.get("/flights").json():
        if f["name"] == name:
            return dict(client.get(f"/flights/{f['id']}").json())
    return None


def _run_uploader(server: GroundServer, folder: Path, roles: dict[str, str] | None = None,
                  token_file: Path | None = None) -> subprocess.CompletedProcess[str]:
    """`python -m onboard.upload` of `folder` to `server` (file roles as NAME=ROLE) with `token_file` (default:
    the companion's drone token), output captured."""
    return subprocess.run([sys.executable, "-m", "onboard.upload", "--url", server.url, "--token-file",
                           str(token_file or server.drone_token_file), *(f"--role={k}={v}" for k, v in (roles or {}).items()),
                           str(folder)], cwd=PROJECT_ROOT, capture_output=True, text=True, timeout=300,
                          check=False, env=dict(os.environ, PYTHONPATH=str(PROJECT_ROOT)))


def upload_flight(rover: Path, server: GroundServer, auto: dict[str, Any] | None = None) -> StageResult:
    """The closed flight on the ground server, compared byte for byte with the drone's files. With `auto` (what
    `record_flight` saw: the companion closed the flight after landing and its upload daemon sent it, no command
    run) only the comparison is made; without it the flight is sent here with the real uploader."""
    import hashlib

    local = {p.name: p for p in rover.iterdir() if p.is_file() and not p.name.startswith(".")}
    size = sum(p.stat().st_size for p in local.values())
    if auto is not None:
        wall_s = float(auto["uploaded_s"]) - float(auto["closed_s"])
        how = "by the companion's upload daemon after it closed the flight, no command run"
    else:
        t = time.monotonic()
        proc = _run_uploader(server, rover)
        wall_s = time.monotonic() - t
        how = "uploader process included"
        if proc.returncode != 0:
            return StageResult("upload", False, f"uploader failed: {proc.stderr.strip()[-400:]}")
    wall_s = max(wall_s, 1e-3)
    from onboard.logger.journal import read_manifest

    manifest = read_manifest(rover)
    with server.client() as client:
        flight = _server_flight(client, manifest.flight if manifest else rover.name)
    if flight is None:
        return StageResult("upload", False, "the server does not list the flight")
    held = server.data_dir / "flights" / flight["id"]
    differ = [n for n, p in local.items() if not (held / n).is_file()
              or hashlib.sha256((held / n).read_bytes()).digest() != hashlib.sha256(p.read_bytes()).digest()]
    ok = not differ and flight["status"] == "complete"
    figures = {"automatic": auto is not None, "closed_after_s": None if auto is None else auto["closed_s"],
               "files": len(local), "bytes": size, "wall_s": wall_s, "throughput_mb_s": size / 1e6 / wall_s,
               "server_flight_id": flight["id"], "differ": differ}
    summary = (f"{len(local)} files, {size / 1e6:.2f} MB in {wall_s:.1f} s after the close ({how}); on the "
               f"server: "
               + ("every file byte-identical" if not differ else f"DIFFERENT: {', '.join(differ)}"))
    return StageResult("upload", ok, summary, figures, {"server_files": str(held)})


def _poll_job(client: Any, flight_id: str, job_id: str, timeout_s: float = 600.0) -> dict[str, Any]:
    def finished() -> dict[str, Any] | None:
        job = client.get(f"/flights/{flight_id}/jobs/{job_id}").json()
        return job if job["status"] in ("done", "failed") else None

    return dict(_wait(finished, timeout_s, f"ground job {job_id}", poll_s=0.5))


def ground_processing(rover: Path, base: Path, out: Path, ctx: dict[str, Any], server: GroundServer,
                      seed: int) -> list[StageResult]:
    """The office's part through the ground API: the rover journal and events of the flight, the base
    station's journal and the photogrammetric block uploaded as one processing set (the API has no way to add
    files to the drone's flight), then the RTK re-processing job (cold start) and the adjustment job on its
    trajectory; results.json and report.html fetched from the server."""
    import numpy as np

    world = ctx["world"]
    office = out / f"{rover.name}-processing"
    office.mkdir(exist_ok=True)
    block = simulate_block(rover, out, ctx, seed)
    files = {"rover.ubx": _segment(rover), "base.ubx": _segment(base), "events.jsonl": rover / "events.jsonl",
             "images.txt": block["images"], "capture_times.csv": block["capture_times"], "gcp.csv": block["gcp"]}
    for name, src in files.items():
        (office / name).write_bytes(Path(src).read_bytes())
    roles = {"rover.ubx": "rover_obs", "images.txt": "orientations", "capture_times.csv": "capture_times",
             "gcp.csv": "gcp"}
    proc = _run_uploader(server, office, roles, server.engineer_token_file)
    if proc.returncode != 0:
        return [StageResult("ground RTK job", False, f"processing set upload failed: {proc.stderr.strip()[-400:]}")]
    lever = np.asarray(world.scenario.flight.lever_arm_cam_m) + np.random.default_rng(seed).normal(0, 0.003, 3)
    stages = []
    with server.client() as client:
        flight = _server_flight(client, office.name)
        assert flight is not None
        fid = flight["id"]
        t = time.monotonic()
        job = client.post(f"/flights/{fid}/jobs", json={"kind": "rtk", "params": {
            "base_obs": "base.ubx", "base_pos": [float(v) for v in world.base_ecef_m]}}).json()
        job = _poll_job(client, fid, job["id"])
        rtk_s = time.monotonic() - t
        sol = server.data_dir / "outputs" / fid / job["id"] / "SOL.pos"
        if job["status"] != "done" or not sol.exists():
            return [StageResult(RTK_COLD, False, f"ground RTK job {job['status']}: {job['message']}")]
        figures, summary = track_figures(sol, world)
        figures["job_s"] = rtk_s
        stages.append(StageResult(RTK_COLD, figures["wrong_fixes"] == 0, f"{summary} (job {rtk_s:.0f} s)",
                                  figures, {"trajectory": str(sol)}))
        t = time.monotonic()
        job = client.post(f"/flights/{fid}/jobs", json={"kind": "adjust", "params": {
            "gcp": "gcp.csv", "capture_times": "capture_times.csv", "lever_arm": [float(v) for v in lever],
            "lever_arm_sigma": 0.005, "estimate": ["delay"], "crs": "EPSG:4979"}}).json()
        job = _poll_job(client, fid, job["id"])
        adjust_s = time.monotonic() - t
        if job["status"] != "done":
            stages.append(StageResult("final adjustment", False, f"ground adjustment job failed: {job['message']}"))
            return stages
        report_dir = out / "ground-report"
        report_dir.mkdir(exist_ok=True)
        res = client.get(f"/flights/{fid}/results").json()
        (report_dir / "results.json").write_text(json.dumps(res, indent=1) + "\n")
        (report_dir / "report.html").write_text(client.get(f"/flights/{fid}/report").text)
    rms = res.get("checkpoint_rms_m", {})
    rms3d = rms.get("3d")
    # the events are the flash marks, taken at the exposure: the delay left to estimate is 0 in the simulator
    figures = {"checkpoint_rms_m": rms, "lever_arm_m": res.get("lever_arm_m"), "delay_s": res.get("delay_s"),
               "true_delay_s": 0.0, "true_lever_arm_m": list(world.scenario.flight.lever_arm_cam_m),
               "sigma0": res.get("sigma0"), "warnings": res.get("warnings"), "job_s": adjust_s}
    ok = rms3d is not None and rms3d <= 0.03
    summary = (f"check-point 3D RMS {100 * rms3d:.1f} cm over {len(res.get('checkpoints', []))} points, "
               f"lever arm {[round(v, 3) for v in res.get('lever_arm_m', [])]} m (simulated "
               f"{list(world.scenario.flight.lever_arm_cam_m)}), flash mark → exposure delay "
               f"{1000 * (res.get('delay_s') or 0):.2f} ms (simulated 0), job {adjust_s:.0f} s"
               if rms3d is not None else "no check points")
    stages.append(StageResult("final adjustment", ok, summary, figures,
                              {"results": str(report_dir / "results.json"),
                               "report": str(report_dir / "report.html"), "fetched_from": f"{server.url}/flights/{fid}/report (a server of this run)"}))
    return stages


def write_summary(out: Path, stages: list[StageResult]) -> Path:
    """Write `summary.json` and return its path."""
    path = out / "summary.json"
    path.write_text(json.dumps([dataclasses.asdict(s) for s in stages], indent=1, default=str) + "\n")
    return path


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Register `flight` on the hil_sim command line."""
    p = sub.add_parser("flight", help="the whole product on a simulated flight: ground server, base station, "
                                      "companion with real-time RTK and autopilot link, go, upload, ground jobs",
                       description=__doc__)
    p.add_argument("--model", choices=("lea6t", "m8t"), default="m8t")
    p.add_argument("--speed", type=float, default=6.0, help="simulated seconds per real second (default 6)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--flight-s", type=float, default=0.0, help="stop after this many simulated s (default: landing)")
    p.add_argument("--ground-s", type=float, default=120.0,
                   help="simulated s on the ground before take-off (default 120: receivers configured, real-time "
                        "RTK fixed and the pre-flight go before the mission arms)")
    p.add_argument("--camera-period", type=float, default=2.0, help="TimePulse camera period, s (2–3)")
    p.add_argument("--missed-flash", type=float, default=0.02, help="probability a flash is missed")
    p.add_argument("--bounce", type=float, default=0.02, help="probability the hot-shoe contact bounces")
    p.add_argument("--radio-gap-interval", type=float, default=120.0,
                   help="mean simulated s between dropouts of the base station's radio (default 120)")
    p.add_argument("--seeded", action="store_true",
                   help="also post-process with the surveyed take-off point (simulator truth), labelled as such")
    p.add_argument("--out", type=Path, default=Path("demo-output"), help="output folder (default demo-output)")
    p.set_defaults(func=main)


def _flight_dir(stages: list[StageResult], name: str) -> Path | None:
    return next((Path(s.outputs["flight"]) for s in stages if s.name == name and "flight" in s.outputs), None)


def main(args: argparse.Namespace) -> int:
    """Fly, upload, process on the ground; print what was measured and where. Exit 0 when every stage passed."""
    out = args.out.resolve() / time.strftime("flight-%Y%m%dT%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    t_wall = time.monotonic()
    server = GroundServer(out)
    stages: list[StageResult] = []
    ctx: dict[str, Any] = {}
    try:
        server.wait_ready()
        flown, ctx = record_flight(args, out, server=server)
        stages += flown
        rover, base = _flight_dir(stages, "record rover"), _flight_dir(stages, "record base")
        if rover is not None:
            stages.append(autopilot_events(rover, ctx))
            stages.append(check_pairing(rover, ctx))
            stages.append(upload_flight(rover, server, ctx["go"].get("auto_upload")))
        if rover is not None and base is not None:
            stages.append(corrections_chain(rover, base, ctx))
            stages.append(realtime_rtk(rover, ctx))
            stages += ground_processing(rover, base, out, ctx, server, args.seed)
            if args.seeded:
                stages.append(process_rtk(rover, base, out, ctx, seeded=True))
        if rover is not None:
            stages.append(convert_rinex(rover, out))
    except (RuntimeError, TimeoutError) as exc:
        print(f"directgeo: hil_sim flight: error: {exc} (logs in {out})", file=sys.stderr)
        return 1
    finally:
        server.stop()
    summary = write_summary(out, stages)
    print(f"directgeo simulated flight ({args.model}, {args.speed:g}× real time, "
          f"{ctx['end'].diff_s(ctx['start']):.0f} s simulated, {time.monotonic() - t_wall:.0f} s wall time)")
    for s in stages:
        print(f"  [{'ok' if s.ok else 'FAILED'}] {s.name}: {s.summary}")
        for key, value in s.outputs.items():
            print(f"        {key}: {value}")
    print(f"ground server data (SQLite, flight files, job outputs): {server.data_dir}; tokens: {server.token_file} (admin), "
          f"{server.drone_token_file} (drone), {server.engineer_token_file} (engineer)")
    print(f"summary: {summary}")
    return 0 if all(s.ok for s in stages) else 1


__all__ = ["GpsTime", "add_parser", "main"]
