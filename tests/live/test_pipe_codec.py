"""The paced processes' pipe codec: typed JSON that gives back every bit of what went in (a session re-runs
bit for bit), never unpickles, and refuses a message of a type it was not told of."""

from __future__ import annotations

import numpy as np
import pytest

from teleprev.devices.runner import RunnerStats
from teleprev.live.core.actuator_host import Forwarded
from teleprev.live.core.pipe_codec import frame, types_by_name, unframe
from teleprev.live.core.sender import SentTick
from teleprev.messages import Event, JointSample, Sample
from teleprev.pipeline.planner import ModeUpdate, TargetUpdate, Tick
from teleprev.thread_priority import PacedStatus


def test_updates_and_ticks_come_back_bit_for_bit():
    rng = np.random.default_rng(5)
    arm = rng.normal(size=6)
    arm[2] = -0.0
    hand = np.append(rng.normal(size=15) * 1e-300, np.nan)
    messages = [
        TargetUpdate(7, 1_795_000_000_123_456_789, arm, arm * 3.1, 1_795_000_000_000_000_001, hand, None),
        ModeUpdate(8, 1_795_000_000_200_000_000, "execute", arm, hand),
        "stop",
        SentTick(Tick(1_795_000_000_300_000_000, 8, arm, None, hand, hand, ("engaging", "hand_stopping"), True), -12),
        PacedStatus(True, "SCHED_FIFO priority 50"),
    ]
    types = types_by_name(TargetUpdate, ModeUpdate, SentTick, Tick, PacedStatus)
    data = b"".join(frame(m) for m in messages)
    got, rest = unframe(data + frame("next")[:5], types)  # a message cut short waits for its rest
    assert rest == frame("next")[:5] and len(got) == len(messages)
    assert got[0].arm.tobytes() == arm.tobytes() and got[0].hand.tobytes() == hand.tobytes()
    assert got[0].arm_v.tobytes() == (arm * 3.1).tobytes() and got[0].hand_v is None
    assert got[0].t_ns == messages[0].t_ns and got[0].arm_ns == messages[0].arm_ns
    assert got[1].mode == "execute" and got[1].hand.tobytes() == hand.tobytes()
    assert got[2] == "stop"
    tick = got[3].tick
    assert isinstance(tick, Tick) and tick.flags == ("engaging", "hand_stopping") and got[3].late_ns == -12
    assert tick.arm.tobytes() == arm.tobytes() and tick.arm_v is None and tick.active is True
    assert got[4] == messages[4]


def test_a_message_of_an_unknown_type_is_refused():
    with pytest.raises(ValueError, match="unknown type 'PacedStatus'"):
        unframe(frame(PacedStatus(False, "no")), types_by_name(TargetUpdate, ModeUpdate))


def test_an_actuator_process_reports_come_back_whole():
    """Samples and device events (dicts) and the runner's stats, as an actuator's own process sends them."""
    state = Sample("/arm/arm/state", JointSample(17, ("joint1", "joint2"), np.array([0.1, -0.0])))
    event = Sample(
        "/events/device", Event(18, "teleprev.DeviceEvent", {"device": "arm", "event": "gap", "since_ns": 3})
    )
    stats = RunnerStats(name="arm", kind="arm", state="ok", received=4, errors=0, rate_hz=99.5, nominal_hz=100.0,
                        latency_ms=0.2, latency_max_ms=1.5, last_receive_ns=19, last_error="", connects=1, gaps=0,
                        sink_errors=0, skipped={"refused_commands": 2}, topics={"/arm/arm/state": 4})
    types = types_by_name(Forwarded, Sample, JointSample, Event, RunnerStats)
    got, _ = unframe(b"".join(frame(m) for m in (Forwarded(state, 20), Forwarded(event, 21), stats)), types)
    assert got[0].receive_ns == 20 and got[0].sample.payload.names == ("joint1", "joint2")
    assert got[0].sample.payload.positions.tobytes() == state.payload.positions.tobytes()
    assert got[1].sample == event and got[2] == stats
