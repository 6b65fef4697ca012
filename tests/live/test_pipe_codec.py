"""The command sender's pipe codec: typed JSON that gives back every bit of what went in (a session re-runs
bit for bit), never unpickles, and refuses a message of a type it was not told of."""

from __future__ import annotations

import numpy as np
import pytest

from teleprev.live.core.pipe_codec import frame, types_by_name, unframe
from teleprev.live.core.sender import SenderStatus, SentTick
from teleprev.pipeline.planner import ModeUpdate, TargetUpdate, Tick


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
        SenderStatus(True, "SCHED_FIFO priority 50"),
    ]
    types = types_by_name(TargetUpdate, ModeUpdate, SentTick, Tick, SenderStatus)
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
    with pytest.raises(ValueError, match="unknown type 'SenderStatus'"):
        unframe(frame(SenderStatus(False, "no")), types_by_name(TargetUpdate, ModeUpdate))
