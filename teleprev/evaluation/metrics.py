"""The numbers `teleprev eval` reports for a re-run session, per episode and overall.

    steps                      pipeline steps (glove samples)
    collision_before_frac      steps whose retargeted hand was in self-collision (the Corrector's verdict)
    collision_after_frac       hand commands in self-collision, by the exact checker (must be 0)
    deviation_mean_rad/_max    max |corrected - retargeted| over joints, mean and worst over steps
    untouched/ccn/fallback     what the Corrector did, as counts
    arm_speed_max, hand_speed_max      rad/s (m/s for a gripper), arm_accel_max, hand_accel_max, arm_jerk_max,
    hand_jerk_max                      of the commands by divided differences on their stamps, each run from
                                       rest (teleprev/pipeline/derivatives.py: the definition audit uses)
    latency_ms_p50/_p99        pipeline step time in this re-run
    held_frac                  steps whose input was flagged and held (stale, invalid, out of range)
    reproduced                 re-run equals recorded, bit for bit, on every command and corrected target
"""

from __future__ import annotations

import json

import numpy as np

from teleprev import topics
from teleprev.evaluation.command_tracks import CommandTrack
from teleprev.evaluation.reproduce import Rerun
from teleprev.pipeline.derivatives import stream_peaks

HOLD_FLAGS = {"glove_stale", "glove_invalid", "glove_out_of_range", "suit_stale", "suit_invalid", "suit_out_of_range"}


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Bit-identical, NaN (nothing produced) matching NaN."""
    return a.shape == b.shape and bool(np.all((a == b) | (np.isnan(a) & np.isnan(b))))


def _peaks(track: CommandTrack, history, span: tuple[int, int]) -> tuple[float, float, float]:
    """Speed, acceleration and jerk peaks of the re-run commands of a track that end within span, each run
    measured whole, from where its controller starts it (the actuator's history)."""
    have = ~np.isnan(track.rerun).any(axis=1)
    if have.sum() < 2:
        return 0.0, 0.0, 0.0
    t = track.t_ns[have]
    return stream_peaks(t, track.rerun[have], rests=history.for_stream(t) if history is not None else None,
                        window=span).worst()


def step_metrics(r: Rerun, rows: np.ndarray, hand_collides: np.ndarray | None, span: tuple[int, int]) -> dict:
    """Metrics over the steps selected by the boolean mask `rows`, and the commands stamped within `span`
    (start, stop)."""
    n = int(rows.sum())
    out: dict = {"steps": n}
    if n == 0:
        return out
    action = r.corrector[rows]
    corrected = action != "held"
    retargeted, fixed = r.rerun[topics.RETARGETED][rows], r.rerun[topics.CORRECTED][rows]
    stepped = (
        ~np.isnan(retargeted).all(axis=1) if retargeted.shape[1] else np.zeros(n, dtype=bool)
    )  # idle steps retarget nothing
    dev = np.nanmax(np.abs(fixed[stepped] - retargeted[stepped]), axis=1) if stepped.any() else np.zeros(0)
    dev = dev[~np.isnan(dev)]
    out["collision_before_frac"] = float(np.isin(action, ("ccn", "fallback")).sum() / max(corrected.sum(), 1))
    arm, hand = (r.commands[k].select(*span) for k in (topics.COMMAND_ARM, topics.COMMAND_HAND))
    if hand_collides is not None:
        inside = (r.commands[topics.COMMAND_HAND].t_ns >= span[0]) & (r.commands[topics.COMMAND_HAND].t_ns < span[1])
        commanded = ~np.isnan(hand.rerun).any(axis=1)
        out["collision_after_frac"] = float(hand_collides[inside][commanded].sum() / max(commanded.sum(), 1))
    out["deviation_mean_rad"] = float(dev.mean()) if len(dev) else 0.0
    out["deviation_max_rad"] = float(dev.max()) if len(dev) else 0.0
    for name in ("untouched", "ccn", "fallback"):
        out[name] = int((action == name).sum())
    for side, k in (("arm", topics.COMMAND_ARM), ("hand", topics.COMMAND_HAND)):
        peaks = _peaks(r.commands[k], r.actuators.get(k), span)
        out[f"{side}_speed_max"], out[f"{side}_accel_max"], out[f"{side}_jerk_max"] = peaks
    lat = r.latency_ns[rows] / 1e6
    out["latency_ms_p50"], out["latency_ms_p99"] = float(np.percentile(lat, 50)), float(np.percentile(lat, 99))
    flags = [r.flags[i] for i in np.flatnonzero(rows)]
    out["held_frac"] = float(sum(bool(HOLD_FLAGS & set(f)) for f in flags) / n)
    out["reproduced"] = (
        _same(r.rerun[topics.CORRECTED][rows], r.recorded[topics.CORRECTED][rows]) and arm.same() and hand.same()
    )
    return out


def dropped_inputs(meta: dict) -> int:
    """Messages the recording lost before they reached the file (the loop's queue and the recorder's)."""
    total = 0
    for record, key in (("loop", "dropped"), ("recorder", "dropped")):
        raw = meta.get(record, {}).get(key)
        if raw:
            try:
                value = json.loads(raw)
                total += sum(value.values()) if isinstance(value, dict) else int(value)
            except (ValueError, TypeError):
                pass
    return total


def session_metrics(r: Rerun, checker=None) -> dict:
    """{"overall": {...}, "episodes": [{...}, ...]} for one re-run session."""
    hand_cmd = r.commands[topics.COMMAND_HAND].rerun
    collides = None
    if checker is not None:
        collides = np.zeros(len(hand_cmd), dtype=bool)
        have = np.flatnonzero(~np.isnan(hand_cmd).any(axis=1))
        if len(have):
            collides[have] = checker.pair_matrix(hand_cmd[have]).any(axis=1)
    everything = (np.iinfo(np.int64).min, np.iinfo(np.int64).max)
    overall = step_metrics(r, np.ones(len(r.t_ns), dtype=bool), collides, everything)
    overall["dropped_inputs"] = dropped_inputs(r.metadata)
    overall["duration_s"] = r.duration_s
    overall["rerun_wall_s"] = r.wall_s
    overall["realtime_x"] = r.duration_s / r.wall_s if r.wall_s > 0 else 0.0
    episodes = []
    for ep in r.episodes:
        stop = ep.stop_ns if ep.stop_ns is not None else np.iinfo(np.int64).max
        m = step_metrics(r, (r.t_ns >= ep.start_ns) & (r.t_ns < stop), collides, (ep.start_ns, stop))
        episodes.append({"episode": ep.index, "task": ep.task, "discarded": ep.discarded, "outcome": ep.outcome, **m})
    return {"overall": overall, "episodes": episodes}
