"""Sessions recorded by earlier teleprevs still read and evaluate: tests/fixtures/sim_v1.mcap (format 1:
speed caps only), sim_v2.mcap (format 2: motion limits, numpy arithmetic) and sim_v3.mcap (format 3: the
compiled hot path, commands computed at each pipeline step), each recorded with
tests/fixtures/fixture_rig.toml, two episodes engaged for 3 s each; sim_v5.mcap (format 5: commands from the
paced sender's planner, the whole hand braking where a command was not free), one episode of 7 s;
sim_v6.mcap (format 6: the arm engaged from its measured state), recorded with
tests/fixtures/fixture_physics_rig.toml, two episodes engaged for 3 s each.

Re-record it only when the format changes on purpose, and keep the old one as sim_v<N>.mcap: the point
is that older sessions keep working.
"""

from pathlib import Path

import numpy as np
import pytest

from teleprev.evaluation.evaluate import evaluate
from teleprev.messages import ImageSample, JointSample, TransformsSample
from teleprev.session.reader import SessionReader

FIXTURE = Path(__file__).parents[1] / "fixtures" / "sim_v1.mcap"
FIXTURE_V2 = Path(__file__).parents[1] / "fixtures" / "sim_v2.mcap"
FIXTURE_V3 = Path(__file__).parents[1] / "fixtures" / "sim_v3.mcap"
FIXTURE_V5 = Path(__file__).parents[1] / "fixtures" / "sim_v5.mcap"  # the whole hand braked (format 6: fingers)
FIXTURE_V6 = Path(__file__).parents[1] / "fixtures" / "sim_v6.mcap"  # engaged from the measured arm (7: held)


def test_every_stream_of_the_old_session_decodes():
    reader = SessionReader(FIXTURE)
    assert reader.metadata["teleprev"]["format_version"] == "1"
    kinds = {}
    for msg in reader.messages():
        kinds.setdefault(msg.topic, type(msg.payload))
    assert kinds["/camera/cam_front/image"] is ImageSample and kinds["/tf"] is TransformsSample
    assert kinds["/glove/glove/hand"] is JointSample
    assert [e.task for e in reader.episodes()] == ["pick_place", "pour"]
    assert all(e.outcome == "success" for e in reader.episodes())


def test_the_old_session_still_evaluates():
    result = evaluate([FIXTURE])
    session = result.report["sessions"][0]
    assert len(session["episodes"]) == 2
    o = result.report["overall"]
    assert o["steps"] > 400 and o["collision_after_frac"] == 0.0
    r = result.reruns[0]
    commanded = ~np.isnan(r.rerun["/command/hand"]).any(axis=1)
    assert commanded.sum() > 300
    # with the models it was recorded with, it must reproduce bit for bit
    assert r.models_match, f"the shipped models are not the ones {FIXTURE.name} was recorded with"
    assert session["bit_identical"]


def test_sessions_of_one_rig_share_a_pipeline_and_rerun_the_same():
    from teleprev.evaluation import reproduce

    first = reproduce.rerun_session(FIXTURE)
    built = dict(reproduce._BUILT)
    second = reproduce.rerun_session(FIXTURE)
    assert reproduce._BUILT == built and len(built) >= 1  # built once, reused
    for topic, table in first.rerun.items():
        np.testing.assert_array_equal(table, second.rerun[topic])
    assert [list(f) for f in first.flags] == [list(f) for f in second.flags]


@pytest.mark.parametrize("fixture,version", [(FIXTURE_V2, 2), (FIXTURE_V3, 3)], ids=["format2", "format3"])
def test_an_older_format_reruns_with_its_own_arithmetic_bit_for_bit(fixture, version):
    from teleprev.evaluation import reproduce

    reader = SessionReader(fixture)
    assert reader.metadata["teleprev"]["format_version"] == str(version)
    assert reproduce.recorded_format(reader.metadata) == version
    result = evaluate([fixture])
    session = result.report["sessions"][0]
    r = result.reruns[0]
    assert (~np.isnan(r.rerun["/command/arm"]).any(axis=1)).sum() > 500
    assert (~np.isnan(r.rerun["/command/hand"]).any(axis=1)).sum() > 300
    assert "ccn" in set(r.corrector)  # the CCN's arithmetic is part of what must reproduce
    assert r.models_match, f"the shipped models are not the ones {fixture.name} was recorded with"
    assert session["bit_identical"]


def test_a_planned_format_reruns_with_its_own_arithmetic_bit_for_bit():
    """Format 5: the planner's commands, the whole hand braking where a command was not free (format 6
    holds back only the colliding fingers, which would send other commands at the braked ticks)."""
    from teleprev import topics
    from teleprev.evaluation import reproduce

    reader = SessionReader(FIXTURE_V5)
    assert reproduce.recorded_format(reader.metadata) == 5
    braked = sum("hand_swept_braked" in m.payload.data["flags"] for m in reader.messages([topics.COMMAND_TICK]))
    assert braked > 5  # the fixture holds ticks whose commands format 6 would make otherwise
    result = evaluate([FIXTURE_V5])
    r = result.reruns[0]
    hand = r.commands[topics.COMMAND_HAND]
    assert (~np.isnan(hand.rerun).any(axis=1)).sum() > 500 and hand.same()
    assert r.models_match
    assert result.report["sessions"][0]["bit_identical"]


def test_format_6_reruns_its_engages_from_the_measured_arm_bit_for_bit(monkeypatch):
    """Format 6, recorded in the physics world: its second engage started from the measured arm, a
    picoradian off the command the controller held. It reproduces with its own planner, and would not with
    the current one (format 7 starts from the held command)."""
    from teleprev.evaluation import reproduce
    from teleprev.pipeline.older_formats import MeasuredEngagePlanner

    reader = SessionReader(FIXTURE_V6)
    assert reproduce.recorded_format(reader.metadata) == 6
    assert [m.payload.data["mode"] for m in reader.messages(["/events/mode"])] == ["execute", "preview"] * 2
    result = evaluate([FIXTURE_V6])
    r = result.reruns[0]
    arm = r.commands["/command/arm"]
    assert (~np.isnan(arm.rerun).any(axis=1)).sum() > 500 and arm.same()
    assert result.report["sessions"][0]["bit_identical"]
    monkeypatch.setattr(MeasuredEngagePlanner, "engages_from_held", True)  # as format 7 engages
    assert not evaluate([FIXTURE_V6]).reruns[0].commands["/command/arm"].same()


def test_a_rerun_keeps_the_long_lived_objects_out_of_the_collectors_scans(monkeypatch):
    """While a session re-runs, what was alive before it is frozen out of the garbage collector's scans
    (a full collection over it cost about a tenth of a re-run), and handed back afterwards."""
    import gc

    from teleprev.evaluation import reproduce

    seen = []
    rerun = reproduce._rerun

    def spy(*args):
        seen.append(gc.get_freeze_count())
        return rerun(*args)

    monkeypatch.setattr(reproduce, "_rerun", spy)
    before = gc.get_freeze_count()
    reproduce.rerun_session(FIXTURE_V3)
    assert seen and seen[0] > before + 1000
    assert gc.get_freeze_count() == before
