#!/usr/bin/env bash
# Set up directgeo and fly one simulated survey through the real recorder daemon (hil_sim receiver over a
# pseudo-terminal), then print what was recorded and where. Extra arguments go to `python -m hil_sim flight`.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh onboard ground  # the simulator runs both roles: the recorder, onboard rtk, ground adjust
exec .venv/bin/python -m hil_sim flight --out demo-output "$@"
