"""The arm's flange (TCP) linear speed: the cap the command planner keeps, and the speed `teleprev audit`
measures on the commands.

A servo-mode xArm faults (error C60) when its TCP moves faster than 1000 mm/s (UFactory's servo mode guide;
the SDK's xarm/x3/base.py, _max_tcp_speed), however well its joints keep their own limits: a fast wrist
sweep with the arm stretched out reaches it (1.18 m/s seen). The flange is the origin of the arm chain's
last moving link (the xArm's link6, where its link_eef and the controller's TCP with no offset sit).

The planner keeps the cap by lowering the velocity limits ruckig plans with (the acceleration and jerk
limits unchanged), never by clamping a sample: a clamped sample would break the jerk limit. Each joint's
limit at a tick is f x c_i, where c_i = min(v_max_i, |v_i| + HEADROOM_S x a_max_i) (v_max_i times the
engage fraction while the commands engage): the joint's speed now and what it can gain meanwhile (0.5
rad/s at 10 rad/s^2; the limit is set again at every tick, so a joint speeding up is not held back: within
a tick and the jerk's turn of its acceleration it gains 0.18 rad/s). f makes the fastest the flange can
move with every joint within f x c_i at most TCP_MARGIN x the cap. That fastest is exact: v_flange =
sum_i J_i qdot_i (J_i = a_i x (p - o_i) for a revolute joint, a_i for a prismatic one) is linear in qdot,
its norm convex: over the box |qdot_i| <= c_i it is largest at a corner, one of 2^(n-1) sign patterns and
their negatives (32 for six joints: one small matrix product). Where f drops while a joint moves faster
than it allows, ruckig brakes it to it within the acceleration and jerk limits; the margin covers the
flange's speed meanwhile (the bound changes little over that braking, a few ticks). Taking the joints' own
speeds, not their caps, matters: a wrist sweep asking 1.29 m/s of the flange got 0.46 m/s with the caps
alone (the box allowing every joint at its cap), 0.77 m/s so.
"""

from __future__ import annotations

import numpy as np

from teleprev.robot.compiled_kinematics import CompiledKinematics
from teleprev.robot.model import RobotModel

TCP_MARGIN = 0.85  # of the cap: the bound the speed fraction keeps (see the module docstring)
HEADROOM_S = 0.05  # seconds of full acceleration a joint's velocity limit leaves above its speed


class TcpSpeedCap:
    """The flange's speed cap (m/s) for the arm chain `chain` (joints in its order, speed caps `velocity`,
    acceleration limits `acceleration`)."""

    def __init__(self, chain: RobotModel, velocity: np.ndarray, acceleration: np.ndarray, cap_mps: float):
        self.cap = float(cap_mps)
        self.velocity = np.asarray(velocity, dtype=float)
        self.headroom = np.asarray(acceleration, dtype=float) * HEADROOM_S
        self.kinematics = CompiledKinematics(chain)
        self._flange = chain.link_index[chain.joints[-1].child]
        self._links = np.array([chain.link_index[j.child] for j in chain.joints])
        self._axes = np.array([j.axis for j in chain.joints], dtype=float)
        self._revolute = np.array([j.type != "prismatic" for j in chain.joints])
        n = len(chain.joints)  # every sign pattern of the joint speeds (a pattern and its negative: one)
        self._signs = 1.0 - 2.0 * ((np.arange(2 ** max(n - 1, 0))[None, :] >> np.arange(n)[:, None]) & 1)

    def flange(self, q: np.ndarray) -> np.ndarray:
        """The flange's position (m) at arm joints q (n,), or of each row of a batch (N, n)."""
        world = self.kinematics.world(q)
        return world[..., self._flange, :3, 3]

    def speed_bound(self, q: np.ndarray, speeds: np.ndarray | None = None) -> float:
        """The fastest the flange can move at q with every joint within `speeds` (default: its speed cap), m/s."""
        speeds = self.velocity if speeds is None else speeds
        world = self.kinematics.world(q)
        p = world[self._flange, :3, 3]
        frames = world[self._links]
        axes = np.einsum("kij,kj->ki", frames[:, :3, :3], self._axes)
        columns = np.where(self._revolute[:, None], np.cross(axes, p - frames[:, :3, 3]), axes)  # (n, 3)
        corners = (columns * speeds[:, None]).T @ self._signs  # (3, 2^(n-1))
        return float(np.sqrt((corners * corners).sum(axis=0).max()))

    def joint_speeds(self, q: np.ndarray, v: np.ndarray, frac: float = 1.0) -> np.ndarray | None:
        """The joints' velocity limits for the next profile from q moving at v, under `frac` of their speed caps
        (the engage fraction; see the module docstring), or None where frac x the caps keeps the flange within
        TCP_MARGIN x the cap."""
        caps = self.velocity * frac
        if self.speed_bound(q, caps) <= TCP_MARGIN * self.cap:
            return None
        # frac applies to the caps only: applied to |v| + headroom too, it would hold a joint at
        # frac x headroom / (1 - frac) (0.5 rad/s while engaging at half speed)
        c = np.minimum(caps, np.abs(v) + self.headroom)
        bound = self.speed_bound(q, c)
        return c * min(1.0, TCP_MARGIN * self.cap / bound) if bound > 0.0 else c

    def speeds(self, t_ns: np.ndarray, q: np.ndarray) -> np.ndarray:
        """The flange's speed (m/s) between consecutive commands (stamps t_ns, positions q (N, n))."""
        if len(t_ns) < 2:
            return np.zeros(0)
        p = self.flange(q)
        return np.linalg.norm(np.diff(p, axis=0), axis=1) / (np.diff(t_ns) / 1e9)
