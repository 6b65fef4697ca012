#!/usr/bin/env bash
# Set up (scripts/setup.sh) and run the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
# The tests run a corpus on a real local Ray instance, so they install the optional `ray` extra (about
# 240 MB, which the demo and a plain setup leave out) and fail, rather than skip, if it is missing; likewise
# the hardware SDKs (`xarm`, `leap`: a few MB; `realsense`: about 30 MB), which the tests drive against emulated hardware, and `train`
# (accelerate, for lerobot-train in tests/live/test_rollout_loop.py).
bash scripts/setup.sh --extra ray --extra xarm --extra leap --extra realsense --extra train
# The XR page's tests (tests/webxr) open it in a real browser: Debian's Chromium, driven by playwright (in the
# dev group), with Meta's IWER (npm, pinned in tests/webxr/browser/package-lock.json) emulating a Quest 3.
if ! command -v chromium >/dev/null 2>&1 && ! command -v chromium-browser >/dev/null 2>&1; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium >/dev/null
fi
npm ci --prefix tests/webxr/browser --no-audit --no-fund --silent
exec .venv/bin/python -m pytest -q "$@"
