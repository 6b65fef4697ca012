"""Foundation figures: FK (fast path vs pytorch-kinematics, batched), arm IK, exact self-collision.

    python bench/kinematics.py [--json] [--quick]

JSON keys:
    fk_single_us_p50              float
    fk_pk_single_us_p50           float
    fk_speedup_x                  float
    fk_batch_cfg_per_s            float
    fk_pk_batch_cfg_per_s         float
    ik_ms_p50                     float
    ik_ms_p99                     float
    ik_converged_frac             float
    ik_us_p50                     float
    ik_compiled_us_p50            float
    ik_compiled_us_p99            float
    ik_compiled_speedup_x         float
    arm_solve_us_p50              float
    arm_solve_compiled_us_p50     float
    arm_solve_compiled_speedup_x  float
    ik_compiled_converged_frac    float
    collision_check_us_p50        float
    collision_free_configs        int
    labels_per_s                  float
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402  (sets one-thread environment before numpy loads)

import numpy as np  # noqa: E402


def smooth_trajectory(ik, q0: np.ndarray, steps: int, rate_hz: float = 120.0) -> list[np.ndarray]:
    """A smooth 6-D path: a 15 cm Lissajous in position and +-0.3 rad swings in orientation."""
    from teleprev.transforms import axis_angle_to_matrix

    home = ik.pose(q0)
    out = []
    for k in range(steps):
        t = k / rate_hz
        target = home.copy()
        target[:3, 3] += 0.15 * np.array([np.sin(0.5 * t), np.sin(0.7 * t) * np.cos(0.3 * t), 0.5 * np.sin(0.4 * t)])
        swing = 0.3 * np.array([np.sin(0.6 * t), np.sin(0.45 * t), np.sin(0.35 * t)])
        target[:3, :3] = axis_angle_to_matrix(swing) @ home[:3, :3]
        out.append(target)
    return out


def main() -> None:
    args = common.parser(__doc__).parse_args()
    import torch

    torch.set_num_threads(1)
    from teleprev.robot.batched import BatchedKinematics
    from teleprev.robot.collision import SelfCollisionChecker
    from teleprev.robot.ik import ArmIK
    from teleprev.robot.model import load_robot

    rng = np.random.default_rng(0)
    hand = load_robot("leap_hand_right")
    pk_fk = BatchedKinematics(hand)
    n_single = 300 if args.quick else 3000
    q_single = hand.sample_uniform(n_single, rng)

    for q in q_single[:50]:  # warm up both paths
        hand.fk(q)
        pk_fk.fk(q)
    fast = common.time_calls(hand.fk, [(q,) for q in q_single])
    slow = common.time_calls(pk_fk.fk, [(q,) for q in q_single[: n_single // 3]])

    batch = hand.sample_uniform(10_000, rng)
    rates = []
    for _ in range(3 if args.quick else 7):
        t = time.perf_counter()
        hand.fk(batch)
        rates.append(len(batch) / (time.perf_counter() - t))
    pk_rates = []
    with torch.no_grad():
        qt = torch.as_tensor(batch)
        for _ in range(3):
            t = time.perf_counter()
            pk_fk.fk_tensor(qt)
            pk_rates.append(len(batch) / (time.perf_counter() - t))

    arm = load_robot("xarm6")
    ik = ArmIK(arm, "link_eef")
    q = np.array([0.0, -0.3, -0.6, 0.0, 0.9, 0.0])
    targets = smooth_trajectory(ik, q, 1200 if args.quick else 7200)
    ik_times, converged = [], 0
    for target in targets:
        t = time.perf_counter()
        result = ik.solve(target, q)
        ik_times.append(time.perf_counter() - t)
        converged += result.converged
        q = result.q

    # The pipeline's arm solve (ArmRetargeter: target, then IK from the constant-velocity warm start) and
    # IK alone, numpy against compiled on the same targets, interleaved so that both see the same noise.
    from teleprev.pipeline.older_formats import NumpyArmIK, NumpyArmRetargeter
    from teleprev.retarget.arm import ArmRetargeter

    numpy_arm, compiled_arm = NumpyArmRetargeter(NumpyArmIK(arm, "link_eef")), ArmRetargeter(ArmIK(arm, "link_eef"))
    q_home = np.array([0.0, -0.3, -0.6, 0.0, 0.9, 0.0])
    anchor = numpy_arm.anchor(np.eye(4), q_home)
    wrists = []  # the wrist poses that ask for the targets (identity anchor wrist, no scale or frame change)
    for target in targets:
        w = np.eye(4)
        w[:3, :3] = target[:3, :3] @ anchor.tcp[:3, :3].T
        w[:3, 3] = target[:3, 3] - anchor.tcp[:3, 3]
        wrists.append(w)
    compiled_arm.solve(anchor, wrists[0], q_home)  # loads the kernels (from numba's cache after setup.sh)
    arm_us = {False: [], True: []}
    ik_us = {False: [], True: []}
    ik_converged = {False: 0, True: 0}
    state = {False: (q_home, q_home), True: (q_home, q_home)}
    retargeters = {False: numpy_arm, True: compiled_arm}  # keyed by: compiled?
    for k, wrist in enumerate(wrists):
        for c in ((False, True) if k % 2 else (True, False)):
            retargeter = retargeters[c]
            q, q_before = state[c]
            start = 2.0 * q - q_before
            t = time.perf_counter()
            result, _ = retargeter.solve(anchor, wrist, start)
            arm_us[c].append(time.perf_counter() - t)
            t = time.perf_counter()
            retargeter.ik.solve(targets[k], start)
            ik_us[c].append(time.perf_counter() - t)
            ik_converged[c] += result.converged
            state[c] = (result.q, q)

    checker = SelfCollisionChecker(hand)
    pool = hand.sample_uniform(4000 if args.quick else 20_000, rng)
    free = pool[~checker.pair_matrix(pool).any(axis=1)]
    checker.check(free[0])
    check_times = common.time_calls(checker.check, [(q,) for q in free])
    label_rates = []
    for _ in range(3 if args.quick else 7):
        qs = hand.sample_uniform(1000, rng)
        t = time.perf_counter()
        checker.labels(qs)
        label_rates.append(len(qs) / (time.perf_counter() - t))

    fk_us = common.percentile(fast, 50) * 1e6
    pk_us = common.percentile(slow, 50) * 1e6
    figures = {
        "fk_single_us_p50": fk_us,
        "fk_pk_single_us_p50": pk_us,
        "fk_speedup_x": pk_us / fk_us,
        "fk_batch_cfg_per_s": float(np.median(rates)),
        "fk_pk_batch_cfg_per_s": float(np.median(pk_rates)),
        "ik_ms_p50": common.percentile(ik_times, 50) * 1e3,
        "ik_ms_p99": common.percentile(ik_times, 99) * 1e3,
        "ik_converged_frac": converged / len(targets),
        "ik_us_p50": common.percentile(ik_us[False], 50) * 1e6,
        "ik_compiled_us_p50": common.percentile(ik_us[True], 50) * 1e6,
        "ik_compiled_us_p99": common.percentile(ik_us[True], 99) * 1e6,
        "ik_compiled_speedup_x": common.percentile(ik_us[False], 50) / common.percentile(ik_us[True], 50),
        "arm_solve_us_p50": common.percentile(arm_us[False], 50) * 1e6,
        "arm_solve_compiled_us_p50": common.percentile(arm_us[True], 50) * 1e6,
        "arm_solve_compiled_speedup_x": common.percentile(arm_us[False], 50) / common.percentile(arm_us[True], 50),
        "ik_compiled_converged_frac": ik_converged[True] / len(targets),
        "collision_check_us_p50": common.percentile(check_times, 50) * 1e6,
        "collision_free_configs": int(len(free)),
        "labels_per_s": float(np.median(label_rates)),
    }
    targets_text = {
        "fk_speedup_x": ">= 10",
        "fk_batch_cfg_per_s": ">= 50,000 (numpy, the data-generation path on CPU)",
        "ik_ms_p99": "<= 1.0",
        "ik_converged_frac": ">= 0.999",
        "collision_check_us_p50": "<= 300",
        "labels_per_s": ">= 3,000",
    }
    common.report(
        "bench/kinematics.py: LEAP Hand FK and collision, xArm6 IK (one thread)", figures, targets_text, args.json
    )


if __name__ == "__main__":
    main()
