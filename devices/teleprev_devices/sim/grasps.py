"""Hand shapes of the simulated operator, as SMPL-X finger angles (flexion, abduction; radians).

Each shape takes a tightness c in [0, 1]: how hard the person squeezes. The numbers are human ranges
(MCP/PIP flexion up to ~1.6 rad, abduction ±0.3 rad, a thumb that swings across the palm); retargeted
one to one onto the LEAP Hand, a tight power grasp or fist pushes fingertips into the palm and the thumb
into the fingers, a firm pinch presses the thumb tip into the index tip, and a flat hand with the fingers
squeezed together crosses the index over the middle finger: the self-collisions the corrector exists for.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from teleprev.devices import smplx

HandAngles = np.ndarray  # (30,): flexion of the 15 SMPL-X hand joints, then their abduction


def _hand(fingers: dict[str, tuple[float, float, float]], spread: dict[str, float],
          thumb: tuple[float, float, float], thumb_abduction: float) -> HandAngles:
    out = np.zeros(30)
    for finger, flex in (*fingers.items(), ("thumb", thumb)):
        for i, v in enumerate(flex, start=1):
            out[smplx.JOINT_INDEX[f"{finger}{i}"]] = v
    for finger, a in (*spread.items(), ("thumb", thumb_abduction)):
        out[15 + smplx.JOINT_INDEX[f"{finger}1"]] = a
    return out


def rest(c: float = 0.0) -> HandAngles:
    """Relaxed hand hanging at the side of the task: slightly curled, more so towards the little finger."""
    k = 1.0 + 0.5 * c
    return _hand(
        {"index": (0.20 * k, 0.25 * k, 0.15 * k), "middle": (0.25 * k, 0.30 * k, 0.20 * k),
         "ring": (0.30 * k, 0.35 * k, 0.20 * k), "pinky": (0.35 * k, 0.40 * k, 0.25 * k)},
        {"index": 0.08, "middle": 0.0, "ring": -0.06, "pinky": -0.14},
        (0.25, 0.20, 0.10), 0.25,
    )


def open_hand(c: float = 0.0) -> HandAngles:
    """Pre-shape before a grasp: fingers nearly straight and spread (wider with c), thumb swung out."""
    return _hand(
        {f: (0.08, 0.10, 0.05) for f in ("index", "middle", "ring", "pinky")},
        {"index": 0.12 + 0.1 * c, "middle": 0.0, "ring": -0.08 - 0.06 * c, "pinky": -0.18 - 0.1 * c},
        (0.15, 0.10, 0.05), 0.45 + 0.15 * c,
    )


def power(c: float) -> HandAngles:
    """Cylindrical power grasp around a cup; the thumb wraps across the fingers as c grows."""
    f1, f2, f3 = 0.75 + 0.55 * c, 0.85 + 0.55 * c, 0.55 + 0.45 * c
    return _hand(
        {
            "index": (f1, f2, f3),
            "middle": (f1, f2, f3),
            "ring": (f1 + 0.05, f2, f3),
            "pinky": (f1 + 0.1, f2 + 0.05, f3),
        },
        {"index": 0.02, "middle": 0.0, "ring": -0.03, "pinky": -0.06},
        (0.50 + 0.40 * c, 0.45 + 0.30 * c, 0.30 + 0.40 * c),
        -0.30 - 0.60 * c,
    )


def pour_grip(c: float) -> HandAngles:
    """A power grasp for pouring: the middle and ring fingers curl round the cup, deeper than a power
    grasp's (squeezed past c ~0.8 the fingertips would be in the palm), the index finger (at the rim)
    only lightly bent along it and the thumb against its side, so that neither curls over the mouth
    the contents pour from."""
    out = power(c)
    curled = (0.75 + 0.85 * c, 0.85 + 0.90 * c, 0.55 + 0.70 * c)
    shape = {"index": (0.30 + 0.15 * c, 0.25 + 0.15 * c, 0.15), "middle": curled, "ring": curled,
             "thumb": (0.45, 0.20, 0.10)}
    for finger, flex in shape.items():
        for i, v in enumerate(flex, start=1):
            out[smplx.JOINT_INDEX[f"{finger}{i}"]] = v
    out[15 + smplx.JOINT_INDEX["thumb1"]] = -0.2
    return out


def fist(c: float) -> HandAngles:
    """Closed fist, thumb folded across the fingers (operators clench between takes)."""
    return _hand(
        {f: (1.35 + 0.2 * c, 1.60 + 0.15 * c, 1.10 + 0.2 * c) for f in ("index", "middle", "ring", "pinky")},
        {"index": 0.0, "middle": 0.0, "ring": 0.0, "pinky": -0.03},
        (0.90, 0.70, 0.60), -0.80 - 0.20 * c,
    )


def pinch(c: float) -> HandAngles:
    """Tip pinch of thumb and index (a spoon handle); the other fingers tucked in."""
    return _hand(
        {"index": (0.75 + 0.15 * c, 0.70 + 0.20 * c, 0.35 + 0.20 * c),
         "middle": (1.00 + 0.30 * c, 1.20 + 0.30 * c, 0.80), "ring": (1.10 + 0.30 * c, 1.25 + 0.30 * c, 0.80),
         "pinky": (1.20 + 0.30 * c, 1.30 + 0.30 * c, 0.80)},
        {"index": 0.0, "middle": 0.0, "ring": 0.0, "pinky": -0.05},
        (0.55 + 0.15 * c, 0.45 + 0.25 * c, 0.35 + 0.40 * c), -0.55 - 0.35 * c,
    )


def flat(c: float) -> HandAngles:
    """Flat hand pushing on a box face, fingers squeezed together (the index crosses the middle as c grows)."""
    return _hand(
        {f: (0.15, 0.10, 0.05) for f in ("index", "middle", "ring", "pinky")},
        {"index": -0.05 - 0.30 * c, "middle": -0.05, "ring": 0.05 + 0.10 * c, "pinky": 0.05},
        (0.30, 0.20, 0.10), -0.10,
    )


def claw(c: float) -> HandAngles:
    """Fingers spread and hooked over the top of a box, thumb opposed."""
    return _hand(
        {f: (0.60 + 0.30 * c, 0.70 + 0.30 * c, 0.50) for f in ("index", "middle", "ring", "pinky")},
        {"index": 0.15, "middle": 0.0, "ring": -0.10, "pinky": -0.20},
        (0.60, 0.40, 0.30), -0.40,
    )


SHAPES: dict[str, Callable[[float], HandAngles]] = {
    "rest": rest, "open": open_hand, "power": power, "pour": pour_grip, "fist": fist, "pinch": pinch, "flat": flat,
    "claw": claw,
}
