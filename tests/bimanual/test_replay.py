"""`teleprev replay` of a bimanual session and of a bimanual dataset, to the simulated robots: each side
played as its own single-arm replay (its commands or its left_/right_ action columns, its own limits and
generator), both from one recorded instant, the replay recorded as a bimanual session that the audit passes;
and the refusal of a sequence that would bring the two robots into contact."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from teleprev.session.reader import SessionReader
from tests.bimanual.test_record_export import expected_names
from tests.helpers.cli import teleprev

RIG = Path(__file__).resolve().parents[2] / "rigs" / "sim_bimanual.toml"
SIDES = ("left", "right")


def commands(path: Path, topic: str, played_only: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(stamps ns, positions) of a command stream; `played_only`: those in the file's one episode (a replay's
    played steps, not its engage ramp)."""
    with SessionReader(path) as reader:
        lo = reader.episodes()[0].start_ns if played_only else 0
        msgs = [m.payload for m in reader.messages([topic]) if m.log_time_ns >= lo]
    return np.array([m.stamp_ns for m in msgs], dtype=np.int64), np.array([m.positions for m in msgs])


def audited(path: Path, tmp_path: Path) -> dict:
    out = tmp_path / f"{path.stem}_audit.json"
    ran = teleprev("audit", path, "--json", out)
    assert ran.returncode == 0, ran.stdout
    (report,) = json.loads(out.read_text())
    return {s["topic"]: s["commands"] for s in report["streams"]}


def test_a_bimanual_session_is_replayed_to_sim_smoothed_and_refused_unsmoothed(session, tmp_path):
    ran = teleprev("replay", session, "--to", "sim", "--engage-after", "0", "--no-preview")
    assert ran.returncode == 2, ran.stdout + ran.stderr
    assert "add --smooth" in " ".join((ran.stdout + ran.stderr).split())
    out = tmp_path / "replay.mcap"
    ran = teleprev("replay", session, "--to", "sim", "--smooth", "--engage-after", "0", "--no-preview", "--out", out)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    for side in SIDES:
        for kind in ("arm", "hand"):
            topic = f"/command/{side}/{kind}"
            _, q_src = commands(session, topic)
            _, q = commands(out, topic, played_only=True)
            assert len(q) > 50
            np.testing.assert_allclose(q[-1], q_src[-1], atol=1e-6)  # at rest on this side's last command
    with SessionReader(out) as reader:
        for side in SIDES:  # the simulated arm of each side followed that side's commands
            states = [m.payload for m in reader.messages([f"/arm/arm_{side}/state"])]
            assert len(states) > 50
            np.testing.assert_allclose(states[-1].positions, commands(session, f"/command/{side}/arm")[1][-1],
                                       atol=0.01)
    counts = audited(out, tmp_path)
    assert list(counts) == [f"/command/{s}/{k}" for s in SIDES for k in ("arm", "hand")]


def test_a_bimanual_dataset_episode_replays_to_sim_smoothed(dataset, tmp_path):
    import pyarrow.parquet as pq

    out = tmp_path / "replay.mcap"
    ran = teleprev("replay", dataset, "--episode", "0", "--to", "sim", "--config", RIG, "--smooth",
                   "--engage-after", "0", "--no-preview", "--out", out)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    table = pq.read_table(sorted((dataset / "data").rglob("*.parquet"))[0], columns=["action"]).to_pydict()
    action, names = np.asarray(table["action"], dtype=float), expected_names()
    for side in SIDES:
        for kind, joints in (("arm", [f"joint{i}" for i in range(1, 7)]), ("hand", [str(i) for i in range(16)])):
            _, q = commands(out, f"/command/{side}/{kind}", played_only=True)
            last = action[-1, [names.index(f"{side}_{kind}.{j}") for j in joints]]
            assert len(q) > 100
            np.testing.assert_allclose(q[-1], last, atol=1e-6)  # at rest on this side's last action
    assert all(n > 100 for n in audited(out, tmp_path).values())


def test_a_replay_that_would_join_the_two_robots_is_refused(dataset, tmp_path):
    rig = tmp_path / "one_mount.toml"  # both arms on one base: every step has them in contact
    rig.write_text(RIG.read_text().replace("mount_xyz = [0.0, -0.30, 0.0]", "mount_xyz = [0.0, 0.30, 0.0]"))
    ran = teleprev("replay", dataset, "--episode", "0", "--to", "sim", "--config", rig, "--smooth",
                   "--engage-after", "0", "--no-preview")
    assert ran.returncode != 0
    assert "not replaying: the two sides' commands touch 0.000 s in (" in " ".join((ran.stdout + ran.stderr).split())
