"""`python -m hil_sim flight`: one whole simulated survey flight through the real onboard code paths.

The simulator's receivers (rover on the drone, base on the ground) run on real pseudo-terminals; the real
recorder daemon (`python -m onboard run`, one process per receiver, as on the drone and at the base) configures
them, journals every byte and pairs the camera's trigger pulses with its flashes. After landing the flight goes
through the same tools a user runs: RINEX conversion, post-processed RTK against the base (a cold start, the
figures a user gets, then a second run seeded with the surveyed take-off point) and the final adjustment on the
cold start's trajectory. Each stage is checked against the simulator's truth and the summary says where everything is.
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


def _start_recorder(name: str, port: str, out: Path, camera_period_s: float, meas_rate_ms: int) -> tuple[subprocess.Popen[bytes], Path, Path]:
    cfg = out / f"{name}.toml"
    cfg.write_text(
        "# written by python -m hil_sim flight\n"
        f'[receiver]\ncamera_period_s = {camera_period_s}\ntrigger = "extint1"\nmeas_rate_ms = {meas_rate_ms}\n'
        "[journal]\ndisk_floor_mb = 50.0\n"
    )
    data_dir, status_path = out / name, out / f"{name}-status.json"
    env = dict(os.environ, PYTHONPATH=str(PROJECT_ROOT))
    env.pop("NOTIFY_SOCKET", None)
    log_file = open(out / f"{name}-recorder.log", "wb")  # noqa: SIM115 - handed to the child process
    proc = subprocess.Popen(
        [sys.executable, "-m", "onboard", "run", "--config", str(cfg), "--port", port, "--baud", "115200",
         "--data-dir", str(data_dir), "--status", str(status_path)],
        cwd=PROJECT_ROOT, env=env, stdout=log_file, stderr=subprocess.STDOUT,
    )
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


def record_flight(args: argparse.Namespace, out: Path) -> tuple[list[StageResult], dict[str, Any]]:
    """Stage 1: simulate rover and base receivers on ptys and record both with the real daemon."""
    from hil_sim.pty_server import ReceiverEmulator
    from hil_sim.receiver import ReceiverOptions
    from hil_sim.scenario import CameraPlan, Scenario
    from hil_sim.world import World

    camera = CameraPlan(period_s=args.camera_period, valid_after_s=20.0,
                        missed_flash_probability=args.missed_flash, bounce_probability=args.bounce)
    scenario = Scenario.default(model=args.model, seed=args.seed, camera=camera)
    world = World(scenario)
    flight_s = world.trajectory.duration_s + 10.0
    if args.flight_s:
        flight_s = min(flight_s, args.flight_s)
    opts = ReceiverOptions(trigger_extint=True, time_valid_after_s=camera.valid_after_s)
    rover = ReceiverEmulator(args.model, opts, world, speed=args.speed, receiver="rover")
    base = ReceiverEmulator(args.model, opts, world, speed=args.speed, receiver="base")
    procs: dict[str, subprocess.Popen[bytes]] = {}
    dirs: dict[str, Path] = {}
    statuses: dict[str, Path] = {}
    meas_rate_ms = 1000 if args.model == "lea6t" else 500
    try:
        for name, emu in (("rover", rover), ("base", base)):
            port = emu.start()
            procs[name], dirs[name], statuses[name] = _start_recorder(name, port, out, args.camera_period, meas_rate_ms)
        for name in procs:
            def configured(n: str = name) -> bool:
                return _status(statuses[n]).get("config_state") in ("verified", "failed")

            _wait(configured, 90, f"{name} receiver configuration")
        t0 = scenario.start
        while (done := rover.sim_time().diff_s(t0)) < flight_s:
            _progress("flying", done, flight_s)
            for name, proc in procs.items():
                if proc.poll() is not None:
                    raise RuntimeError(f"the {name} recorder exited early (see {out}/{name}-recorder.log)")
            time.sleep(0.5)
        _progress("flying", flight_s, flight_s)
        end = rover.sim_time()
    finally:
        codes = {name: _stop(p) for name, p in procs.items()}
        rover.stop()
        base.stop()
    return [_recording_result(name, dirs[name], statuses[name], codes.get(name, -1)) for name in ("rover", "base")], {
        "world": world, "scenario": scenario, "start": scenario.start, "end": end, "dirs": dirs,
    }


def _recording_result(name: str, data_dir: Path, status_path: Path, code: int) -> StageResult:
    from onboard.logger.journal import read_manifest
    from onboard.receiver.decode import iter_journal
    from onboard.rtk.types import ObsEpoch

    st = _status(status_path)
    flights = sorted(data_dir.glob("flight-*"))
    if not flights:
        return StageResult(f"record {name}", False, f"no flight directory under {data_dir}")
    flight = flights[-1]
    manifest = read_manifest(flight)
    problems = _verify_segments(flight, manifest)
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
               f"{figures['bytes']} bytes in {figures['segments']} segment(s), SHA-256 "
               f"{'verified' if not problems else 'MISMATCH'}")
    return StageResult(f"record {name}", ok, summary, figures, {"flight": str(flight)})


def _verify_segments(flight: Path, manifest: Any) -> list[str]:
    """Names of the manifest's segments whose size or SHA-256 does not match the file on disk."""
    import hashlib

    if manifest is None:
        return ["no manifest"]
    bad = []
    for seg in manifest.segments:
        data = (flight / seg.name).read_bytes() if (flight / seg.name).exists() else b""
        if len(data) != seg.bytes or hashlib.sha256(data).hexdigest() != seg.sha256:
            bad.append(seg.name)
    return bad


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
    errors_ns, missing, flagged, clean = [], 0, 0, 0
    for ev in truth:
        p = by_pulse.get(round(ev.pulse_time.total_ns / 1e6))
        if p is None:
            missing += 1
        elif p.flags:
            flagged += 1
        elif p.delay_ns is not None and ev.delay_s is not None:
            clean += 1
            errors_ns.append(abs(p.delay_ns - round(ev.delay_s * 1e9)))
    worst = max(errors_ns) if errors_ns else None
    ok = missing == 0 and clean > 0 and worst is not None and worst <= 1000
    figures = {"camera_events": len(truth), "paired": clean, "flagged": flagged, "missing": missing,
               "max_delay_error_ns": worst,
               "mean_delay_ms": (sum(p.delay_ns for p in with_pulse if p.delay_ns) / max(1, clean + flagged)) / 1e6}
    summary = (f"{clean} images with a measured shutter delay (worst error vs simulator {worst} ns), "
               f"{flagged} flagged (missed/bounced flash), {missing} pulses not recorded")
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


RTK_COLD = "RTK"
"""Stage name of the cold start: what a user gets (no position known before the first fix)."""
RTK_SEEDED = "RTK seeded with the surveyed take-off point (simulator truth)"
"""Stage name of the second run, started from the take-off point as a surveyor would measure it (here: exact)."""


def process_rtk(rover: Path, base: Path, out: Path, ctx: dict[str, Any], seeded: bool = False) -> StageResult:
    """Stage 4: post-processed fix-and-hold RTK of the rover journal against the base journal, vs truth.

    A cold start by default: the engine is given the base position and that the drone stands still before
    take-off, nothing else. `seeded` adds the take-off point as `--init-pos` (a surveyed start, Daakir 2015:
    ambiguities computed from a known position); here it is the simulator's exact truth, so it is the best case.
    """
    import numpy as np

    from onboard.formats.pos import read_pos

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
    track = read_pos(pos_path)
    q = np.asarray(track.q)
    times = list(track.time)
    truth = np.array([world.truth(t)["antenna_ecef_m"] for t in times])
    err = np.linalg.norm(np.asarray(track.pos_ecef_m) - truth, axis=1)
    fixed = q == 1
    n = len(q)
    wrong = int(np.sum(fixed & (err > 0.10)))
    rms = float(np.sqrt(np.mean(err[fixed] ** 2))) if fixed.any() else float("nan")
    first_fix = next((times[i].diff_s(times[0]) for i in range(n) if fixed[i]), None)
    figures = {"epochs": n, "fix_ratio": float(fixed.mean()) if n else 0.0, "fixed_3d_rms_m": rms,
               "wrong_fixes": wrong, "first_fix_s": first_fix}
    ok = n > 0 and wrong == 0
    summary = (f"{n} epochs, {100 * float(fixed.mean() if n else 0.0):.1f} % fixed, fixed-epoch 3D RMS vs truth "
               f"{100 * rms:.1f} cm, {wrong} wrong fixes (> 10 cm), first fix after "
               f"{'never' if first_fix is None else f'{first_fix:.0f} s'}")
    return StageResult(name, ok, summary, figures, {"trajectory": str(pos_path)})


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


def adjust_block(rover: Path, out: Path, ctx: dict[str, Any], trajectory: Path, seed: int) -> StageResult:
    """Stage 5: the final adjustment with the real `ground adjust` command: lever-arm prior, flash marks, 1 GCP."""
    import numpy as np

    world = ctx["world"]
    block = simulate_block(rover, out, ctx, seed)
    lever = np.asarray(world.scenario.flight.lever_arm_cam_m) + np.random.default_rng(seed).normal(0, 0.003, 3)
    adj = out / "adjustment"
    cmd = [sys.executable, "-m", "ground", "adjust", "--trajectory", str(trajectory),
           "--events", str(rover / "events.jsonl"), "--capture-times", str(block["capture_times"]),
           "--orientations", str(block["images"]), "--gcp", str(block["gcp"]),
           "--lever-arm", ",".join(f"{v:.4f}" for v in lever), "--lever-arm-sigma", "0.005",
           "--estimate", "delay", "--crs", "EPSG:4979", "-o", str(adj)]
    proc = subprocess.run(cmd, cwd=PROJECT_ROOT, capture_output=True, text=True, timeout=900, check=False)
    results = adj / "results.json"
    if proc.returncode != 0 or not results.exists():
        return StageResult("final adjustment", False, f"ground adjust failed: {(proc.stderr or proc.stdout).strip()[-400:]}")
    res = json.loads(results.read_text())
    rms = res.get("checkpoint_rms_m", {})
    figures = {"checkpoint_rms_m": rms, "lever_arm_m": res.get("lever_arm_m"), "delay_s": res.get("delay_s"),
               "sigma0": res.get("sigma0"), "warnings": res.get("warnings"), "outliers": res.get("outliers")}
    rms3d = rms.get("3d")
    ok = rms3d is not None and rms3d <= 0.03
    summary = (f"check-point 3D RMS {100 * rms3d:.1f} cm over {len(res.get('checkpoints', []))} points, "
               f"lever arm {[round(v, 3) for v in res.get('lever_arm_m', [])]} m, "
               f"delay {1000 * (res.get('delay_s') or 0):.2f} ms" if rms3d is not None else "no check points")
    return StageResult("final adjustment", ok, summary, figures,
                       {"results": str(results), "report": str(adj / "report.html")})


def write_summary(out: Path, stages: list[StageResult]) -> Path:
    """Write `summary.json` and return its path."""
    path = out / "summary.json"
    path.write_text(json.dumps([dataclasses.asdict(s) for s in stages], indent=1, default=str) + "\n")
    return path


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Register `flight` on the hil_sim command line."""
    p = sub.add_parser("flight", help="a whole simulated flight through the real daemon, RTK and adjustment",
                       description=__doc__)
    p.add_argument("--model", choices=("lea6t", "m8t"), default="m8t")
    p.add_argument("--speed", type=float, default=6.0, help="simulated seconds per real second (default 6)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--flight-s", type=float, default=0.0, help="stop after this many simulated s (default: landing)")
    p.add_argument("--camera-period", type=float, default=2.0, help="TimePulse camera period, s (2–3)")
    p.add_argument("--missed-flash", type=float, default=0.02, help="probability a flash is missed")
    p.add_argument("--bounce", type=float, default=0.02, help="probability the hot-shoe contact bounces")
    p.add_argument("--out", type=Path, default=Path("demo-output"), help="output folder (default demo-output)")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    """Fly, then print what was recorded and where. Exit 0 when every stage passed its checks."""
    out = args.out.resolve() / time.strftime("flight-%Y%m%dT%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    t_wall = time.monotonic()
    stages, ctx = record_flight(args, out)
    rover = next((Path(s.outputs["flight"]) for s in stages if s.name == "record rover" and "flight" in s.outputs), None)
    base = next((Path(s.outputs["flight"]) for s in stages if s.name == "record base" and "flight" in s.outputs), None)
    if rover is not None:
        stages.append(check_pairing(rover, ctx))
        stages.append(convert_rinex(rover, out))
    if rover is not None and base is not None:
        rtk = process_rtk(rover, base, out, ctx)  # cold start: the figures a user gets
        stages.append(rtk)
        stages.append(process_rtk(rover, base, out, ctx, seeded=True))
        if "trajectory" in rtk.outputs:
            stages.append(adjust_block(rover, out, ctx, Path(rtk.outputs["trajectory"]), args.seed))
    summary = write_summary(out, stages)
    print(f"directgeo simulated flight ({args.model}, {args.speed:g}× real time, "
          f"{ctx['end'].diff_s(ctx['start']):.0f} s simulated in {time.monotonic() - t_wall:.0f} s)")
    for s in stages:
        print(f"  [{'ok' if s.ok else 'FAILED'}] {s.name}: {s.summary}")
        for key, value in s.outputs.items():
            print(f"        {key}: {value}")
    print(f"summary: {summary}")
    return 0 if all(s.ok for s in stages) else 1


__all__ = ["GpsTime", "add_parser", "main"]
