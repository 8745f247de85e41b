"""`python -m onboard run`: the command line of the recorder daemon (its composition root is `run_recorder`)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from onboard.cmdline import EXIT_USAGE, report_error
from onboard.errors import ConfigFileError


def add_run_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:  # type: ignore[type-arg]
    """Register `run` (the recorder daemon)."""
    from onboard.recorder.settings import add_recorder_arguments

    p = subparsers.add_parser("run", help="record: the onboard recorder daemon",
                              description="Record every byte from the receiver into a crash-safe journal, "
                                          "configure and monitor the receiver, write a status snapshot.")
    p.add_argument("--port", help="receiver serial device (overrides port.device)")
    add_recorder_arguments(p)
    p.set_defaults(func=_run)
    return p


def _run(args: argparse.Namespace) -> int:
    from onboard.logger.files import FileLayer, OsFileLayer, SyncLogFileLayer
    from onboard.recorder.app import gpio_edge_sources, run_recorder, serial_port_opener
    from onboard.recorder.daemon import EXIT_DISK_FULL, RecorderDeps
    from onboard.recorder.sdnotify import SdNotifier
    from onboard.recorder.settings import check_recording_paths, load_settings, recorder_overrides

    try:
        settings = load_settings(args.config, overrides=recorder_overrides(args))
        check_recording_paths(settings)  # before the flight opens: a bad path is a configuration error (exit 2)
    except ConfigFileError as exc:
        return report_error("run", str(exc), EXIT_USAGE)
    # Test hook: a file layer that logs every fsync'd length, so a power-cut test can cut files back to it.
    sync_log = os.environ.get("ONBOARD_TEST_SYNC_LOG")
    files: FileLayer = SyncLogFileLayer(Path(sync_log)) if sync_log else OsFileLayer()
    deps = RecorderDeps(open_port=serial_port_opener(settings), files=files, notifier=SdNotifier(),
                        edge_sources=gpio_edge_sources(settings))
    code = run_recorder(settings, deps)
    if code == EXIT_DISK_FULL:
        report_error("run", "free disk space is below journal.disk_floor_mb: recording stopped (see the status "
                     "snapshot); free space, then start the recorder again", code)
    return code
