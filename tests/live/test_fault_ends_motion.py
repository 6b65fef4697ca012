"""After a controller fault nothing moves until the operator says so: an unattended session engages once
per episode and never again after the fault (the refusal is recorded), nothing more is sent to the
stopped arm, and an operator's engage starts from the measured state at rest, within the limits."""

import time

import numpy as np

from teleprev import topics
from teleprev.evaluation.audit import audit_session
from teleprev.live.core.gate import GateState
from teleprev.live.record.run import run_script
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.pipeline.planner import ModeUpdate
from teleprev.rig import default_rig_path
from teleprev.session.reader import SessionReader
from tests.helpers.sessions import engage_until_accepted


def record_mode_updates(rec: LiveSession) -> list[ModeUpdate]:
    """The mode updates the session loop passes to the command sender, in order."""
    sent, send = [], rec.sender.send

    def keep(update):
        if isinstance(update, ModeUpdate):
            sent.append(update)
        return send(update)

    rec.sender.send = keep
    return sent


def _faulting_rig(tmp_path, after_s: float):
    text = (
        default_rig_path().read_text().replace('plugin = "sim.arm"', f'plugin = "sim.arm"\nfault_after_s = {after_s}')
    )
    rig = tmp_path / "rig.toml"
    rig.write_text(text)
    return rig


def test_a_fault_mid_episode_ends_the_motion_until_the_operator_engages(tmp_path):
    out = tmp_path / "s.mcap"
    rec = LiveSession(RecordOptions(out=out, rig=_faulting_rig(tmp_path, 1.0)))
    rec.start()
    modes_sent = record_mode_updates(rec)
    try:
        run_script(rec, duration=6.0, episodes=2, engage_after=0.8)  # the second episode would engage at 3.8 s
        assert rec.loop.stats.engages == 1 and rec.loop.gate.state is GateState.FAULTED
        engage_until_accepted(rec)  # the operator's key (again while the arm reconnects)
        time.sleep(1.0)
    finally:
        rec.stop()
    assert rec.loop.stats.engages == 2
    with SessionReader(out) as reader:
        modes = [(m.log_time_ns, m.payload.data) for m in reader.messages([topics.MODE])]
        refused = [m.payload.data for m in reader.messages([topics.OPERATOR])]
        ticks = [m.payload.data["seq"] for m in reader.messages([topics.COMMAND_TICK])]
        arm = [(m.payload.stamp_ns, m.payload.positions) for m in reader.messages([topics.COMMAND_ARM])]
        states = [(m.log_time_ns, m.payload.positions) for m in reader.messages(["/arm/arm/state"])]
    halts = [t for t, d in modes if d.get("halt")]
    engages = [t for t, d in modes if d["mode"] == "execute"]
    assert len(halts) == 1 and [d["reason"] for _, d in modes if d.get("halt")] == ["device arm failed"]
    assert len(engages) == 2 and engages[0] < halts[0] < engages[1]
    assert [r["event"] for r in refused] == ["engage_refused"]  # the second episode's engage, once
    # nothing was sent between the fault and the operator's engage: no tick had adopted the halt without
    # also having the engage after it (a tick computed before the halt crossed the pipe may be stamped
    # after the halt's record; it did not know of the halt)
    halt_seq = next(u.seq for u in modes_sent if u.mode == "halt")
    engage_seq = next(u.seq for u in modes_sent if u.mode == "execute" and u.seq > halt_seq)
    assert not [seq for seq in ticks if halt_seq <= seq < engage_seq]
    assert [seq for seq in ticks if seq >= engage_seq]  # and the engage did send
    # the re-engage starts where the arm stands, at rest
    first = next(q for t, q in arm if t > engages[1])
    measured = [q for t, q in states if t <= engages[1]][-1]  # the driver's latest when the switch came
    assert np.abs(first - measured).max() < 1e-9
    assert audit_session(out).ok
