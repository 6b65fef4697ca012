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
# Two workers (pytest-xdist): most tests wait on real time (sessions, sockets, subprocesses, the benches'
# quick runs), so two share the two cores of a small machine and the suite stays within its 10 minutes.
# --dist worksteal: each worker takes half of the tests, in order (a module's fixtures set up once), and
# the first to run out takes over what the other has not started. The default (load) hands the first
# worker a fixed first chunk, an eighth of the tests: here the benches' quick runs and the bimanual
# tests, the longest stretch of the suite, which the second worker could not take a share of.
# A few tests time real-time paths end to end (emulated hardware answering in time); two workers on two
# cores can starve them where no real robot would be, so a test that fails is run once more alone, and
# the run says which did: a test that fails alone too fails the suite.
if .venv/bin/python -m pytest -q -n 2 --dist worksteal "$@"; then
  exit 0
fi
echo "test.sh: running the failed tests again, one at a time, on a machine without the other worker"
exec .venv/bin/python -m pytest -q --lf --lfnf=none "$@"
