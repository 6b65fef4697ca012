"""Pipeline figures: one step's time over the sim operator's five tasks, how often the Corrector acted,
the terminal preview's redraw rate while the pipeline runs at 120 Hz, and dex-retargeting for scale.

    python bench/pipeline.py [--json] [--quick] [--busy N]

Step timing drives the pure pipeline step directly (no device threads), with the default LEAP rig and
the shipped models: the operator's glove at 120 Hz and suit at 60 Hz, execution engaged after 1 s, the
arm's measured joints following the previous command. preview_fps runs a real recording of the
default sim rig with the terminal preview drawn into a 120 x 40 off-screen console; tcp_speed_ratio_max
is the fastest the arm's flange moved between consecutive commands of that recording (FK, `teleprev audit`'s
check) over the rig's cap (arm_tcp_speed, 1.0 m/s for the xArm): at most 1.

JSON keys:
    step_ms_p50                 float
    step_ms_p99                 float
    steps                       int
    corrected_frac              float
    fallback_frac               float
    ccn_frac                    float
    busy_processes              int
    step_thread                 str
    preview_fps                 float
    preview_render_ms_p50       float
    pipeline_hz_during_preview  float
    live_step_ms_p50            float
    tcp_speed_ratio_max         float
"""

from __future__ import annotations

import io
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402

import numpy as np  # noqa: E402

TASKS = ("pick_place", "hang", "pour", "box_rotation", "cup_stack")


def operator_inputs(task: str, seconds: float, seed: int = 0):
    """(t_ns, glove sample, suit sample or None) at 120 Hz; the suit updates every second glove sample."""
    from teleprev.human.smplx import HAND_POSE_NAMES, hand_pose_from_angles
    from teleprev.messages import JointSample, PoseSample
    from teleprev_devices.sim.operator import SimOperator

    op = SimOperator(seed, task, "fixed")
    wrist = None
    for k in range(int(seconds * 120)):
        t = k / 120.0
        t_ns = int(t * 1e9) + 1
        flexion, abduction = op.hand_angles(t)
        glove = JointSample(t_ns, HAND_POSE_NAMES, hand_pose_from_angles(flexion, abduction).reshape(45))
        if k % 2 == 0:
            position, quaternion = op.wrist(t)
            wrist = PoseSample(t_ns, "suit", position, quaternion)
        yield t_ns, glove, wrist


def step_timing(seconds: float) -> dict:
    from teleprev.assembly import build_pipeline
    from teleprev.messages import JointSample
    from teleprev.pipeline.step import PipelineState, StepInputs
    from teleprev.rig import load_rig

    pipeline = build_pipeline(load_rig())
    times, actions, per_task = [], [], {}
    for task in TASKS:
        state = PipelineState()
        arm = np.array([0.0, -0.35, -0.75, 0.0, 1.1, 0.0])
        hand = np.zeros(len(pipeline.effector_names))
        task_times = []
        for k, (t_ns, glove, wrist) in enumerate(operator_inputs(task, seconds)):
            inputs = StepInputs(
                t_ns,
                glove,
                wrist,
                JointSample(t_ns, pipeline.arm_names, arm),
                JointSample(t_ns, pipeline.effector_names, hand),
            )
            if k == 120:
                state, _ = pipeline.set_mode(state, "execute", inputs)
            t0 = time.perf_counter()
            result = pipeline.step(state, inputs)
            task_times.append(time.perf_counter() - t0)
            state = result.state
            actions.append(result.report["corrector"])
        times += task_times
        per_task[task] = common.percentile(task_times, 50) * 1e3
    actions = np.array(actions)
    return {
        "step_ms_p50": common.percentile(times, 50) * 1e3,
        "step_ms_p99": common.percentile(times, 99) * 1e3,
        "steps": len(times),
        "corrected_frac": float(np.isin(actions, ("ccn", "fallback")).mean()),
        "fallback_frac": float((actions == "fallback").mean()),
        "ccn_frac": float((actions == "ccn").mean()),
        **{f"step_ms_p50[{task}]": v for task, v in per_task.items()},
    }


def preview_rate(seconds: float) -> dict:
    """Frames the terminal preview draws per second during a real recording of the default sim rig, and
    the flange's fastest speed over its cap in that recording."""
    import tempfile

    from rich.console import Console

    from teleprev.evaluation.audit import audit_session
    from teleprev.live.record.run import run_script
    from teleprev.live.record.session import LiveSession, RecordOptions
    from teleprev.session.reader import SessionReader

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "preview.mcap"
        rec = LiveSession(RecordOptions(out=out))
        console = Console(file=io.StringIO(), width=120, height=40, force_terminal=True, color_system="truecolor")
        rec.start()
        try:
            stats = run_script(rec, seconds, 1, 1.0, console, "side", fps=60.0)
        finally:
            rec.stop()
        with SessionReader(out) as reader:
            steps = reader.topics["/pipeline/report"].message_count
        step_ns = rec.loop.stats.step_ns
        arm = next(s for s in audit_session(out).streams if s.topic == "/command/arm")
    return {
        "tcp_speed_ratio_max": arm.ratios["tcp_speed"],
        "preview_fps": stats.fps(),
        "preview_render_ms_p50": common.percentile(stats.render_s, 50) * 1e3,
        "pipeline_hz_during_preview": steps / seconds,
        "live_step_ms_p50": common.percentile(step_ns, 50) / 1e6,
    }


def dex_retargeting(seconds: float) -> dict:
    """dex-retargeting's vector retargeting of the same LEAP Hand (our URDF) on the same machine.

    Its inputs are fingertip vectors from the wrist, taken from the LEAP FK of our retargeted sim
    trajectories (no human hand model files are needed for timing). Installed with `uv sync --extra compare`.
    """
    try:
        from dex_retargeting.retargeting_config import RetargetingConfig
    except ImportError:
        return {"dexretargeting_ms_p50": None, "dexretargeting": "not installed (uv sync --extra compare)"}
    from teleprev.human.smplx import hand_pose_from_values
    from teleprev.retarget.hand import LeapRetargeter
    from teleprev.robot.model import load_robot

    hand = load_robot("leap_hand_right")
    retarget = LeapRetargeter(hand)
    tips = ["thumb_tip_head", "index_tip_head", "middle_tip_head", "ring_tip_head"]
    config = RetargetingConfig(
        type="vector", urdf_path=str(hand.urdf_path),
        target_origin_link_names=["palm_lower"] * 4, target_task_link_names=tips,
        target_link_human_indices=np.array([[0, 0, 0, 0], [1, 2, 3, 4]]), scaling_factor=1.0, low_pass_alpha=1.0,
    )
    solver = config.build()
    times = []
    for task in TASKS:
        for _, glove, _ in operator_inputs(task, seconds / len(TASKS)):
            poses = hand.fk(retarget(hand_pose_from_values(glove.names, glove.positions)))
            palm = poses.position("palm_lower")
            keypoints = np.array([palm] + [poses.position(t) for t in tips])
            vectors = keypoints[[1, 2, 3, 4]] - keypoints[[0, 0, 0, 0]]
            t0 = time.perf_counter()
            solver.retarget(vectors)
            times.append(time.perf_counter() - t0)
    return {
        "dexretargeting_ms_p50": common.percentile(times, 50) * 1e3,
        "dexretargeting_ms_p99": common.percentile(times, 99) * 1e3,
    }


def at_loop_priority(fn, *args):
    """(fn(*args), its thread's priority): run on a thread at the session loop's priority
    (teleprev/thread_priority.py), as the live steps run; the busy processes stay at the default."""
    import threading

    from teleprev.thread_priority import raise_this_thread

    out = {}

    def run():
        out["priority"] = raise_this_thread()
        out["value"] = fn(*args)

    thread = threading.Thread(target=run, name="steps")
    thread.start()
    thread.join()
    return out["value"], out["priority"]


def main() -> None:
    p = common.parser(__doc__)
    p.add_argument("--busy", type=int, default=0, help="busy processes beside the step timing")
    args = p.parse_args()
    seconds = 3.0 if args.quick else 30.0
    with common.Load(args.busy):
        figures, priority = at_loop_priority(step_timing, seconds)
    figures["busy_processes"] = args.busy
    figures["step_thread"] = priority
    figures.update(preview_rate(2.0 if args.quick else 12.0))
    figures.update(dex_retargeting(2.0 if args.quick else 30.0))
    targets = {
        "step_ms_p50": "<= 0.1", "step_ms_p99": "<= 0.5", "corrected_frac": "reported", "fallback_frac": "reported",
        "preview_fps": ">= 20 (pipeline at 120 Hz)", "dexretargeting_ms_p50": "for comparison",
        "tcp_speed_ratio_max": "<= 1",
    }
    common.report(f"bench/pipeline.py: one pipeline step (retarget + Corrector + IK + gate), one thread, "
                  f"{args.busy} busy processes beside it", figures, targets, args.json)


if __name__ == "__main__":
    main()
