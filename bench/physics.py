"""The physics world's speed (issue 39): stepping against the clock, and rendering with the world stepping.

    python bench/physics.py [--json] [--quick]

physics_realtime_x   simulated seconds per wall second, the slowest task: the xArm6 + LEAP Hand moving
                     (every joint on a smooth target) with the task's objects, stepped at 500 Hz alone on
                     one core; physics_realtime_x[task] per task; physics_realtime_x_cpu the same per
                     second of the process's CPU time (what a quiet core would give)
render_fps           640x480 colour frames per wall second from the front camera, the world stepping
                     1/30 s between frames, on the same core (Mesa's llvmpipe held to one thread)
eval_physics_*       `teleprev eval --physics` on a session recorded here on the physics rig (4 episodes of
                     3 s; --quick 1): eval_physics_realtime_x the world seconds both plays stepped per wall
                     second they took (the world stepped as fast as it goes, on one core);
                     eval_physics_session_x the session's seconds per wall second of the whole evaluation
                     (re-run and both plays); eval_physics_agree whether the recorded commands, played
                     again, give every episode the mark the live world gave it
realtime_physics_*   bench/realtime.py --rig physics: unattended physics-rig sessions (preview in a pty)
                     beside 8 busy processes (--quick: 1 session, 1 busy), measured where the robot feels
                     them: arm faults, the longest command gap, sender lateness, audit failures
demo_success_rate    per task, the share of the simulated operator's episodes that world/success.py
                     judges a success, through the rig's retarget, Corrector and command planner into
                     the physics world, in lock step off the wall clock (teleprev/evaluation/demos.py):
                     20 episodes of each task (seeds 0..19), the operator watching the world;
                     demo_success_rate_min the lowest task's
demo_success_without_corrector   the same per task with the CCN not applied (the retargeted hand where
                     the exact check finds it free, else the last free target held; the swept check on)
demo_success_without_guard       the same per task with no hand self-collision check at all (bench only)
--quick: one episode of pick_place for each of the three, instead of 20 of every task; --demos N sets the
episodes per task, --jobs N runs them in N processes; --task T (repeatable) prints only the demo figures, of
task T (no timings, eval, real-time check or rollout).
rollout_success_rate the policy scored: `teleprev record` on the physics rig (rollout_demos episodes of
                     pick_place by the watching operator, each marked by the world), `teleprev export`, a
                     small ACT trained by lerobot-train on the CPU (rollout_train_steps steps; no pretrained
                     backbone), then `teleprev rollout` on the physics rig (rollout_episodes episodes), its
                     episodes' marks by the world: the share that succeeded (lerobot-eval's pc_success / 100).
                     rollout_demo_success_rate: the demos' own. --quick: 1 demo, 2 steps, 1 episode,
                     of 6 s each (too short for a pick-and-place: a smoke run of the path, rate 0).
                     A GPU makes the training minutes instead of hours at the sizes a policy needs to
                     learn the task (tens of thousands of steps, pretrained backbone); the CPU run here
                     is the path, not a trained policy.

JSON keys:
    physics_realtime_x      float
    render_fps              float
    physics_realtime_x_cpu  float
    core                    int
    steal_ms                float
    eval_physics_realtime_x float
    eval_physics_session_x  float
    eval_physics_agree      bool
    eval_physics_episodes   int
    realtime_physics_sessions     int
    realtime_physics_arm_faults   int
    realtime_physics_gap_ms_max   float
    realtime_physics_late_ms_p99  float
    demo_success_rate_min   float
    demo_episodes           int
    rollout_success_rate    float
    rollout_demo_success_rate  float
    rollout_demos           int
    rollout_train_steps     int
    rollout_episodes        int
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402  (sets one-thread environment before numpy loads)

# One core for the GL rasteriser too, and headless EGL; both are read when GL first loads.
os.environ.setdefault("LP_NUM_THREADS", "1")
os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

FRAME_S = 1 / 30


def _pin_to_one_core() -> int:
    core = max(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {core})
    return core


def _moving_targets(world, home: dict[str, float], t: float) -> dict[str, float]:
    """Every joint swinging slowly about its start (arm +-0.15 rad, fingers 0.2..0.9 rad)."""
    arm = {n: home[n] + 0.15 * np.sin(0.8 * t + i) for i, n in enumerate(world.compiled.arm_joints)}
    hand = {n: 0.55 + 0.35 * np.sin(1.3 * t + i) for i, n in enumerate(world.compiled.effector_joints)}
    return arm | hand


def realtime_x(task: str, sim_s: float) -> tuple[float, float]:
    """Simulated seconds per wall second, and per second of this process's CPU time (the same figure
    without the time other processes took the core away: the shared machine's share of the gap)."""
    from teleprev.world.layout import task_layout
    from teleprev.world.world import PhysicsWorld

    world = PhysicsWorld("leap_hand", task_layout(task, 0))
    home = world.joint_positions()
    command_ns = 10_000_000  # a new target every 10 ms, as the command sender's ticks would bring them
    steps = int(sim_s * 1e9 // command_ns)
    start, cpu = time.perf_counter(), time.process_time()
    for k in range(steps):
        world.set_targets(_moving_targets(world, home, k * command_ns / 1e9))
        world.advance_to((k + 1) * command_ns)
    return sim_s / (time.perf_counter() - start), sim_s / (time.process_time() - cpu)


def render_fps(frames: int) -> float:
    from teleprev.world.camera import WorldCamera
    from teleprev.world.layout import task_layout
    from teleprev.world.world import PhysicsWorld

    world = PhysicsWorld("leap_hand", task_layout("pour", 0))
    home = world.joint_positions()
    with WorldCamera(world, "front", 640, 480) as camera:
        camera.render()  # the GL context and its buffers, outside the timing
        start = time.perf_counter()
        for k in range(frames):
            world.set_targets(_moving_targets(world, home, k * FRAME_S))
            world.advance_to(int((k + 1) * FRAME_S * 1e9))
            camera.render()
        return frames / (time.perf_counter() - start)


def _all_cores(cores: set[int]):
    """While inside: this process (and what it starts) on `cores` again, then back on the one it had."""
    import contextlib

    @contextlib.contextmanager
    def scope():
        pinned = os.sched_getaffinity(0)
        os.sched_setaffinity(0, cores)
        try:
            yield
        finally:
            os.sched_setaffinity(0, pinned)

    return scope()


def eval_figures(quick: bool, cores: set[int]) -> dict:
    """`teleprev eval --physics` on a physics-rig session recorded here (the recording on every core; the
    evaluation in this process, on its one core)."""
    import tempfile

    import realtime

    from teleprev.evaluation.evaluate import evaluate

    episodes = 1 if quick else 4
    folder = Path(tempfile.mkdtemp(prefix="physics-eval-"))
    out = folder / "session.mcap"
    with _all_cores(cores):
        code = realtime.record(realtime.PHYSICS_RIG, out, 3.0 * episodes, episodes, 0.3)
    if code != 0:
        raise SystemExit(f"bench/physics.py: recording the session for eval --physics failed (exit {code})")
    start = time.perf_counter()
    session = evaluate([out], physics=True).report["sessions"][0]
    wall = time.perf_counter() - start
    played = session["physics"]
    return {"eval_physics_realtime_x": played["world_s"] / played["wall_s"],
            "eval_physics_session_x": session["overall"]["duration_s"] / wall,
            "eval_physics_agree": played["agree"], "eval_physics_episodes": len(played["episodes"])}


def realtime_figures(quick: bool, cores: set[int]) -> dict:
    """bench/realtime.py --rig physics: its figures (on every core, beside its busy processes)."""
    import tempfile

    import realtime

    with _all_cores(cores):
        return realtime.physics_figures(1 if quick else 4, 4.0 if quick else 20.0, 1 if quick else 8,
                                        Path(tempfile.mkdtemp(prefix="physics-realtime-")))


HAND_RUNS = {"demo_success_rate": "corrector", "demo_success_without_corrector": "no_corrector",
             "demo_success_without_guard": "no_guard"}


def _demo(job: tuple[str, int, str]) -> tuple[str, int, str, bool, str]:
    from teleprev.evaluation.demos import run_demo
    from teleprev.rig import load_rig

    task, seed, hand = job
    result = run_demo(load_rig(Path(__file__).resolve().parents[1] / "rigs" / "sim_physics.toml"), task, seed, hand)
    return task, seed, hand, result.outcome.success, result.outcome.reason


def demo_success(tasks: tuple[str, ...], episodes: int, hands: dict[str, tuple[str, ...]], jobs: int) -> dict:
    """{figure: {task: share of successes}}: `episodes` seeds of each task per hand side (hands: figure ->
    the tasks it runs), each judged by world/success.py; every episode's outcome is printed to stderr."""
    import multiprocessing

    work = [(task, seed, HAND_RUNS[figure]) for figure, run in hands.items() for task in run
            for seed in range(episodes)]
    if jobs > 1:
        with multiprocessing.get_context("fork").Pool(jobs) as pool:
            done = list(pool.imap_unordered(_demo, work))
    else:
        done = [_demo(job) for job in work]
    wins: dict[tuple[str, str], list[bool]] = {}
    for task, seed, hand, success, reason in sorted(done):
        print(f"demo {hand:12s} {task:12s} seed {seed:2d}: {'success' if success else 'failure'}: {reason}",
              file=sys.stderr)
        wins.setdefault((hand, task), []).append(success)
    return {figure: {task: sum(wins[HAND_RUNS[figure], task]) / episodes for task in run}
            for figure, run in hands.items()}


ROLLOUT_TASK = "pick_place"
ROLLOUT_EPISODE_S = 16.0  # an operator's pick-and-place (10-14 s after its start) with its rest


def _teleprev(*args, ok: tuple[int, ...] = (0,)) -> None:
    """A `teleprev` command as a user runs it; its output when it exits otherwise than `ok`."""
    import subprocess

    command = [str(Path(sys.executable).with_name("teleprev")), *map(str, args)]
    ran = subprocess.run(command, capture_output=True, text=True)
    print(ran.stdout[-600:], file=sys.stderr)
    if ran.returncode not in ok:
        raise RuntimeError(f"{' '.join(command)} failed ({ran.returncode}):\n{ran.stdout[-2000:]}{ran.stderr[-2000:]}")


def _success_rate(session: Path) -> float:
    from teleprev.session.episodes import success_by_task
    from teleprev.session.reader import SessionReader

    with SessionReader(session) as reader:
        rate = success_by_task(reader.episodes())[ROLLOUT_TASK]
    return (rate.pc_success or 0.0) / 100.0


def policy_rollout(folder: Path, demos: int, steps: int, episodes: int, episode_s: float = ROLLOUT_EPISODE_S) -> dict:
    """Record demos on the physics rig, export them, train a small ACT, roll it out there: the rollout's
    success rate by the world's marks (see the module docstring)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.helpers.policies import train_tiny_act

    rig = Path(__file__).resolve().parents[1] / "rigs" / "sim_physics.toml"
    demo = folder / "demos.mcap"
    _teleprev("record", rig, "--task", ROLLOUT_TASK, "--episodes", demos, "--episode-time", episode_s,
              "--engage-after", 1.0, "--no-preview", "--no-cues", "--out", demo)
    _teleprev("export", demo, "--repo-id", "bench/physics_demos", "--root", folder / "demos")
    policy = train_tiny_act(folder / "demos", "bench/physics_demos", folder / "train", steps=steps,
                            timeout_s=max(300.0, 2.0 * steps))
    rolled = folder / "rollout.mcap"
    # Exit 1 where the policy never acted in time to engage (a slow CPU inference): recorded and judged all
    # the same, each such episode a failure.
    _teleprev("rollout", "--policy", policy, "--config", rig, "--task", ROLLOUT_TASK, "--episodes", episodes,
              "--episode-time", episode_s, "--engage-after", 1.0, "--out", rolled, ok=(0, 1))
    return {"rollout_success_rate": _success_rate(rolled), "rollout_demo_success_rate": _success_rate(demo),
            "rollout_demos": demos, "rollout_train_steps": steps, "rollout_episodes": episodes}


def main() -> None:
    parser = common.parser(__doc__)
    parser.add_argument("--demos", type=int, default=20, help="episodes of each task for the demo figures")
    parser.add_argument("--jobs", type=int, default=1, help="processes for the demo episodes")
    parser.add_argument("--rollout-demos", type=int, default=10, help="demos the rolled-out policy learns from")
    parser.add_argument("--train-steps", type=int, default=300, help="lerobot-train steps of that policy")
    parser.add_argument("--rollout-episodes", type=int, default=5, help="episodes of its rollout")
    parser.add_argument("--task", action="append", default=[], help="only the demo figures, of this task (repeatable)")
    args = parser.parse_args()
    from teleprev.world.layout import TASKS

    unknown = sorted(set(args.task) - set(TASKS))
    if unknown:
        parser.error(f"--task {', '.join(unknown)}: not a task (tasks: {', '.join(TASKS)})")
    if args.task:
        tasks = tuple(t for t in TASKS if t in args.task)
        demos = demo_success(tasks, args.demos, dict.fromkeys(HAND_RUNS, tasks), args.jobs)
        figures = demos | {"demo_success_rate_min": min(demos["demo_success_rate"].values()),
                           "demo_episodes": args.demos}
        common.report(f"bench/physics.py: the simulated operator's demos ({', '.join(tasks)})", figures,
                      {"demo_success_rate_min": ">= 0.8"}, args.json)
        return

    cores = os.sched_getaffinity(0)
    core = _pin_to_one_core()
    steal_before = common.steal_ms()
    measured = {task: realtime_x(task, 1.0 if args.quick else 5.0) for task in TASKS}
    per_task = {task: wall for task, (wall, _) in measured.items()}
    fps = render_fps(15 if args.quick else 90)
    steal_after = common.steal_ms()
    figures = {"physics_realtime_x": min(per_task.values()), "render_fps": fps}
    figures |= {f"physics_realtime_x[{task}]": x for task, x in per_task.items()}
    figures["physics_realtime_x_cpu"] = min(cpu for _, cpu in measured.values())
    figures["core"] = core
    figures["steal_ms"] = (steal_after - steal_before) if steal_before is not None and steal_after is not None else None
    figures |= eval_figures(args.quick, cores)
    figures |= realtime_figures(args.quick, cores)
    with _all_cores(cores):  # the demos after the timings, on every core
        if args.quick:
            demos = demo_success(TASKS, 1, dict.fromkeys(HAND_RUNS, ("pick_place",)), 1)
            episodes = 1
        else:
            demos = demo_success(TASKS, args.demos, dict.fromkeys(HAND_RUNS, TASKS), args.jobs)
            episodes = args.demos
    figures |= demos
    figures["demo_success_rate_min"] = min(demos["demo_success_rate"].values())
    figures["demo_episodes"] = episodes
    os.environ.setdefault("HF_HUB_OFFLINE", "1")  # nothing downloaded: no pretrained backbone, no Hub
    with tempfile.TemporaryDirectory(prefix="bench_physics_") as tmp, _all_cores(cores):
        sizes = (1, 2, 1, 6.0) if args.quick else (args.rollout_demos, args.train_steps, args.rollout_episodes)
        figures |= policy_rollout(Path(tmp), *sizes)
    targets = {"physics_realtime_x": ">= 5", "render_fps": ">= 15", "eval_physics_realtime_x": ">= 5",
               "eval_physics_agree": "true", "realtime_physics_arm_faults": "0", "realtime_physics_gap_ms_max": "<= 25",
               "demo_success_rate_min": ">= 0.8"}
    common.report("bench/physics.py: the MuJoCo world on one core (xArm6 + LEAP Hand, 500 Hz)", figures, targets,
                  args.json)


if __name__ == "__main__":
    main()
