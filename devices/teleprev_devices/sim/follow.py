"""Kinematic joint following for the sim arm and hand: towards the latest target, within limits."""

from __future__ import annotations

import numpy as np


class JointFollower:
    """Joint positions moved towards a target one fixed time step at a time.

    Each step's velocity is the fastest that still stops at the target (sqrt(2 a |error|), and no
    further than the error in one step), capped at `max_velocity` and changed by at most
    `max_acceleration * dt` from the last step (inf: rate-limited only). Positions stay within limits.
    """

    def __init__(self, q0: np.ndarray, lower: np.ndarray, upper: np.ndarray, max_velocity: np.ndarray,
                 max_acceleration: np.ndarray | float = np.inf):
        self.lower = np.asarray(lower, dtype=float)
        self.upper = np.asarray(upper, dtype=float)
        self.q = np.clip(np.asarray(q0, dtype=float), self.lower, self.upper)
        self.v = np.zeros_like(self.q)
        self.target = self.q.copy()
        self.max_velocity = np.broadcast_to(np.asarray(max_velocity, dtype=float), self.q.shape).copy()
        self.max_acceleration = np.broadcast_to(np.asarray(max_acceleration, dtype=float), self.q.shape).copy()
        self._unlimited = np.isinf(self.max_acceleration)
        self._acceleration = np.where(self._unlimited, 0.0, self.max_acceleration)

    def set_target(self, target: np.ndarray) -> None:
        self.target = np.clip(np.asarray(target, dtype=float), self.lower, self.upper)

    def step(self, dt: float) -> None:
        e = self.target - self.q
        dist = np.abs(e)
        braking = np.where(self._unlimited, np.inf, np.sqrt(2.0 * self._acceleration * dist))
        speed = np.minimum(np.minimum(self.max_velocity, braking), dist / dt)
        v = np.sign(e) * speed
        dv = self.max_acceleration * dt
        v = np.clip(v, self.v - dv, self.v + dv)
        v = np.clip(v, -self.max_velocity, self.max_velocity)
        q = np.clip(self.q + v * dt, self.lower, self.upper)
        self.v = (q - self.q) / dt
        self.q = q
