"""Retargeted human hand trajectories: the configurations the Corrector sees in use.

A trajectory visits hand shapes (open, power grasp / fist, pinch, spread, crossed fingers) in random order,
each varied at random, moving between them with minimum-jerk profiles and a slow wobble on every angle,
sampled at the pipeline rate. The finger angles become an SMPL-X hand pose and go through the default
LEAP retargeting, as the live pipeline does; fists and crossed fingers retarget into self-collision.
"""

from __future__ import annotations

import numpy as np

from teleprev.human.smplx import JOINT_INDEX, hand_pose_from_angles
from teleprev.retarget.hand import LeapRetargeter
from teleprev.robot.model import RobotModel

FINGERS = ("index", "middle", "ring", "pinky")
SHAPES = ("open", "fist", "pinch", "spread", "crossed")


def _angles(flex: dict[str, tuple[float, float, float]], abd: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    f, a = np.zeros(15), np.zeros(15)
    for finger, values in flex.items():
        for i, v in enumerate(values):
            f[JOINT_INDEX[f"{finger}{i + 1}"]] = v
    for finger, v in abd.items():
        a[JOINT_INDEX[f"{finger}1"]] = v
    return f, a


def shape_angles(shape: str, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(flexion, abduction) of one hand shape, randomly varied (radians; abduction + towards the thumb)."""
    u = rng.uniform
    if shape == "open":
        flex = {f: (u(-0.1, 0.2), u(-0.05, 0.2), u(-0.05, 0.15)) for f in FINGERS}
        flex["thumb"] = (u(-0.1, 0.3), u(-0.1, 0.3), u(-0.1, 0.2))
        abd = {f: u(-0.1, 0.1) for f in FINGERS} | {"thumb": u(-0.2, 0.3)}
    elif shape == "fist":
        flex = {f: (u(1.2, 1.7), u(1.3, 1.9), u(0.8, 1.4)) for f in FINGERS}
        flex["thumb"] = (u(0.4, 1.1), u(0.5, 1.2), u(0.4, 1.2))
        abd = {f: u(-0.15, 0.15) for f in FINGERS} | {"thumb": u(0.2, 1.0)}
    elif shape == "pinch":
        flex = {"index": (u(0.5, 1.0), u(0.5, 1.1), u(0.3, 0.8)), "thumb": (u(0.3, 0.9), u(0.3, 0.9), u(0.2, 0.8))}
        flex |= {f: (u(0.1, 1.2), u(0.1, 1.2), u(0.1, 0.8)) for f in ("middle", "ring", "pinky")}
        abd = {
            "index": u(-0.1, 0.2),
            "middle": u(-0.1, 0.1),
            "ring": u(-0.1, 0.1),
            "pinky": u(-0.2, 0.0),
            "thumb": u(0.3, 1.0),
        }
    elif shape == "spread":
        flex = {f: (u(-0.1, 0.3), u(0.0, 0.3), u(0.0, 0.2)) for f in FINGERS}
        flex["thumb"] = (u(-0.2, 0.2), u(-0.1, 0.3), u(-0.1, 0.2))
        abd = {
            "index": u(0.2, 0.45),
            "middle": u(-0.1, 0.1),
            "ring": u(-0.45, -0.2),
            "pinky": u(-0.6, -0.3),
            "thumb": u(-0.4, 0.1),
        }
    elif shape == "crossed":  # middle over index, or index over middle
        flex = {f: (u(0.0, 0.6), u(0.0, 0.5), u(0.0, 0.4)) for f in FINGERS}
        flex["thumb"] = (u(0.0, 0.8), u(0.0, 0.8), u(0.0, 0.6))
        cross = u(0.25, 0.6)
        abd = {"index": -cross, "middle": cross, "ring": u(-0.2, 0.2), "pinky": u(-0.3, 0.0), "thumb": u(-0.2, 0.6)}
    else:
        raise ValueError(f"unknown hand shape {shape!r} (known: {', '.join(SHAPES)})")
    return _angles(flex, abd)


def _min_jerk(s: np.ndarray) -> np.ndarray:
    return s ** 3 * (10 - 15 * s + 6 * s ** 2)


def angle_trajectory(rng: np.random.Generator, seconds: float, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Finger angles (T, 15) x 2 for one trajectory, starting from an open hand."""
    n = int(round(seconds * rate_hz))
    keys = [shape_angles("open", rng)]
    times = [0.0]
    t = 0.0
    while t < seconds:
        t += rng.uniform(0.1, 0.5)  # hold
        keys.append(keys[-1])
        times.append(t)
        t += rng.uniform(0.4, 1.2)  # move
        keys.append(shape_angles(str(rng.choice(SHAPES)), rng))
        times.append(t)
    flex_k = np.array([k[0] for k in keys])
    abd_k = np.array([k[1] for k in keys])
    ts = np.arange(n) / rate_hz
    seg = np.clip(np.searchsorted(times, ts, side="right") - 1, 0, len(times) - 2)
    s = _min_jerk(np.clip((ts - np.array(times)[seg]) / (np.array(times)[seg + 1] - np.array(times)[seg]), 0.0, 1.0))[
        :, None
    ]
    flex = flex_k[seg] + s * (flex_k[seg + 1] - flex_k[seg])
    abd = abd_k[seg] + s * (abd_k[seg + 1] - abd_k[seg])
    # a slow wobble on every angle, as a real hand never holds still
    freq = rng.uniform(0.3, 1.5, size=(2, 15))
    phase = rng.uniform(0, 2 * np.pi, size=(2, 15))
    wobble = 0.04 * np.sin(2 * np.pi * freq[:, None, :] * ts[None, :, None] + phase[:, None, :])
    return flex + wobble[0], abd + 0.5 * wobble[1]


def retargeted_trajectories(
    hand: RobotModel, count: int, seconds: float = 10.0, rate_hz: float = 120.0, seed: int = 0
) -> list[np.ndarray]:
    """`count` LEAP joint trajectories (T, 16), clamped to the limits as the retargeting does."""
    rng = np.random.default_rng(seed)
    retarget = LeapRetargeter(hand)
    out = []
    for _ in range(count):
        flex, abd = angle_trajectory(rng, seconds, rate_hz)
        out.append(retarget(hand_pose_from_angles(flex, abd)))
    return out
