"""Non-collision module figures: CPN accuracy and speed, CCN validity, the gradient-projection baseline,
and the runtime Corrector, all on held-out data this run generates (one thread); and issue 18's compiled
CPN / CCN inference against the numpy networks, in the same run (`*_numpy_us` / `*_compiled_us`).

    python bench/collision_model.py [--json] [--quick] [--models DIR] [--compiled-only]

Held-out data: uniform samples for the CPN (plus boundary samples, the `cpn_boundary_*` figures); invalid
configurations from uniform sampling and from retargeted human hand trajectories for the CCN, the baseline
and the Corrector. Trajectories run through the Corrector in order, each output passed back as `previous`.

JSON keys:
    cpn_auc_min_link             float
    cpn_recall                   float
    cpn_config_fnr               float
    cpn_single_us_p50            float
    cpn_batch_cfg_per_s          float
    ccn_valid_frac               float
    ccn_mean_dev_rad             float
    baseline_valid_frac          float
    baseline_mean_dev_rad        float
    baseline_ms_p50              float
    n_invalid                    int
    corrector_colliding_outputs  int
    corrector_ms_p50             float
    corrector_ms_p99             float
    corrector_ms_p99_uniform     float
    corrector_ms_p99_trajectory  float
    corrector_untouched_ms_p50   float
    corrector_ccn_frac           float
    corrector_fallback_frac      float
    corrector_mean_dev_rad       float
    corrector_max_step_rad       float
    cpn_threshold                float
    cpn_precision                float
    cpn_config_fpr               float
    cpn_boundary_auc_min_link    float
    cpn_boundary_recall          float
    cpn_boundary_precision       float
    cpn_boundary_config_fnr      float
    cpn_boundary_config_fpr      float
    cpn_worst_link               str
    ccn_n_invalid                int
    ccn_valid_frac_uniform       float
    ccn_mean_dev_rad_uniform     float
    ccn_valid_frac_trajectory    float
    ccn_mean_dev_rad_trajectory  float
    ccn_us_p50                   float
    baseline_n                   int
    n_invalid_trajectory         int
    cpn_numpy_us                 float
    cpn_compiled_us              float
    cpn_speedup                  float
    ccn_numpy_us                 float
    ccn_compiled_us              float
    ccn_speedup                  float
    ccn_step_numpy_us            float
    ccn_step_compiled_us         float
    ccn_step_speedup             float
    correct_numpy_us             float
    correct_compiled_us          float
    correct_speedup              float
    compiled_n                   int
"""

from __future__ import annotations

import gc
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402  (sets one-thread environment before numpy loads)

import numpy as np  # noqa: E402

SEED = 777  # differs from every training seed


COMPILED_TARGETS = {"correct_compiled_us": "(live step p50 <= 100 us in all)"}


def _median_us(fn, inputs) -> float:
    return float(np.median(common.time_calls(fn, [(x,) for x in inputs]))) * 1e6


def compiled_inference(hand, checker, corrector, models, n: int) -> dict:
    """Per-call microseconds (medians over the same colliding inputs, interleaved rounds) of the numpy and
    the compiled CPN decision, CCN proposal, the Corrector's CCN step (proposal + bisection) and its
    single-configuration correct() after prepare (the live step's path), numpy vs compiled."""
    from teleprev.noncollision.corrector import Corrector

    fast = Corrector.load(models, hand, checker)
    nets = fast._nets
    q = hand.sample_uniform(8 * n, np.random.default_rng(SEED + 1))
    q = q[checker.pair_matrix(q).any(axis=1)][:n]
    prep_np = [corrector.prepare(x[None])[0] for x in q]
    prep_c = [fast.prepare(x[None])[0] for x in q]
    cases = {
        "cpn": (corrector.cpn.predicts_free, nets.cpn.predicts_free, q),
        "ccn": (corrector.ccn, nets.ccn, q),
        "ccn_step": (lambda x: corrector._shortest_predicted_free(x, corrector.ccn(x)),
                     lambda x: nets.propose_shorten(x[None]), q),
        "correct": (lambda k: corrector.correct(q[k], None, prep_np[k]), lambda k: fast.correct(q[k], None, prep_c[k]),
                    range(len(q))),
    }
    out: dict = {}
    gc.disable()
    for name, (numpy_fn, compiled_fn, inputs) in cases.items():
        numpy_fn(next(iter(inputs)))
        compiled_fn(next(iter(inputs)))
        rounds = [(_median_us(numpy_fn, inputs), _median_us(compiled_fn, inputs)) for _ in range(3)]
        out[f"{name}_numpy_us"] = float(np.median([r[0] for r in rounds]))
        out[f"{name}_compiled_us"] = float(np.median([r[1] for r in rounds]))
        out[f"{name}_speedup"] = out[f"{name}_numpy_us"] / out[f"{name}_compiled_us"]
    gc.enable()
    out["compiled_n"] = len(q)
    return out


def main() -> None:
    p = common.parser(__doc__)
    p.add_argument("--models", type=Path, default=None, help="models folder (default: the shipped models/)")
    p.add_argument("--compiled-only", action="store_true", help="only the numpy vs compiled inference figures")
    args = p.parse_args()

    from teleprev.noncollision import evaluate, sampling
    from teleprev.noncollision.projection import project
    from teleprev.pipeline.older_formats import NumpyCorrector
    from teleprev.robot.collision import SelfCollisionChecker
    from teleprev.robot.model import load_robot

    quick = args.quick
    hand = load_robot("leap_hand_right")
    checker = SelfCollisionChecker(hand)
    corrector = NumpyCorrector.load(args.models, hand, checker)  # the numpy networks, against the compiled ones
    cpn, ccn = corrector.cpn, corrector.ccn
    rng = np.random.default_rng(SEED)
    figures: dict = {}
    compiled_figs = compiled_inference(hand, checker, corrector, args.models, 500 if quick else 2000)
    if args.compiled_only:
        common.report("bench/collision_model.py: numpy vs compiled CPN/CCN inference (LEAP Hand, one thread)",
                      compiled_figs, COMPILED_TARGETS, args.json)
        return

    # ---- CPN: accuracy on fresh labelled data, speed -------------------------------------------
    n_u, n_b = (20_000, 10_000) if quick else (200_000, 50_000)
    cpn_figs = evaluate.cpn_heldout(hand, checker, cpn, n_u, n_b, seed=SEED)
    per_link = cpn_figs.pop("cpn_auc_per_link")
    figures.update({k: cpn_figs[k] for k in ("cpn_auc_min_link", "cpn_recall", "cpn_config_fnr")})
    q_single = hand.sample_uniform(2000 if quick else 10_000, rng)
    for q in q_single[:100]:
        cpn.prob(q)
    figures["cpn_single_us_p50"] = common.percentile(common.time_calls(cpn.prob, [(q,) for q in q_single]), 50) * 1e6
    batch = hand.sample_uniform(10_000, rng)
    rates = []
    for _ in range(3 if quick else 7):
        t = time.perf_counter()
        cpn.prob(batch)
        rates.append(len(batch) / (time.perf_counter() - t))
    figures["cpn_batch_cfg_per_s"] = float(np.median(rates))

    # ---- CCN alone and the baseline, on the same invalid configurations -------------------------------
    n_inv_u, n_inv_t = (8_000, 2_000) if quick else (80_000, 20_000)
    invalid = evaluate.invalid_set(hand, checker, n_inv_u, n_inv_t, seed=SEED)
    ccn_figs = evaluate.ccn_heldout(checker, ccn, invalid)
    figures.update({k: ccn_figs[k] for k in ("ccn_valid_frac", "ccn_mean_dev_rad")})
    t_ccn = common.time_calls(ccn, [(q,) for q in invalid.q[:2000]])

    # the baseline is ~10x slower per input: a seeded subset of the same inputs
    n_base = 500 if quick else 5_000
    pick = np.random.default_rng(SEED).choice(len(invalid.q), min(n_base, len(invalid.q)), replace=False)
    base_ok, base_dev, base_t = [], [], []
    for q in invalid.q[pick]:
        t = time.perf_counter()
        r = project(cpn, checker, hand, q)
        base_t.append(time.perf_counter() - t)
        base_ok.append(r.valid)
        base_dev.append(float(np.abs(r.q - q).mean()))
    base_ok = np.array(base_ok)  # valid: the exact checker passed the projection's answer
    figures.update({
        "baseline_valid_frac": float(base_ok.mean()),
        "baseline_mean_dev_rad": float(np.mean(base_dev)),
        "baseline_ms_p50": common.percentile(base_t, 50) * 1e3,
    })

    # ---- Corrector ---------------------------------------------------------------------------------
    # Outputs go into preallocated arrays and the cyclic GC is paused while timing, so the timings are the
    # Corrector's own, not the growing bookkeeping of this script.
    uniform_q = invalid.q[invalid.source == "uniform"]
    n_frames = len(uniform_q) + sum(len(t) for t in invalid.trajectories)
    outputs, inputs = np.empty((n_frames, 16)), np.empty((n_frames, 16))
    times, actions, from_traj = np.empty(n_frames), np.empty(n_frames, dtype=object), np.zeros(n_frames, dtype=bool)
    k = 0
    gc.disable()
    for q in uniform_q:  # independent inputs: no previous output
        t = time.perf_counter()
        c = corrector.correct(q)
        times[k] = time.perf_counter() - t
        outputs[k], inputs[k], actions[k] = c.q, q, c.action
        k += 1
    jumps = []
    for traj in invalid.trajectories:  # in order, as the pipeline runs it
        previous = None
        for q in traj:
            t = time.perf_counter()
            c = corrector.correct(q, previous)
            times[k] = time.perf_counter() - t
            outputs[k], inputs[k], actions[k], from_traj[k] = c.q, q, c.action, True
            if previous is not None:
                jumps.append(float(np.max(np.abs(c.q - previous))))
            previous = c.q
            k += 1
    gc.enable()
    fixed = actions != "untouched"  # the invalid inputs
    free_times = times[~fixed]
    times_inv = times[fixed]
    colliding = sampling.colliding(checker, outputs)  # independent (batched) check of every output, free ones too
    in_limits = np.all((outputs >= hand.lower) & (outputs <= hand.upper), axis=1)
    n_traj_invalid = int((fixed & from_traj).sum())
    outputs, inputs, actions = outputs[fixed], inputs[fixed], actions[fixed]
    figures.update({
        "n_invalid": int(fixed.sum()),
        "corrector_colliding_outputs": int((colliding | ~in_limits).sum()),
        "corrector_ms_p50": common.percentile(times_inv, 50) * 1e3,
        "corrector_ms_p99": common.percentile(times_inv, 99) * 1e3,
        "corrector_ms_p99_uniform": common.percentile(times[fixed & ~from_traj], 99) * 1e3,
        "corrector_ms_p99_trajectory": common.percentile(times[fixed & from_traj], 99) * 1e3,
        "corrector_untouched_ms_p50": common.percentile(free_times, 50) * 1e3 if len(free_times) else float("nan"),
        "corrector_ccn_frac": float((actions == "ccn").mean()),
        "corrector_fallback_frac": float((actions == "fallback").mean()),
        "corrector_mean_dev_rad": float(np.abs(outputs - inputs).mean()),
        "corrector_max_step_rad": float(np.max(jumps)) if jumps else float("nan"),
    })
    extra = {
        **{
            k: v
            for k, v in cpn_figs.items()
            if k.startswith("cpn_boundary_") or k in ("cpn_threshold", "cpn_precision", "cpn_config_fpr")
        },
        "cpn_worst_link": min(per_link, key=per_link.get),
        **{k: v for k, v in ccn_figs.items() if k not in figures},
        "ccn_us_p50": common.percentile(t_ccn, 50) * 1e6,
        "baseline_n": int(len(pick)),
        "n_invalid_trajectory": n_traj_invalid,
    }
    figures.update(extra)
    figures.update(compiled_figs)
    targets = {
        **COMPILED_TARGETS,
        "cpn_auc_min_link": ">= 0.995 (uniform held-out)",
        "cpn_recall": ">= 0.995",
        "cpn_config_fnr": "<= 0.005",
        "cpn_single_us_p50": "<= 50",
        "ccn_valid_frac": ">= 0.95",
        "corrector_colliding_outputs": "== 0",
        "n_invalid": ">= 100,000",
        "corrector_ms_p99": "<= 1.0",
    }
    common.report("bench/collision_model.py: CPN, CCN, projection baseline, Corrector (LEAP Hand, one thread)",
                  figures, targets, args.json)


if __name__ == "__main__":
    main()
