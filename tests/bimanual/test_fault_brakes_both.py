"""A fault on one side of a bimanual session brakes both: the faulted side gets nothing more at once (its
controller stopped it), the other brakes to rest within its limits and holds; neither moves again
without the operator."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from teleprev.evaluation.audit import audit_session
from teleprev.live.core.gate import GateState
from teleprev.live.record.bimanual_session import BimanualSession
from teleprev.live.record.run import run_script
from teleprev.live.record.session import RecordOptions
from teleprev.session.reader import SessionReader

ROOT = Path(__file__).resolve().parents[2]


def test_a_left_arm_fault_halts_left_and_brakes_right(tmp_path):
    text = (ROOT / "rigs" / "sim_bimanual.toml").read_text()
    arm = '[devices.arm_left]\nplugin = "sim.arm"'
    text = text.replace(arm, arm + "\nfault_after_s = 1.0", 1)
    assert "fault_after_s" in text
    rig = tmp_path / "rig.toml"
    rig.write_text(text)
    out = tmp_path / "s.mcap"
    rec = BimanualSession(RecordOptions(out=out, rig=rig))
    rec.start()
    try:
        run_script(rec, duration=4.5, episodes=1, engage_after=0.8)
        assert rec.loop.stats.engages == 1 and rec.loop.gate.state is GateState.FAULTED  # no unattended re-engage
        brake_s = max(p.motion.stop_time_bound() for p in rec.pipelines.values())
    finally:
        rec.stop()
    with SessionReader(out) as r:
        modes = [(m.log_time_ns, m.payload.data) for m in r.messages(["/events/mode"])]
        left = [x.payload for x in r.messages(["/command/left/arm"])]
        right = [x.payload for x in r.messages(["/command/right/arm"])]
    faults = [(t, d) for t, d in modes if d.get("side")]
    assert len(faults) == 1
    t_fault, data = faults[0]
    assert data == {"mode": "preview", "reason": "device arm_left failed", "side": "left", "halt": True}
    tick_s = 1 / 120
    # the left arm: nothing sampled after the halt reached the sender (a tick in flight may carry an older one)
    assert left and not [m for m in left if m.stamp_ns > t_fault + 3 * tick_s * 1e9]
    # the right arm braked to rest after the fault, and then nothing more was sent
    after = [m for m in right if m.stamp_ns > t_fault]
    assert after, "the right arm got no braking commands"
    assert np.abs(after[-1].velocities).max() < 1e-6
    assert after[-1].stamp_ns - t_fault < (brake_s + 0.3) * 1e9
    assert audit_session(out).ok
