"""Two arms and two hands (issue 40): bimanual sessions on rigs/sim_bimanual.toml, measured.

    python bench/bimanual.py [--json] [--quick] [--busy N]

Records unattended `teleprev record rigs/sim_bimanual.toml` sessions (10 of 8 s beside 8 busy processes, the
realtime bench's load; --quick: 1 of 5 s beside 2), then, quiet, re-runs the first session's raw streams
through a fresh BimanualDriver and exports it.

    step_ms_p99               both sides' pipeline step (the left side's step + the right side's, for each
                              pair of glove samples), quiet, from the recorded streams (target <= 1.0)
    bimanual_realtime_faults  arm controller faults (device errors not injected) in the loaded sessions
    command_gap_ms_max        the longest interval between two commands of one engaged run, either side, on
                              the command stamps (each side's /command/<side>/tick, as bench/realtime.py)
    audit_failures            sessions whose commands `teleprev audit` faults, each side against its own limits
    export_roundtrip_exact    `teleprev export` of the first session loaded with LeRobotDataset (pyav): action
                              and observation.state named left_arm.joint1 .. right_hand.15 in that order, and each
                              side's half equal, value for value, to an export of that side's streams alone (which
                              may hold a frame more at an end: its streams may stop a tick after the other's)
    sessions                  sessions recorded (and loaded: > 100 commands per side)
    cross_side_colliding_commands  a scripted episode drives the two hands through each other on purpose
                              (tests/helpers/bimanual_drive.py: the real BimanualDriver with its cross-side
                              guard, each side's real CommandPlanner ticked at 120 Hz, offline): sender ticks
                              at which the two robots' commands touch, checked exactly by FCL (target 0)
    cross_side_held           targets the guard held in that episode (target >= 1)
    cross_side_unguarded_colliding  the same episode without the guard: its ticks in contact (the script
                              does bring the sides together)
    emulated_bimanual_session_ok  two xArm controller emulators and two Dynamixel buses driven through the real
                              plugins and SDKs in one session (tests/helpers/emulated_bimanual.py): an actuator
                              process each, each side's written commands equal to its recorded ones, every arm
                              write received by its own controller, no controller fault

    lerobot_train_ok          the first session's default `teleprev export` (action and observation.state of 44,
                              the right side's camera cam_right as observation.images.cam_right) trains a tiny ACT
                              with lerobot-train two steps on CPU (tests/helpers/policies.py), its checkpoint saved
                              with those features

JSON keys:
    step_ms_p99               float
    step_ms_p50               float
    bimanual_realtime_faults  int
    command_gap_ms_max        float
    audit_failures            int
    export_roundtrip_exact    bool
    sessions                  int
    cross_side_colliding_commands  int
    cross_side_held           int
    cross_side_unguarded_colliding  int
    emulated_bimanual_session_ok  bool
    lerobot_train_ok          bool
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PYTHONPATH = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import common  # noqa: E402  (sets one-thread environment before numpy loads)

import numpy as np  # noqa: E402

CLI = [sys.executable, "-m", "teleprev.cli.app"]
RIG = ROOT / "rigs" / "sim_bimanual.toml"
SIDES = ("left", "right")
TARGETS = {"step_ms_p99": "<= 1.0", "bimanual_realtime_faults": "0", "command_gap_ms_max": "<= 25",
           "audit_failures": "0", "export_roundtrip_exact": "true", "cross_side_colliding_commands": "0",
           "cross_side_held": ">= 1", "lerobot_train_ok": "true", "emulated_bimanual_session_ok": "true"}


def measure(path: Path) -> dict:
    """Faults, command gaps (per side, from its ticks) and the audit of one session."""
    from teleprev import topics
    from teleprev.evaluation.audit import audit_session
    from teleprev.pipeline.bimanual import side_topic
    from teleprev.session.reader import SessionReader
    from teleprev.session.summary import SenderSummary, summarize

    faults = [e for e in summarize(path).device_events if e.event == "error" and "injected" not in e.message]
    gaps, commands = [], []
    with SessionReader(path) as reader:
        for side in SIDES:
            gaps.append(SenderSummary.from_session(reader, side_topic(topics.COMMAND_TICK, side)).gap_ms_max)
            commands.append(sum(1 for _ in reader.messages([side_topic(topics.COMMAND_ARM, side)])))
    audit = audit_session(path)
    return {"faults": len(faults), "gap_ms": max(gaps), "audit_ok": audit.ok, "ok": min(commands) > 100}


def step_times(path: Path) -> list[float]:
    """Milliseconds of both sides' steps per pair of glove samples, the session's raw streams re-run quiet."""
    from teleprev.bimanual import build_bimanual_driver
    from teleprev.rig import load_rig
    from teleprev.session.reader import SessionReader

    rig = load_rig(RIG)
    driver = build_bimanual_driver(rig)
    gloves = {side: f"/glove/{rig.sides[side].devices['glove']}/hand" for side in SIDES}
    inputs = [t for side in SIDES for t in driver.inputs[side].topics.__dict__.values() if t]
    per_side: dict[str, list[float]] = {side: [] for side in SIDES}
    with SessionReader(path) as reader:
        for msg in reader.messages(inputs):
            start = time.perf_counter_ns()
            driver.feed(msg)
            took = (time.perf_counter_ns() - start) / 1e6
            for side, topic in gloves.items():
                if msg.topic == topic:
                    per_side[side].append(took)
    n = min(len(v) for v in per_side.values())
    pairs = np.asarray(per_side["left"][:n]) + np.asarray(per_side["right"][:n])
    return list(pairs[20:])  # the first steps warm the kernels' caches


def export_roundtrip(path: Path, folder: Path) -> bool:
    """The bimanual export, loaded with LeRobotDataset, against each side exported alone from its own topics
    (no export splits an episode at a gap here: one side's streams may pause where the other's do not, and the
    comparison is of values)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from teleprev.export.recipe import recipe_from_table
    from teleprev.export.run import ExportOptions, export
    from tests.helpers.bimanual_export import within

    def recipe(state: list[str], action: list[str], name: str):
        return recipe_from_table({"export": {"max_gap_ms": 60_000.0}, "feature": [
            {"name": "observation.state", "streams": state}, {"name": "action", "streams": action}]}, name)

    def rows(ds) -> dict[str, np.ndarray]:
        return {f: np.stack([ds[i][f].numpy() for i in range(len(ds))]) for f in ("action", "observation.state")}

    names = [f"{side}_{role}.{j}" for side in SIDES
             for role, joints in (("arm", [f"joint{i}" for i in range(1, 7)]), ("hand", [str(i) for i in range(16)]))
             for j in joints]
    export(ExportOptions([path], "lab/bimanual", folder / "both",
                         recipe(["arm_state", "effector_state"], ["arm_command", "effector_command"], "both.toml")))
    both = LeRobotDataset("lab/bimanual", root=folder / "both", video_backend="pyav")
    wrong = [f"{f} names" for f in ("action", "observation.state") if both.meta.features[f]["names"] != names]
    values, half = rows(both), len(names) // 2
    for k, side in enumerate(SIDES):
        export(ExportOptions([path], f"lab/{side}", folder / side, recipe(
            [f"/arm/arm_{side}/state", f"/hand/hand_{side}/state"], [f"/command/{side}/arm", f"/command/{side}/hand"],
            f"{side}.toml")))
        alone = rows(LeRobotDataset(f"lab/{side}", root=folder / side, video_backend="pyav"))
        for f, v in values.items():
            if not within(v[:, k * half:(k + 1) * half], alone[f]):
                wrong.append(f"{side} {f}: {v.shape[0]} frames, alone {alone[f].shape[0]}, not equal in order")
    if len(both) <= 30:
        wrong.append(f"{len(both)} frames")
    for line in wrong:
        print(f"export round trip: {line}", file=sys.stderr)
    return not wrong


def train_ok(path: Path, folder: Path) -> bool:
    """A tiny ACT trains two steps on the session's default export; its saved config has the 44-vectors and
    the camera."""
    from tests.helpers.policies import train_tiny_act

    done = subprocess.run([*CLI, "export", str(path), "--repo-id", "lab/bimanual_act", "--root", str(folder / "act")],
                          capture_output=True, text=True, env={**os.environ, "PYTHONPATH": PYTHONPATH}, timeout=600)
    if done.returncode != 0:
        print(f"lerobot train: export exited {done.returncode}: {done.stderr.strip()[-2000:]}", file=sys.stderr)
        return False
    try:
        policy = train_tiny_act(folder / "act", "lab/bimanual_act", folder / "act_train", timeout_s=600)
    except AssertionError as exc:
        print(f"lerobot train: {exc}", file=sys.stderr)
        return False
    config = json.loads((policy / "config.json").read_text())
    shapes = {k: v["shape"] for k, v in {**config["input_features"], **config["output_features"]}.items()}
    wanted = {"observation.state": [44], "action": [44], "observation.images.cam_right": [3, 120, 160]}
    wrong = {k: shapes.get(k) for k, v in wanted.items() if shapes.get(k) != v}
    if wrong:
        print(f"lerobot train: the policy's features {wrong}, not {wanted}", file=sys.stderr)
    return not wrong


def drive(guard: bool):
    """The scripted episode that drives the two hands through each other, with or without the guard."""
    from teleprev.rig import load_rig
    from tests.helpers.bimanual_drive import drive_through

    return drive_through(load_rig(RIG), guard=guard)


def emulated_ok(folder: Path) -> bool:
    from tests.helpers.emulated_bimanual import check_emulated_run, run_emulated_bimanual

    (folder / "emulated").mkdir()
    try:
        wrong = check_emulated_run(run_emulated_bimanual(folder / "emulated"))
    except AssertionError as exc:
        wrong = [str(exc)]
    for line in wrong:
        print(f"emulated bimanual session: {line}", file=sys.stderr)
    return not wrong


def main() -> None:
    import realtime  # its unattended `teleprev record` runner

    p = common.parser(__doc__)
    p.add_argument("--busy", type=int, default=None, help="busy processes beside the sessions (default 8, --quick 2)")
    args = p.parse_args()
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    busy = args.busy if args.busy is not None else (2 if args.quick else 8)
    count, seconds = (1, 5.0) if args.quick else (10, 8.0)
    with tempfile.TemporaryDirectory(prefix="bench_bimanual_") as tmp:
        folder = Path(tmp)
        sessions, results = [], []
        with common.Load(busy):
            for k in range(count):
                out = folder / f"{k:02d}.mcap"
                code = realtime.record(RIG, out, seconds, 1, 1.5)
                if code == 0 and out.is_file():
                    sessions.append(out)
        for out in sessions:
            results.append(measure(out))
            print(f"{out.name}: faults {results[-1]['faults']}, gap {results[-1]['gap_ms']:.1f} ms, "
                  f"audit {'ok' if results[-1]['audit_ok'] else 'FAILED'}", file=sys.stderr, flush=True)
        steps = step_times(sessions[0]) if sessions else []
        guarded, unguarded = drive(True), drive(False)
        emulated = emulated_ok(folder)
        exact = export_roundtrip(sessions[0], folder / "datasets") if sessions else False
        trained = train_ok(sessions[0], folder / "datasets") if sessions else False
    figures = {
        "step_ms_p99": common.percentile(steps, 99) if steps else float("nan"),
        "step_ms_p50": common.percentile(steps, 50) if steps else float("nan"),
        "bimanual_realtime_faults": sum(r["faults"] for r in results),
        "command_gap_ms_max": max((r["gap_ms"] for r in results), default=float("nan")),
        "audit_failures": sum(not r["audit_ok"] for r in results),
        "export_roundtrip_exact": bool(exact),
        "sessions": sum(r["ok"] for r in results),
        "cross_side_colliding_commands": guarded.colliding_commands,
        "cross_side_held": guarded.held,
        "cross_side_unguarded_colliding": unguarded.colliding_commands,
        "emulated_bimanual_session_ok": emulated,
        "lerobot_train_ok": trained,
        "busy_processes": busy,
    }
    title = f"bench/bimanual.py: {len(sessions)} bimanual sessions of {seconds:g} s beside {busy} busy processes"
    with contextlib.redirect_stdout(sys.stderr if args.json else sys.stdout):  # the table; the JSON alone last
        common.report(title, figures, TARGETS)
    if args.json:
        print(json.dumps({k: None if isinstance(v, float) and v != v else v for k, v in figures.items()}))


if __name__ == "__main__":
    main()
