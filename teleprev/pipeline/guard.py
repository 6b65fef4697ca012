"""The last check before a command leaves teleprev.

Every command is a step from the previous command towards a target: at most `speed * dt` per joint,
inside the joint limits, and, for a hand, free of self-collision by the exact checker. Two collision-free
hand configurations can have a collision between them, so a capped step that collides is shortened by
bisection towards the previous command (collision-free by induction) until the exact check passes.
"""

from __future__ import annotations

import numpy as np

from teleprev.robot.collision import SelfCollisionChecker


class JointGuard:
    def __init__(
        self,
        lower: np.ndarray,
        upper: np.ndarray,
        speed: np.ndarray,
        max_dt: float,
        checker: SelfCollisionChecker | None = None,
        bisection_steps: int = 12,
    ):
        self.lower = np.asarray(lower, dtype=float)
        self.upper = np.asarray(upper, dtype=float)
        self.speed = np.asarray(speed, dtype=float)
        self.max_dt = max_dt  # a pause in commands must not become one long step
        self.checker = checker
        self.bisection_steps = bisection_steps

    def step(
        self, last: np.ndarray, target: np.ndarray, dt: float, speed_frac: float = 1.0, target_valid: bool = False
    ) -> np.ndarray:
        """The next command from `last` (itself a valid command) towards `target`.

        `target_valid` says the target itself passed the exact check (the Corrector's output did), so a
        step that reaches it exactly needs no second check.
        """
        cap = self.speed * speed_frac * min(max(dt, 0.0), self.max_dt)
        delta = target - last
        reach = np.abs(delta) <= cap
        stepped = np.where(reach, target, last + np.minimum(np.maximum(delta, -cap), cap))
        cmd = np.minimum(np.maximum(stepped, self.lower), self.upper)
        if self.checker is None or (target_valid and reach.all() and np.array_equal(cmd, target)):
            return cmd
        if not self.checker.collides(cmd):
            return cmd
        lo, hi = 0.0, 1.0  # fraction of the step known free / known colliding
        delta = cmd - last
        for _ in range(self.bisection_steps):
            mid = 0.5 * (lo + hi)
            if self.checker.collides(last + mid * delta):
                hi = mid
            else:
                lo = mid
        return last + lo * delta

    def valid(self, q: np.ndarray) -> bool:
        """Inside the limits, finite and (for a hand) collision-free: the invariant of every command."""
        if not np.all(np.isfinite(q)) or np.any(q < self.lower - 1e-12) or np.any(q > self.upper + 1e-12):
            return False
        return self.checker is None or not self.checker.collides(q)
