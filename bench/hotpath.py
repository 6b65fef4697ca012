"""Issue 18's compiled hot path: the LEAP Hand's exact self-collision check and the glove sample's
preparation (one thread).

    python bench/hotpath.py [--json] [--quick]

Compares the compiled checker (numba kernels) with the fcl checker it replaced and with a
vectorised-numpy version of the same separating-axis test, checks it against FCL on uniform random
configurations, times the checker the pipeline runs (SelfCollisionChecker: compiled, FCL within the
margin; its answers must equal FCL's exactly), and times what compiling costs: cold (empty kernel cache, in a fresh
process), from
the cache (--quick: from the cache only), and whether `teleprev --help` stays fast. The glove preparation
(Pipeline.prepare_hands: decode,
checks, angles, retargeting, clip, and for the LEAP Hand the exact check) is timed with the numpy
arithmetic (the earliest sessions') and the compiled one (teleprev/kernels/glove.py), the two
interleaved sample by sample: one sample as the live step prepares it, and a session's worth as eval does.

JSON keys:
    collision_check_us_p50                              float
    collision_first_contact_us_p50                      float
    collision_check_uniform_us_p50                      float
    collision_first_contact_uniform_us_p50              float
    compiled_batch_us_per_config                        float
    pipeline_checker_us_p50                             float
    pipeline_checker_uniform_us_p50                     float
    fcl_collision_check_us_p50                          float
    fcl_first_contact_us_p50                            float
    numpy_vectorised_collision_us_p50                   float
    numpy_vectorised_disagreements                      int
    compiled_fk_us_p50                                  float
    numpy_fk_us_p50                                     float
    free_configs_timed                                  int
    prepare_hand_us_p50_numpy                           float
    prepare_hand_us_p50_compiled                        float
    prepare_hand_speedup                                float
    prepare_hands_batch_us_per_sample_numpy             float
    prepare_hands_batch_us_per_sample_compiled          float
    prepare_gripper_hand_us_p50_numpy                   float
    prepare_gripper_hand_us_p50_compiled                float
    prepare_gripper_hand_speedup                        float
    prepare_gripper_hands_batch_us_per_sample_numpy     float
    prepare_gripper_hands_batch_us_per_sample_compiled  float
    compiled_vs_fcl_disagreements                       int
    compiled_vs_fcl_margin_side                         int
    compiled_vs_fcl_missed_contacts                     int
    compiled_vs_fcl_label_disagreements                 int
    compiled_vs_fcl_configs                             int
    pipeline_checker_vs_fcl_disagreements               int
    cached_import_and_first_call_s                      float
    help_s                                              float
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402  (sets one-thread environment before numpy loads)

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

# Run in a fresh interpreter: import the checker and answer one check, reporting the seconds taken.
_FIRST_CALL = """
import time, teleprev
from teleprev.robot.model import load_robot
hand = load_robot("leap_hand_right")
t = time.perf_counter()
from teleprev.robot.compiled_collision import CompiledSelfCollisionChecker
CompiledSelfCollisionChecker(hand).check(hand.neutral())
first = time.perf_counter() - t
from teleprev.kernels import warm
t = time.perf_counter()
warm()
print(first, time.perf_counter() - t)
"""


class NumpySat:
    """The same test in vectorised numpy, the alternative to compiled code: numpy FK, bounding spheres
    over all box pairs, then the 15-axis separating-axis test on the survivors as array expressions."""

    _NEXT = np.array([1, 2, 0])
    _AFTER = np.array([2, 0, 1])

    def __init__(self, compiled):
        self.model = compiled.model
        self.margin = compiled.margin
        boxes = compiled.boxes  # teleprev.kernels.collision.BoxTable
        links, shape_link = boxes.links, []
        for k, (_, start, stop) in enumerate(links):
            shape_link += [k] * (stop - start)
        pa, pb, lp = [], [], []
        for p, (la, lb) in enumerate(boxes.pairs):
            for a in range(links[la, 1], links[la, 2]):
                for b in range(links[lb, 1], links[lb, 2]):
                    pa.append(a), pb.append(b), lp.append(p)
        self.pa, self.pb, self.lp = np.array(pa), np.array(pb), np.array(lp)
        self.n_pairs = len(boxes.pairs)
        self.model_link = boxes.shape_link
        local = np.zeros((len(boxes.shape_local), 4, 4))
        local[:, :3], local[:, 3, 3] = boxes.shape_local, 1.0
        self.local = local
        self.half = boxes.shape_size[:, :3]
        self.reach2 = (boxes.shape_size[self.pa, 3] + boxes.shape_size[self.pb, 3] + self.margin) ** 2

    def pairs(self, q: np.ndarray) -> np.ndarray:
        boxes = self.model.fk(q).world[self.model_link] @ self.local
        centre = boxes[:, :3, 3]
        d = centre[self.pb] - centre[self.pa]
        near = np.flatnonzero(np.einsum("ki,ki->k", d, d) <= self.reach2)
        a, b = self.pa[near], self.pb[near]
        ra, rb = boxes[a, :3, :3], boxes[b, :3, :3]
        rel = np.swapaxes(ra, 1, 2) @ rb
        t = (np.swapaxes(ra, 1, 2) @ d[near][..., None])[..., 0]
        q_abs = np.abs(rel)
        ha, hb = self.half[a], self.half[b]
        face_a = np.abs(t) - ha - (q_abs @ hb[..., None])[..., 0]
        face_b = np.abs((t[:, None, :] @ rel)[:, 0]) - (ha[:, None, :] @ q_abs)[:, 0] - hb
        i1, i2 = self._NEXT[:, None], self._AFTER[:, None]  # rows: i
        j1, j2 = self._NEXT[None, :], self._AFTER[None, :]  # columns: j
        i, j = np.arange(3)[:, None], np.arange(3)[None, :]
        p_abs = q_abs + 1e-12
        dist = np.abs(t[:, i2] * rel[:, i1, j] - t[:, i1] * rel[:, i2, j])
        reach = (ha[:, i1] * p_abs[:, i2, j] + ha[:, i2] * p_abs[:, i1, j]
                 + hb[:, j1] * p_abs[:, i, j2] + hb[:, j2] * p_abs[:, i, j1])
        length = np.sqrt(rel[:, i1, j] ** 2 + rel[:, i2, j] ** 2)
        apart = ((face_a > self.margin).any(axis=1) | (face_b > self.margin).any(axis=1)
                 | (dist - reach > self.margin * length).reshape(len(near), 9).any(axis=1))
        out = np.zeros(self.n_pairs, dtype=bool)
        out[self.lp[near[~apart]]] = True
        return out


def _subprocess_seconds(code: str, env: dict) -> list[float]:
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True, cwd=ROOT)
    return [float(v) for v in out.stdout.split()]


def compile_costs(quick: bool) -> dict:
    """Cold and cached first-call cost in fresh processes, against a kernel cache of their own; with
    `quick`, the cached cost only, from the project's cache (compiling every kernel takes minutes)."""
    figures = {}
    if quick:
        cached_first, _ = _subprocess_seconds(_FIRST_CALL, dict(os.environ))
    else:
        with tempfile.TemporaryDirectory() as cache:
            env = {**os.environ, "NUMBA_CACHE_DIR": cache}
            cold_first, cold_warm = _subprocess_seconds(_FIRST_CALL, env)
            cached_first, cached_warm = _subprocess_seconds(_FIRST_CALL, env)
        figures |= {"first_compile_s": cold_first, "setup_warm_s": cold_first + cold_warm}
    cli = Path(sys.executable).with_name("teleprev")  # the project's environment's command, as a user runs it
    if not cli.exists():
        sys.exit(f"bench/hotpath.py: no {cli}: run it with the project's environment (.venv/bin/python)")
    help_times = []
    for _ in range(2 if quick else 5):
        t = time.perf_counter()
        subprocess.run([str(cli), "--help"], capture_output=True, check=True)
        help_times.append(time.perf_counter() - t)
    return figures | {"cached_import_and_first_call_s": cached_first, "help_s": float(np.median(help_times))}


def agreement(hand, fcl_checker, compiled, strict, pipeline_checker, n: int, rng) -> dict:
    """Configurations whose colliding link pairs differ between the compiled check and FCL, in batches."""
    disagree = margin_side = missed = label_diff = pipeline_diff = 0
    for start in range(0, n, 5000):
        q = hand.sample_uniform(min(5000, n - start), rng)
        expected = fcl_checker.pair_matrix(q)
        ours = compiled.pair_matrix(q)
        pipeline_diff += int((pipeline_checker.pair_matrix(q) != expected).any(axis=1).sum())
        deep = strict.pair_matrix(q)
        differ = (ours != expected).any(axis=1)
        # margin-side: the compiled check adds pairs (and drops none) that are not overlapping by more than 1 nm
        extra_only = differ & ~(expected & ~ours).any(axis=1) & ~(deep & ~expected).any(axis=1)
        disagree += int(differ.sum())
        margin_side += int(extra_only.sum())
        missed += int((expected & ~ours).any(axis=1).sum())
        label_diff += int(
            (compiled.labels_from_pairs(ours) != fcl_checker.labels_from_pairs(expected)).any(axis=1).sum()
        )
    return {
        "compiled_vs_fcl_disagreements": disagree,
        "compiled_vs_fcl_margin_side": margin_side,
        "compiled_vs_fcl_missed_contacts": missed,
        "compiled_vs_fcl_label_disagreements": label_diff,
        "compiled_vs_fcl_configs": n,
        "pipeline_checker_vs_fcl_disagreements": pipeline_diff,
    }


def prepare_hand_figures(quick: bool, rng) -> dict:
    """Pipeline.prepare_hands per glove sample, numpy vs compiled, for the LEAP Hand (angles, retargeting,
    exact check) and a parallel gripper (the angles only), alone and in a batch."""
    from teleprev.assembly import build_pipeline
    from teleprev.human.smplx import HAND_POSE_NAMES, hand_pose_from_angles
    from teleprev.messages import JointSample
    from teleprev.rig import default_rig_path, load_rig

    n = 1000 if quick else 5000
    gloves = [JointSample(k, HAND_POSE_NAMES, hand_pose_from_angles(rng.uniform(-0.2, 1.8, 15),
                                                                     rng.uniform(-0.4, 0.4, 15)).ravel())
              for k in range(n)]
    figures = {}
    for label, rig in (("", default_rig_path()), ("gripper_", default_rig_path().parent / "sim_gripper.toml")):
        old, new = (build_pipeline(load_rig(rig), session_format=f) for f in (2, 3))
        for g in gloves[:50]:  # load the kernels, warm the caches
            old.prepare_hands([g]), new.prepare_hands([g])
        t_old, t_new = [], []
        for g in gloves:
            t_old += common.time_calls(old.prepare_hands, [([g],)])
            t_new += common.time_calls(new.prepare_hands, [([g],)])
        batch = {}
        for name, p in (("numpy", old), ("compiled", new)):
            t = time.perf_counter()
            p.prepare_hands(gloves)
            batch[name] = (time.perf_counter() - t) / n * 1e6
        figures[f"prepare_{label}hand_us_p50_numpy"] = common.percentile(t_old, 50) * 1e6
        figures[f"prepare_{label}hand_us_p50_compiled"] = common.percentile(t_new, 50) * 1e6
        figures[f"prepare_{label}hand_speedup"] = (
            figures[f"prepare_{label}hand_us_p50_numpy"] / figures[f"prepare_{label}hand_us_p50_compiled"]
        )
        figures[f"prepare_{label}hands_batch_us_per_sample_numpy"] = batch["numpy"]
        figures[f"prepare_{label}hands_batch_us_per_sample_compiled"] = batch["compiled"]
    return figures


def main() -> None:
    args = common.parser(__doc__).parse_args()
    from teleprev.kernels import boxes as boxes_kernels
    from teleprev.robot.collision import FclSelfCollisionChecker, SelfCollisionChecker
    from teleprev.robot.compiled_collision import CompiledSelfCollisionChecker
    from teleprev.robot.model import load_robot

    quick = args.quick
    rng = np.random.default_rng(18)
    hand = load_robot("leap_hand_right")
    fcl_checker = FclSelfCollisionChecker(hand)
    pipeline_checker = SelfCollisionChecker(hand)
    compiled = CompiledSelfCollisionChecker(hand)
    strict = CompiledSelfCollisionChecker(hand, margin=-boxes_kernels.MARGIN)
    numpy_sat = NumpySat(compiled)

    pool = hand.sample_uniform(4000 if quick else 20_000, rng)
    pool_pairs = compiled.pair_matrix(pool)
    free = pool[~pool_pairs.any(axis=1)]
    uniform = pool[: len(free)]
    for q in uniform[:100]:  # load the kernels, warm the caches
        compiled.check(q), compiled.collides(q), fcl_checker.check(q), numpy_sat.pairs(q), pipeline_checker.check(q)

    def p50_us(fn, qs):
        return common.percentile(common.time_calls(fn, [(q,) for q in qs]), 50) * 1e6

    numpy_disagree = sum(bool((numpy_sat.pairs(q) != pool_pairs[i]).any()) for i, q in enumerate(pool[:2000]))
    batch = hand.sample_uniform(10_000, rng)
    compiled.pair_matrix(batch[:10])
    t = time.perf_counter()
    compiled.pair_matrix(batch)
    batch_us = (time.perf_counter() - t) / len(batch) * 1e6

    figures = {
        "collision_check_us_p50": p50_us(compiled.check, free),
        "collision_first_contact_us_p50": p50_us(compiled.collides, free),
        "collision_check_uniform_us_p50": p50_us(compiled.check, uniform),
        "collision_first_contact_uniform_us_p50": p50_us(compiled.collides, uniform),
        "compiled_batch_us_per_config": batch_us,
        "pipeline_checker_us_p50": p50_us(pipeline_checker.check, free),
        "pipeline_checker_uniform_us_p50": p50_us(pipeline_checker.check, uniform),
        "fcl_collision_check_us_p50": p50_us(fcl_checker.check, free),
        "fcl_first_contact_us_p50": p50_us(fcl_checker.collides, free),
        "numpy_vectorised_collision_us_p50": p50_us(numpy_sat.pairs, free[: min(len(free), 2000)]),
        "numpy_vectorised_disagreements": numpy_disagree,
        "compiled_fk_us_p50": p50_us(compiled.kinematics.world, free),
        "numpy_fk_us_p50": p50_us(hand.fk, free),
        "free_configs_timed": int(len(free)),
    }
    figures.update(prepare_hand_figures(quick, rng))
    figures.update(agreement(hand, fcl_checker, compiled, strict, pipeline_checker, 10_000 if quick else 100_000, rng))
    figures.update(compile_costs(quick))
    targets = {
        "collision_check_us_p50": "<= 20 (collision-free configs: every pair examined)",
        "compiled_vs_fcl_disagreements": "0, or margin-side only",
        "compiled_vs_fcl_missed_contacts": "0",
        "pipeline_checker_vs_fcl_disagreements": "0 (FCL decides within the margin)",
        "cached_import_and_first_call_s": "no compile on the record/eval path",
        "help_s": "<= 0.8",
        "prepare_hand_us_p50_compiled": "part of the step's <= 100 (LEAP Hand: includes the exact check)",
    }
    common.report("bench/hotpath.py: compiled LEAP Hand self-collision (one thread)", figures, targets, args.json)


if __name__ == "__main__":
    main()
