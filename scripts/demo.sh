#!/usr/bin/env bash
# Set up directgeo and run the whole product on one simulated survey: a ground server, the base station sending
# RTCM3 over a simulated radio and, through the autopilot stand-in, as GPS_RTCM_DATA, the rover companion with
# real-time RTK and the autopilot link, the pre-flight page's go, the flight, the upload, the ground's RTK and
# adjustment jobs and their report; then print what was measured and where everything is (about 5 minutes).
# Extra arguments go to `python -m hil_sim flight` (e.g. --seeded, --speed 4, --out DIR).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh onboard ground  # the demo runs both roles: the drone, the base station and the ground app
exec .venv/bin/python -m hil_sim flight --out demo-output "$@"
