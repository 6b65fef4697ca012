#!/usr/bin/env bash
# Set up (scripts/setup.sh) and run the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
# The tests run a corpus on a real local Ray instance, so they install the optional `ray` extra (about
# 240 MB, which the demo and a plain setup leave out) and fail, rather than skip, if it is missing; likewise
# the hardware SDKs (`xarm`, `leap`: a few MB), which the tests drive against emulated hardware, and `train`
# (accelerate, for lerobot-train in tests/live/test_rollout_loop.py).
bash scripts/setup.sh --extra ray --extra xarm --extra leap --extra train
export TELEPREV_REQUIRE_RAY=1
exec .venv/bin/python -m pytest -q "$@"
