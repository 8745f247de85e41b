"""`python -m onboard web`: registering the command imports nothing heavy (FastAPI loads only when it runs)."""

from __future__ import annotations

import argparse
from pathlib import Path

from onboard.recorder.status import DEFAULT_STATUS_PATH
from onboard.validate import arg_type, tcp_port


def add_web_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Register `python -m onboard web` (the pre-flight check page)."""
    p = subparsers.add_parser("web", help="serve the pre-flight check page (reads the recorder's status snapshot)")
    p.add_argument("--status", type=Path, default=DEFAULT_STATUS_PATH, help="status snapshot path")
    p.add_argument("--base-stream", default=None, metavar="SPEC",
                   help="the recorder's rtk.base_stream, to name the base-correction source (credentials are never "
                        "shown; default $ONBOARD_RTK_BASE_STREAM)")
    p.add_argument("--host", default="0.0.0.0", help="listen address (default all: the field laptop joins the Pi's Wi-Fi)")
    p.add_argument("--port", type=arg_type(tcp_port), default=8080, metavar="PORT",
                   help="TCP port to listen on, 1–65535 (default 8080)")
    p.set_defaults(func=_serve)


def _serve(args: argparse.Namespace) -> int:
    import uvicorn

    from onboard.web.app import create_app

    uvicorn.run(create_app(args.status, base_stream=args.base_stream), host=args.host, port=args.port, log_level="info")
    return 0
