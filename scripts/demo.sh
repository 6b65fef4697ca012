#!/usr/bin/env bash
# Set up (scripts/setup.sh), then teleprev's main job on the simulated physics rig: record a session, look at it,
# export it to a LeRobot dataset, replay it to the simulated robot, and evaluate it.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export PATH="$PWD/.venv/bin:$PATH"
out=sessions/demo
rm -rf "$out" datasets/out/teleprev_demo
mkdir -p "$out"

echo "== 1/5 record: two pick-and-place episodes on the simulated rig in a MuJoCo world (preview, then execute"
echo "   0.3 s into each); the world marks each episode a success or failure when it ends"
teleprev record rigs/sim_physics.toml --out "$out/demo.mcap" --task pick_place --episodes 2 --episode-time 20 --engage-after 0.3

echo "== 2/5 what was recorded, with each episode's outcome"
teleprev info "$out/demo.mcap"

echo "== 3/5 export to a LeRobot dataset"
teleprev export "$out/demo.mcap" --repo-id local/teleprev_demo --root datasets/out/teleprev_demo

echo "== 4/5 replay the first episode to the simulated robot, asking for 2x (teleprev slows down where 2x would break a speed limit)"
teleprev replay "$out/demo.mcap" --episode 0 --to sim --speed 2 --engage-after 0.5 --no-preview

echo "== 5/5 re-run the pipeline on the recording (metrics, bit-identical reproduction), and play it into the"
echo "   physics world again: each episode's outcome with the recorded and with the re-computed commands"
teleprev eval "$out/demo.mcap" --physics --out "$out/report.json" --plots "$out/plots"
echo "session, report and plots in $out/; dataset in datasets/out/teleprev_demo"
