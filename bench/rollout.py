"""A trained policy in the loop: a tiny ACT rolled out on the sim rig, measured as a session.

    python bench/rollout.py [--json] [--quick]

Records a short demo on the default sim rig, exports it, trains a tiny ACT with lerobot-train (2 steps,
CPU, no pretrained backbone: tests/helpers/policies.py), then rolls it out for 2 episodes of about 4 s
(engaged 0.5 s into each) through the real path (teleprev.live.rollout.rollout, as `teleprev rollout` runs it).

    rollout_commands          commands sent to the arm (each tick also sends the hand's)
    rollout_audit_failures    violations `teleprev audit` finds in the rollout's commands (and hand states)
    policy_hz                 inferences a second while inferring (1 / mean inference time)
    command_gap_ms_max        the longest interval between two commands of one engaged run, on the command
                              stamps (teleprev.session.summary: the figure bench/realtime.py reports)

It also prints the figures of bench/episode_figures.py (episode_timing_err_ms_max) and
bench/dataset_figures.py (dataset_replay_ok, filtered_export_ok) where those modules exist; null where not.
--quick: episodes of 2.5 s, and not those figures (their benches' own quick runs measure them).

JSON keys:
    rollout_commands        int
    rollout_audit_failures  int
    policy_hz               float
    command_gap_ms_max      float
    actions_handed          int
    frames_without_action   int
    train_s                 float
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
import common  # noqa: E402

TARGETS = {"rollout_commands": ">= 300", "rollout_audit_failures": "0", "command_gap_ms_max": "<= 25"}
OTHERS = {"episode_figures": ("episode_timing_err_ms_max",),
          "dataset_figures": ("dataset_replay_ok", "filtered_export_ok")}


def other_figures(folder: Path) -> dict:
    """The figures of the other benches' modules where they exist (None for a module that is missing)."""
    out = {}
    for module, keys in OTHERS.items():
        try:
            measure = importlib.import_module(module).measure
        except ModuleNotFoundError:
            out.update(dict.fromkeys(keys))
            continue
        work = folder / module
        work.mkdir()
        found = measure(work)
        out.update({k: found.get(k) for k in keys})
    return out


def rollout(folder: Path, episodes: int, episode_s: float) -> dict:
    from teleprev import topics
    from teleprev.evaluation.audit import audit_session
    from teleprev.live.rollout.lerobot_policy import LeRobotPolicy
    from teleprev.live.rollout.rollout import Rollout, RolloutOptions, check_rollout
    from teleprev.session.summary import summarize
    from tests.helpers.policies import train_tiny_act
    from tests.helpers.sessions import record_sim

    demo = folder / "demo.mcap"
    record_sim(demo, seconds=4.0, engage_after=0.5)
    teleprev = str(Path(sys.executable).with_name("teleprev"))
    subprocess.run([teleprev, "export", str(demo), "--repo-id", "bench/demo", "--root", str(folder / "demo")],
                   check=True, capture_output=True)
    started = time.perf_counter()
    policy = train_tiny_act(folder / "demo", "bench/demo", folder / "train")
    train_s = time.perf_counter() - started
    out = folder / "rollout.mcap"
    options = RolloutOptions(policy=policy, out=out, episodes=episodes, episode_time_s=episode_s, engage_after_s=0.5)
    plan = check_rollout(options)
    run = Rollout(options, plan, LeRobotPolicy.load(policy))
    result = run.run()
    assert not result.unconnected, result.unconnected
    audit = audit_session(out)
    summary = summarize(out)
    stats = run.runner.stats
    return {
        "rollout_commands": sum(s.count for s in summary.streams if s.topic == topics.COMMAND_ARM),
        "rollout_audit_failures": sum(len(s.violations) for s in audit.streams) + int(bool(audit.hand_state_colliding)),
        "policy_hz": stats.policy_hz(),
        "command_gap_ms_max": summary.sender.gap_ms_max if summary.sender else float("nan"),
        "actions_handed": stats.handed,
        "frames_without_action": stats.starved,
        "train_s": train_s,
    }


def main() -> None:
    p = common.parser(__doc__)
    args = p.parse_args()
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    with tempfile.TemporaryDirectory(prefix="bench_rollout_") as tmp:
        folder = Path(tmp)
        figures = rollout(folder, 2, 2.5 if args.quick else 4.0)
        if not args.quick:
            figures.update(other_figures(folder))
    common.report("policy rollout on the sim rig (tiny ACT)", figures, TARGETS, args.json)


if __name__ == "__main__":
    main()
