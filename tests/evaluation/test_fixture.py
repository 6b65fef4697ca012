"""A session recorded by an earlier teleprev (tests/fixtures/sim_v1.mcap, format 1) still reads and evaluates.

Re-record it only when the format changes on purpose, and keep the old one as sim_v<N>.mcap: the point
is that older sessions keep working.
"""

from pathlib import Path

import numpy as np

from teleprev.messages import ImageSample, JointSample, TransformsSample
from teleprev.evaluation.evaluate import evaluate
from teleprev.session.reader import SessionReader

FIXTURE = Path(__file__).parents[1] / "fixtures" / "sim_v1.mcap"


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
    if r.models_match:  # with the models it was recorded with, it must reproduce bit for bit
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
