"""`python -m onboard upload-daemon`: the automatic uploader's command line (see `onboard.upload.daemon`)."""

from __future__ import annotations

import argparse
import logging
import signal
import threading
from pathlib import Path
from typing import Any

from onboard.cmdline import EXIT_USAGE, report_error
from onboard.errors import ConfigFileError

log = logging.getLogger(__name__)


def add_upload_daemon_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:  # type: ignore[type-arg]
    """Register `upload-daemon`."""
    p = subparsers.add_parser(
        "upload-daemon", help="send closed flights to the ground app, in the background",
        description="Upload the flights the recorder closed (its queue in <data_dir>/upload/) to upload.url, "
                    "oldest first, resumably and checked by SHA-256, never while the autopilot is armed, at low "
                    "CPU and I/O priority; writes upload.json beside the status snapshot.",
        epilog="example: python -m onboard upload-daemon --config /etc/directgeo/recorder.toml")
    p.add_argument("--config", type=Path, help="TOML configuration file (the recorder's: [upload], journal.data_dir, "
                                               "status.path, autopilot.link)")
    p.add_argument("--data-dir", type=Path, help="where flights are recorded (overrides journal.data_dir)")
    p.add_argument("--status", type=Path, help="the recorder's status snapshot path: upload.json goes beside it "
                                               "(overrides status.path)")
    p.set_defaults(func=_run)
    return p


def _run(args: argparse.Namespace) -> int:
    from onboard.recorder.settings import load_settings
    from onboard.upload.client import read_token
    from onboard.upload.daemon import UploadService, http_uploader_for
    from onboard.upload.priority import lower_priority

    overrides: dict[str, Any] = {"journal.data_dir": str(args.data_dir) if args.data_dir else None,
                                 "status.path": str(args.status) if args.status else None}
    try:
        settings = load_settings(args.config, overrides=overrides)
        if not settings.upload_url:
            raise ConfigFileError("upload.url is not set: nothing to upload to")
        try:
            token = read_token(Path(settings.upload_token_file))
        except ValueError as exc:
            raise ConfigFileError(str(exc).replace("--token-file", "upload.token_file")) from None
    except ConfigFileError as exc:
        return report_error("upload-daemon", str(exc), EXIT_USAGE)
    priority = lower_priority()  # before any other thread exists: threads inherit it
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    service = UploadService(settings, http_uploader_for(settings, token, stop), stop)
    service.status.priority = priority
    log.info("uploading %s to %s (priority %s)", settings.data_dir, settings.upload_url, priority)
    try:
        service.run()
    finally:
        service.uploader.close()
    return 0
