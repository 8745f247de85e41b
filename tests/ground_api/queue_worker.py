"""`python -m tests.ground_api.queue_worker slow|hang --api URL --token-file F --dsn DSN --cache-dir D --name N`:
the real worker (`ground.api.worker.serve`) with a test job function for kind `adjust` (`jobfuncs.slow_adjust`,
the real adjustment after a pause; or `jobfuncs.hangs`), a 1 s heartbeat and a 3 s stalled-worker age."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from ground.api.settings import load_token
from ground.api.worker import WorkerOptions, serve
from tests.ground_api import jobfuncs

FUNCTIONS = {"slow": {"adjust": jobfuncs.slow_adjust}, "hang": {"adjust": jobfuncs.hangs}}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=sorted(FUNCTIONS))
    ap.add_argument("--api", required=True)
    ap.add_argument("--token-file", required=True, type=Path)
    ap.add_argument("--dsn", required=True)
    ap.add_argument("--cache-dir", required=True, type=Path)
    ap.add_argument("--name", default="")
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    serve(WorkerOptions(api_url=args.api, token=load_token(args.token_file), dsn=args.dsn, cache_dir=args.cache_dir,
                        heartbeat_s=1.0, stalled_after_s=3.0, name=args.name), FUNCTIONS[args.mode])


if __name__ == "__main__":
    main()
