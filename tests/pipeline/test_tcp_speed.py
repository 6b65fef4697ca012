"""The flange's linear speed cap (teleprev/pipeline/tcp_speed.py): a target stream that would drive the
flange faster than the cap gives commands whose flange speed (FK over consecutive commands) keeps it, and
every joint limit too; the older formats' planner (uncapped_tcp) does not, which is why it is a format."""

import numpy as np
import pytest

from teleprev.assembly import build_pipeline
from teleprev.pipeline.older_formats import UncappedTcpPlanner
from teleprev.pipeline.planner import CommandPlanner
from teleprev.rig import load_rig
from tests.pipeline.test_planner import PERIOD, Script, _run, _within

REACHING = np.array([0.0, 0.3, -1.2, 0.0, 1.0, 0.0])  # stretched out: a long lever from joint 1 to the flange


@pytest.fixture(scope="module")
def pipeline():
    return build_pipeline(load_rig())  # the default sim rig: xArm6 + LEAP Hand (cap 1.0 m/s, the table's)


def _sweep(p, planner_class):
    """A big, fast sweep of the wrist (joints 1, 4 and 5 at 1.5 Hz, 1 rad), once the engage is over: the
    targets' velocities take the joints to their speed caps."""
    s = Script(p, arm_start=REACHING)
    t0 = 1_000_000_000
    events = [(t0, s.target(t0, REACHING)), (t0 + 1, s.mode("execute", t0 + 1, arm=REACHING))]
    w, mask = 2 * np.pi * 1.5, np.array([1.0, 0.0, 0.0, 1.0, 1.0, 0.0])
    for k in range(1, 600):
        t = t0 + k * PERIOD
        x = max(k - 100, 0) * PERIOD / 1e9
        events.append((t, s.target(t, REACHING + mask * np.sin(w * x), mask * w * np.cos(w * x))))
    return _run(planner_class.for_pipeline(p), events, t0 + 1 + PERIOD * np.arange(600))


def test_the_planner_keeps_the_flange_within_its_cap_and_the_joints_within_theirs(pipeline):
    tcp = pipeline.motion.tcp
    assert tcp is not None and tcp.cap == 1.0
    uncapped = _sweep(pipeline, UncappedTcpPlanner)
    t = np.array([x.t_ns for x in uncapped])
    assert tcp.speeds(t, np.array([x.arm for x in uncapped])).max() > 1.1 * tcp.cap  # the stream asks for more (1.16)
    sent = _sweep(pipeline, CommandPlanner)
    t, q = np.array([x.t_ns for x in sent]), np.array([x.arm for x in sent])
    speeds = tcp.speeds(t, q)
    assert speeds.max() <= tcp.cap, speeds.max()
    # still moving fast: capped, not stopped (0.77 m/s here; with the joints' caps in the box, not their own
    # speeds, 0.46 m/s)
    assert speeds.max() > 0.7 * tcp.cap
    assert any("arm_tcp_capped" in x.flags for x in sent)
    _within(pipeline, sent)  # joint position, speed, acceleration and jerk limits, exactly


def test_the_speed_bound_is_the_fastest_the_flange_moves_with_the_joints_within_their_caps(pipeline):
    """speed_bound, against the flange's speed by finite differences of FK: no joint speeds within the caps
    pass it, and some corner of them reaches it."""
    tcp, arm = pipeline.motion.tcp, pipeline.motion.arm
    rng = np.random.default_rng(3)
    n, dt = len(arm.velocity), 1e-7
    corners = np.array([[1.0 if (c >> i) & 1 else -1.0 for i in range(n)] for c in range(2 ** n)])
    for _ in range(20):
        q = rng.uniform(arm.lower + 0.01, arm.upper - 0.01)
        v = np.vstack([corners, rng.uniform(-1, 1, size=(20, n))]) * arm.velocity
        speed = np.linalg.norm(tcp.flange(q + v * dt) - tcp.flange(q), axis=1) / dt
        bound = tcp.speed_bound(q)
        assert speed.max() <= bound * (1 + 1e-4) and speed.max() >= bound * (1 - 1e-4)


def test_a_rig_tightens_the_cap_and_a_robot_the_table_lacks_has_none(monkeypatch):
    from teleprev.robot import limits
    from tests.pipeline.test_motion import _rig

    assert build_pipeline(_rig(arm_tcp_speed=0.5)).motion.tcp.cap == 0.5
    monkeypatch.setattr(limits, "ARMS", {})
    assert build_pipeline(_rig(arm_acceleration=5.0, arm_jerk=200.0)).motion.tcp is None


def test_an_engage_under_the_cap_still_reaches_its_engage_speed(pipeline):
    """The engage fraction scales the joints' speed caps, not their speeds plus the headroom (which held a
    joint at 0.5 rad/s while engaging at half speed): joint 1 turning 2 rad near home engages at well over
    that, with the flange still within its cap."""
    from tests.pipeline.test_planner import HOME

    s = Script(pipeline, arm_start=HOME)
    t0, goal = 1_000_000_000, HOME + np.array([2.0, 0, 0, 0, 0, 0])
    events = [(t0, s.target(t0, goal)), (t0 + 1, s.mode("execute", t0 + 1, arm=HOME))]
    events += [(t0 + k * PERIOD, s.target(t0 + k * PERIOD, goal)) for k in range(1, 300)]
    sent = _run(CommandPlanner.for_pipeline(pipeline), events, t0 + 1 + PERIOD * np.arange(300))
    t, q = np.array([x.t_ns for x in sent]), np.array([x.arm for x in sent])
    assert all("engaging" in x.flags for x in sent[1:60]) and any("arm_tcp_capped" in x.flags for x in sent)
    assert (np.abs(np.diff(q[:, 0])) / (np.diff(t) / 1e9)).max() > 0.8  # 1.07 rad/s
    assert pipeline.motion.tcp.speeds(t, q).max() <= pipeline.motion.tcp.cap
    _within(pipeline, sent)


@pytest.mark.parametrize("session_format", [4, 5, 6, 7, 9])
def test_older_formats_rerun_without_the_cap(session_format):
    """Sessions of formats 4 to 9 were planned without it: eval re-runs them with a planner that leaves the
    flange uncapped, keeping each format's other classes (format 9: the current swept check and limiter)."""
    from teleprev.pipeline.older_formats import arithmetic
    from teleprev.pipeline.swept import SweptCheck

    older = build_pipeline(load_rig(), session_format=session_format)
    planner = CommandPlanner.for_pipeline(older)
    assert isinstance(planner, UncappedTcpPlanner) and not planner.caps_tcp_speed
    assert (arithmetic(session_format).swept_check is SweptCheck) == (session_format == 9)
    assert type(CommandPlanner.for_pipeline(build_pipeline(load_rig()))) is CommandPlanner
