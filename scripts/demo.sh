#!/usr/bin/env bash
# Set up (scripts/setup.sh) and run teleprev's main job on the simulated rig.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export PATH="$PWD/.venv/bin:$PATH"
teleprev robot info leap_hand_right
teleprev robot check leap_hand_right --samples 5000
