"""`python -m ground adjust|serve` (see ground.cli)."""

from __future__ import annotations

import sys


def main() -> int:
    """Console entry point."""
    from ground.cli import main as cli_main

    return cli_main(sys.argv[1:])


if __name__ == "__main__":
    sys.exit(main())
