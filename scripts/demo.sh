#!/usr/bin/env bash
# Set up (scripts/setup.sh), then teleprev's main job on the simulated rig: record a session, look at it,
# export it to a LeRobot dataset, replay it to the simulated robot, and evaluate it.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export PATH="$PWD/.venv/bin:$PATH"
out=sessions/demo
rm -rf "$out" datasets/out/teleprev_demo
mkdir -p "$out"

echo "== 1/5 record: two pick-and-place episodes on the simulated rig (preview, then execute after 3 s)"
teleprev record --out "$out/demo.mcap" --task pick_place --duration 24 --episodes 2 --engage-after 3

echo "== 2/5 what was recorded"
teleprev info "$out/demo.mcap"

echo "== 3/5 export to a LeRobot dataset"
teleprev export "$out/demo.mcap" --repo-id local/teleprev_demo --root datasets/out/teleprev_demo

echo "== 4/5 replay the first episode to the simulated robot, asking for 2x (teleprev slows down where 2x would break a speed limit)"
teleprev replay "$out/demo.mcap" --episode 0 --to sim --speed 2 --engage-after 0.5 --no-preview

echo "== 5/5 re-run the pipeline on the recording: metrics, and bit-identical reproduction"
teleprev eval "$out/demo.mcap" --out "$out/report.json" --plots "$out/plots"
echo "session, report and plots in $out/; dataset in datasets/out/teleprev_demo"
