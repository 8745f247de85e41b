"""`python -m hil_sim`: the hardware-in-the-loop simulator (stand-ins for the drone's hardware).

Four commands:
  receiver  a u-blox LEA-6T or NEO-M8T on a pseudo-terminal, answering the recorder as the real receiver does
            (configuration, raw measurements of a simulated sky, camera time marks, injected faults) until
            SIGTERM/SIGINT; its first stdout line is the pty path to open (flushed).
  radio     the base-to-drone telemetry radio: prints "<base-side pty> <drone-side pty>" and forwards between
            them with dropouts and an air byte budget, until SIGTERM/SIGINT.
  autopilot an ArduCopter stand-in speaking MAVLink 2 (or 1) on a raw pty or UDP: prints its pty path (or
            "udp:HOST:PORT") and flies a scripted flight or the simulated mission, with injected faults.
  flight    a whole simulated flight through the real recorder daemons (rover and base), RINEX conversion,
            RTK post-processing and the block adjustment; prints each stage's result and a summary.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import signal
import sys
import threading
from collections.abc import Sequence
from types import FrameType

from hil_sim.faults import FaultOptions
from hil_sim.receiver import MODELS, ReceiverOptions
from onboard.errors import InputError

log = logging.getLogger("hil_sim")


def _window(text: str) -> tuple[float, float]:
    try:
        at, dur = (float(x) for x in text.split(":"))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected AT_S:DURATION_S, got {text!r}") from exc
    return at, dur


EPILOG = """examples:
  python -m hil_sim receiver --model m8t --speed 6 --link /tmp/gnss0   (then: python -m onboard run --port /tmp/gnss0)
  python -m hil_sim receiver --model lea6t --corrupt-rate 1e-4 --unplug 60:5
  python -m hil_sim radio --speed 6 --mean-interval 60
  python -m hil_sim flight --model m8t --speed 6 --out demo-output
  python -m hil_sim <command> --help   (each command's options and units)"""


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface: receiver, radio, flight."""
    p = argparse.ArgumentParser(prog="python -m hil_sim", description=__doc__, epilog=EPILOG,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    r = sub.add_parser("receiver", help="u-blox LEA-6T / NEO-M8T emulator on a pseudo-terminal",
                       description="A u-blox receiver on a pseudo-terminal until SIGTERM/SIGINT: the first stdout "
                                   "line is the pty path. Times are simulated seconds (--speed N runs N× real "
                                   "time); probabilities are 0–1.")
    r.add_argument("--model", choices=sorted(MODELS), required=True, help="receiver model to emulate")
    r.add_argument("--speed", type=float, default=1.0, help="simulated time runs N× real time")
    r.add_argument("--seed", type=int, default=1, help="seed of the world and the faults")
    r.add_argument("--baud", type=int, default=9600, help="UART1 rate at power-on (factory 9600)")
    r.add_argument("--link", help="stable symlink to the current pty slave (re-pointed after port loss)")
    r.add_argument("--receiver", choices=("rover", "base"), default="rover",
                   help="which antenna of the world: the drone's (rover, default) or the base station's")
    r.add_argument("--nav", help="RINEX navigation file of the world (default: the scenario's)")
    r.add_argument("--world", help="multi-constellation world (hil_sim.scenario.MULTI_WORLDS: gr-2012, gej-2021; "
                   "default: the GPS world); the M8T tracks what CFG-GNSS enables")
    r.add_argument("--harsh", action="store_true", help="the rover under trees (RoverEnvironment HARSH)")
    r.add_argument("--duration", type=float, default=None,
                   help="simulated span in s (default: the scenario's); afterwards no more measurements")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--clear-align-to-tow", dest="align", action="store_const", const="clear", default="clear",
                   help="clear alignToTow for periods that do not divide 1 s (default)")
    g.add_argument("--keep-align-to-tow", dest="align", action="store_const", const="keep",
                   help="keep alignToTow as requested, whatever the period")
    r.add_argument("--rawx-on-u6", choices=("nak", "ack-ignore"), default="nak",
                   help="LEA-6T answer to enabling RXM-RAWX: NAK (default) or ACK and ignore it")
    r.add_argument("--tp5-on-u6", choices=("ack", "nak"), default="ack",
                   help="LEA-6T answer to CFG-TP5: ACK (default, firmware ≥ 7.0) or NAK (older firmware)")
    r.add_argument("--silent", action="store_true", help="never answer; stream the factory output")
    r.add_argument("--ack-invalid-rates", action="store_true", help="ACK too-fast CFG-RATE, apply the minimum")
    r.add_argument("--camera-tp", type=int, choices=(0, 1), default=1,
                   help="TIMEPULSE driving the camera: 0 TIMEPULSE, 1 TIMEPULSE2 (default)")
    r.add_argument("--trigger-extint", action="store_true", help="trigger pulse on EXTINT1 (TIM-TM2 ch 1)")
    r.add_argument("--time-valid-after", type=float, default=None,
                   help="simulated s to valid time (default: the scenario camera's valid_after_s)")
    r.add_argument("--corrupt-rate", type=float, default=0.0, help="probability per byte written")
    r.add_argument("--drop-epoch-rate", type=float, default=0.0, help="probability per raw epoch")
    r.add_argument("--drop-flash-mark-rate", type=float, default=0.0,
                   help="probability per TIM-TM2 flash report (EXTINT0) of losing it (a missed flash)")
    r.add_argument("--bounce-prob", type=float, default=0.0, help="hot-shoe bounce probability per flash")
    r.add_argument("--unplug", type=_window, action="append", default=[], metavar="AT_S:DURATION_S",
                   help="port disappears at simulated AT_S for DURATION_S (repeatable)")
    r.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    a = sub.add_parser("radio", help="base→drone radio link: two ptys with dropouts and an air byte budget",
                       description="Print '<base-side pty> <drone-side pty>' and forward bytes between them, "
                                   "losing them in dropouts and beyond the air rate, until SIGTERM/SIGINT.")
    a.add_argument("--speed", type=float, default=1.0, help="simulated time runs N× real time (default 1)")
    a.add_argument("--seed", type=int, default=1, help="seed of the dropouts (default 1)")
    a.add_argument("--air-baud", type=int, default=19200, help="air data rate, baud: the byte budget (default 19200)")
    a.add_argument("--mean-interval", type=float, default=120.0, help="mean s between dropouts (simulated)")
    a.add_argument("--gap-min", type=float, default=5.0, help="shortest dropout, simulated s (default 5)")
    a.add_argument("--gap-max", type=float, default=20.0, help="longest dropout, simulated s (default 20)")
    a.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    ap = sub.add_parser("autopilot", help="ArduCopter stand-in: MAVLink on a raw pty or UDP, scripted flight")
    ap.add_argument("--udp", metavar="HOST:PORT", help="send to the companion there (default: a raw pty)")
    ap.add_argument("--speed", type=float, default=1.0, help="simulated time runs N× real time")
    ap.add_argument("--seed", type=int, default=1, help="seed of the injected losses (default 1)")
    ap.add_argument("--system-id", type=int, default=1, help="the vehicle's MAVLink system id")
    ap.add_argument("--mission", action="store_true",
                    help="fly the receiver's default mission (hil_sim.scenario / flight), not the short script")
    ap.add_argument("--arm-at", type=float, default=10.0, help="simulated s on the ground before arming")
    ap.add_argument("--survey", type=float, default=30.0, help="simulated s of survey lines in the air")
    ap.add_argument("--repeat-after", type=float, default=None, metavar="S",
                    help="fly the script again, arming S simulated s after the first disarm")
    ap.add_argument("--mavlink1", action="store_true", help="MAVLink 1 only: send v1, ignore v2 frames")
    ap.add_argument("--no-gcs-heartbeat", action="store_true", help="do not forward a ground station's heartbeat")
    ap.add_argument("--link-loss", type=_window, action="append", default=[], metavar="AT_S:DURATION_S",
                    help="no bytes either way from simulated AT_S for DURATION_S (repeatable)")
    ap.add_argument("--heartbeat-stop", type=_window, action="append", default=[], metavar="AT_S:DURATION_S",
                    help="the autopilot sends no HEARTBEAT from AT_S for DURATION_S (repeatable)")
    ap.add_argument("--reboot-at", type=float, action="append", default=[], metavar="AT_S",
                    help="the autopilot reboots at simulated AT_S: boot clock back to 0, streams off (repeatable)")
    ap.add_argument("--rtcm", help="file of RTCM3 bytes to inject as GPS_RTCM_DATA (one message per interval)")
    ap.add_argument("--rtcm-start", type=float, default=1.0, help="simulated s before the first RTCM message")
    ap.add_argument("--rtcm-interval", type=float, default=0.5, help="simulated s between RTCM messages")
    ap.add_argument("--rtcm-stream", metavar="SPEC",
                    help="live RTCM3 to inject, message by message as it arrives (a ground station on the base's "
                         "radio): serial:DEV@BAUD (a serial device or pty) or tcp://HOST:PORT")
    ap.add_argument("--go-file", metavar="PATH", help="stay disarmed on the ground until PATH exists (a pre-flight go)")
    ap.add_argument("--drop-fragment-rate", type=float, default=0.0, help="probability per GPS_RTCM_DATA fragment")
    ap.add_argument("--reorder-fragments", action="store_true", help="shuffle each message's fragments")
    ap.add_argument("--report", help="JSON file: what the stand-in heard and sent (rewritten twice a second)")
    ap.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    from hil_sim.mission import add_parser as add_flight_parser

    add_flight_parser(sub)
    return p


def _wait_for_signal() -> threading.Event:
    done = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        done.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    return done


def run_radio(args: argparse.Namespace) -> int:
    """Print '<tx_path> <rx_path>' (base side, drone side) and forward until a signal."""
    from hil_sim.radio import RadioLink, RadioOptions

    try:
        opts = RadioOptions(air_baud=args.air_baud, mean_interval_s=args.mean_interval, gap_min_s=args.gap_min,
                            gap_max_s=args.gap_max, seed=args.seed)
    except ValueError as exc:
        print(f"hil_sim radio: {exc}", file=sys.stderr)
        return 2
    link = RadioLink(opts, speed=args.speed)
    done = _wait_for_signal()
    tx, rx = link.start()
    print(tx, rx, flush=True)
    try:
        done.wait()
    finally:
        link.stop()
    ch = link.channel
    log.info("radio stopped: %d B in, %d B out, %d lost in dropouts, %d over budget", ch.bytes_in, ch.bytes_out,
             ch.bytes_lost_dropout, ch.bytes_lost_budget)
    return 0


def run_receiver(args: argparse.Namespace) -> int:
    """Build the world and the emulator, print the pty path, run until a signal."""
    from hil_sim.pty_server import ReceiverEmulator
    from hil_sim.scenario import HARSH, Scenario
    from hil_sim.world import World

    overrides: dict[str, object] = {"seed": args.seed}
    if args.nav:
        overrides["nav_path"] = args.nav
    if args.duration is not None:
        overrides["duration_s"] = args.duration
    if args.harsh:
        overrides["rover_environment"] = HARSH
    scenario = (Scenario.multi(args.world, model=args.model, **overrides) if args.world
                else Scenario.default(model=args.model, **overrides))
    valid_after = args.time_valid_after
    if valid_after is None:
        valid_after = scenario.camera.valid_after_s
    else:  # the world's camera suppresses pulses before the same instant
        scenario = dataclasses.replace(scenario, camera=dataclasses.replace(scenario.camera,
                                                                           valid_after_s=valid_after))
    try:
        world = World(scenario)
    except InputError as exc:
        print(f"hil_sim: {exc}", file=sys.stderr)
        return 2
    options = ReceiverOptions(
        align_to_tow=args.align, rawx_on_u6=args.rawx_on_u6, tp5_on_u6=args.tp5_on_u6, silent=args.silent,
        ack_invalid_rates=args.ack_invalid_rates, trigger_extint=args.trigger_extint,
        camera_tp_idx=args.camera_tp,
        time_valid_after_s=valid_after, receiver=args.receiver,
        faults=FaultOptions(seed=args.seed, corrupt_byte_rate=args.corrupt_rate,
                            drop_epoch_rate=args.drop_epoch_rate,
                            drop_flash_mark_rate=args.drop_flash_mark_rate, bounce_prob=args.bounce_prob,
                            unplug_windows_s=tuple(args.unplug)))
    emu = ReceiverEmulator(args.model, options, world, speed=args.speed, link=args.link,
                           t_start=scenario.start, initial_baud=args.baud)
    done = _wait_for_signal()
    path = emu.start()
    print(path, flush=True)
    if args.link:
        log.info("link %s -> %s", args.link, path)
    try:
        while not done.wait(0.2):
            if emu.error is not None:
                log.error("emulator failed: %s", emu.error)
                return 1
    finally:
        emu.stop()
    s = emu.core.stats
    log.info("stopped: %d frames in, %d ACK, %d NAK, %d epochs out, %d dropped (budget), %d marks",
             s.frames_in, s.acked, s.naked, s.epochs_out, s.epochs_dropped_budget, s.marks_out)
    return 0


def run_autopilot(args: argparse.Namespace) -> int:
    """Print the pty slave path (or "udp:HOST:PORT") and fly the script until a signal."""
    from pathlib import Path

    from hil_sim.autopilot import AutopilotSim, options_from_args

    target = None
    if args.udp:
        host, _, port = args.udp.rpartition(":")
        if not host or not port.isdigit():
            print(f"hil_sim autopilot: --udp {args.udp!r}: expected HOST:PORT", file=sys.stderr)
            return 2
        target = (host, int(port))
    try:
        options = options_from_args(args)
    except OSError as exc:
        print(f"hil_sim autopilot: --rtcm: {exc}", file=sys.stderr)
        return 2
    flight = None
    if args.mission:
        from hil_sim.autopilot import MissionFlight
        from hil_sim.scenario import Scenario

        flight = MissionFlight(Scenario.default(seed=args.seed))
    stream = None
    if args.rtcm_stream:
        from onboard.hw.net_stream import open_base_stream

        try:
            stream = open_base_stream(args.rtcm_stream)
        except ValueError as exc:
            print(f"hil_sim autopilot: --rtcm-stream {args.rtcm_stream!r}: {exc}", file=sys.stderr)
            return 2
    sim = AutopilotSim(options, speed=args.speed, udp_target=target,
                       report_path=Path(args.report) if args.report else None, flight=flight, rtcm_stream=stream,
                       go_file=Path(args.go_file) if args.go_file else None)
    done = _wait_for_signal()
    print(sim.start(), flush=True)
    try:
        while not done.wait(0.2):
            if sim.error is not None:
                return 1
    finally:
        sim.stop()
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `python -m hil_sim`."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if getattr(args, "verbose", False) else logging.INFO, stream=sys.stderr,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    if args.command == "receiver":
        return run_receiver(args)
    if args.command == "radio":
        return run_radio(args)
    if args.command == "autopilot":
        return run_autopilot(args)
    if args.command == "flight":
        logging.getLogger().setLevel(logging.WARNING)
        return int(args.func(args))
    return 2


if __name__ == "__main__":
    sys.exit(main())
