"""The limits the commands keep, and how they stop: the arm's jerk-limited generator, the hand's
acceleration cap and the swept check along each hand command's segment.

The command planner (teleprev/pipeline/planner.py) samples the commands with them at each tick of the
paced sender; replay's smoothing (teleprev/live/player.py) steps recorded targets with them.

    arm     jerk-limited generator towards the target (ArmGenerator), at a speed fraction that keeps the
            flange's speed within its cap (TcpSpeedCap)
    hand    acceleration cap towards the target (HandLimiter), each command segment, and the way on to
            where braking from it would stop, checked for self-collision with a clearance margin; where
            that is not free, the fingers whose motion would collide are held back and slide as far
            towards their step as is free, the others move on (SweptCheck.slide); only where no such
            command is found does the whole hand brake (joint by joint, else keeping its direction), into
            the clearance margin where no link collides on the way, and stop short only where even
            braking would collide
"""

from __future__ import annotations

import numpy as np

from teleprev.kernels.motion import ESTIMATE_GIVEN, ESTIMATE_NONE
from teleprev.pipeline.trajectory import ArmGenerator, HandLimiter

ENGAGED_TOL = 0.02  # rad (m for a gripper): the engage ramp is over once the commands come this close to the
# targets (a human wrist often moves the target faster than the ramp's half speed, so a tight tolerance never ends it)
FEEDFORWARD_MAX_GAP_NS = 100_000_000  # targets further apart than this give no velocity estimate
EXTRAPOLATE_MAX_NS = 50_000_000
RESUME_STEP_S = 0.01  # the first step after a pause in the commands (the sim arm's state period)
FEEDFORWARD_TAU_NS = 30e6  # smoothing of the target velocity estimate (IK jitters by its tolerance)
# A stream's first moving steps, at this fraction of the arm's jerk (format 11). A servo-mode controller paces
# a stream by its arrivals (teleprev/emulators/xarm_servo.py): for its first targets it has one to three gaps
# to go by, each off by the host's 0.5-1.5 ms of jitter (the first SDK call of a run was ~1 ms slower), so the
# start of a stream planned at the jerk limit read up to 1.25x it there; four ticks (33 ms at 120 Hz) in, the
# pace rests on four gaps and is within 0.1 ms.
STREAM_START_TICKS = 4
STREAM_START_JERK_FRAC = 0.5


class Motion:
    """The arm generator and (for a LEAP Hand or a gripper) the hand limiter and swept check."""

    def __init__(self, arm: ArmGenerator, hand: HandLimiter | None, swept=None, tcp=None, start_jerk_frac=1.0,
                 plan_fraction=1.0):
        self.arm = arm
        self.hand = hand
        self.swept = swept  # teleprev.pipeline.swept.SweptCheck or None
        self.tcp = tcp  # teleprev.pipeline.tcp_speed.TcpSpeedCap or None (no cap on the flange's speed)
        # the arm's jerk over a stream's first STREAM_START_TICKS moving ticks (formats up to 10: 1.0)
        self.start_jerk_frac = start_jerk_frac
        # the arm is planned at this fraction of its acceleration and jerk limits (arm.acceleration, arm.jerk)
        self.plan_fraction = plan_fraction

    def stop_time_bound(self) -> float:
        """Seconds a switch to preview takes at most to bring the commands to rest (the slower side's
        bound; a switch such as the vacuum's stops at once)."""
        return max(self.arm.stop_time_bound(), self.hand.stop_time_bound() if self.hand is not None else 0.0)

    def hand_step(self, last, v, target, target_v, dt, dt_before, frac, flags):
        """(command, velocity) one step of dt from hand command `last` moving at v: towards `target`
        (None: brake) moving at `target_v` (None: met at rest), within the acceleration cap, and only along
        a segment that keeps the clearance (replay's smoothing)."""
        estimate = ESTIMATE_NONE if target_v is None else ESTIMATE_GIVEN
        return self.hand_move(last, v, target, estimate, None, target_v, 0.0, dt, dt_before, frac, flags)[:2]

    def hand_move(self, last, v, target, estimate, before, before_v, keep, dt, dt_before, frac, flags):
        """(command, velocity, the target's velocity estimate): the capped track or stop with the target's
        velocity estimated as `estimate` says (HandLimiter.command, one kernel call), then only along a
        segment that keeps the clearance; a command equal to `last` has velocity zero."""
        rows, unchanged = self.hand.command(last, v, target, estimate, before, before_v, keep, dt, dt_before, frac)
        cmd, cmd_v, avoided = self._keep_clear(last, v, rows[0], rows[1], target, dt, dt_before, frac, flags)
        if avoided:
            unchanged = not np.any(cmd != last)
        return cmd, np.zeros_like(cmd_v) if unchanged else cmd_v, rows[2]

    def _keep_clear(self, last, v, cmd, cmd_v, target, dt, dt_before, frac, flags):
        """(cmd, cmd_v, False) where the segment from `last` to cmd and on to its stop point keeps the
        clearance, else _avoid's command and velocity and True."""
        if self.swept is None:
            return cmd, cmd_v, False
        h = self.hand  # compiled: both segments in one kernel call (None: it leaves them to these calls)
        free = self.swept.command_free(last, cmd, cmd_v, h.acceleration, h.lower, h.upper)
        if free is None:
            free = self.swept.segment_free(last, cmd) and self.swept.segment_free(cmd, self._stop_point(cmd, cmd_v))
        if free:
            return cmd, cmd_v, False
        return *self._avoid(last, v, cmd, target, dt, dt_before, frac, flags), True

    def _stop_point(self, q, v):
        """Where braking at the cap from q at v would end: a command is taken only if that way is free too,
        so that the hand can always brake in time instead of stopping short."""
        h = self.hand
        return np.minimum(np.maximum(q + v * np.abs(v) / (2.0 * h.acceleration), h.lower), h.upper)

    def _avoid(self, last, v, cmd, target, dt, dt_before, frac, flags):
        """The capped step `cmd` would come too close to a collision: hold back the fingers that must,
        sliding them as far as is free (SweptCheck.slide); where that finds nothing (and in older
        formats), brake the whole hand as hard as allowed, and only if even that segment is not free,
        stop short on the segment (safety before smoothness).

        The way on from the last command that its check showed free is the straight segment to where each
        joint's braking would end; the braking steps do not follow it where the joints move at different
        speeds (each slows by the same amount per step), so after a command at the margin's edge (a slide)
        the braked segment can graze the margin, or collide. Stopping short there broke the acceleration cap
        (250 rad/s^2 where the cap is 200, `teleprev audit`), so the hand then brakes keeping its direction
        (HandLimiter.stop_straight), and, where neither braking is free, into the margin wherever no link
        collides on the way (SweptCheck.brakes_in_margin; formats up to 8 stopped short)."""
        braked, bv = self.hand.stop(last, v, dt, dt_before)
        h = self.hand
        slid = None
        if self.swept.slides:
            # each joint's capped step towards either limit: a blocked finger's ways out (SweptCheck.slide)
            away = np.stack([h.command(last, v, edge, ESTIMATE_NONE, None, None, 0.0, dt, dt_before, frac)[0][0]
                             for edge in (h.lower, h.upper)])
            slid = self.swept.slide(last, cmd, braked, away, cmd if target is None else target, dt, h.acceleration,
                                    h.lower, h.upper)
        if slid is not None:
            flags.append("hand_swept_slid")
            return slid[0], slid[1]
        if self.swept.segment_free(last, braked):
            flags.append("hand_swept_braked")
            return braked, bv
        if self.swept.brakes_in_margin:
            straight, sv = self.hand.stop_straight(last, v, dt, dt_before)
            if self.swept.segment_free(last, straight):
                flags.append("hand_swept_braked_straight")
                return straight, sv
            for q, qv in ((braked, bv), (straight, sv)):
                if self.swept.segment_collision_free(last, q):
                    flags.append("hand_swept_braked_in_margin")
                    return q, qv
        flags.append("hand_swept_stopped")
        q = self.swept.last_free_on_segment(last, braked)
        return q, (q - last) / dt if dt > 0 else np.zeros_like(v)
