"""teleprev eval over a corpus: real sim sessions re-run in real worker processes (and one of them
made to die), one report for all, worst sessions first."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from teleprev.corpus.executor import FAULT_ENV, LocalExecutor
from teleprev.corpus.sessions import resolve_sessions
from teleprev.evaluation.corpus import PRELOAD, EvalJob, badness, eval_one, evaluate_corpus

pytestmark = pytest.mark.usefixtures("forkserver")  # workers fork with lerobot and eval imported

TIMING = {"latency_ms_p50", "latency_ms_p99", "rerun_wall_s", "realtime_x"}  # the only figures that may differ


@pytest.fixture
def corpus(sim_corpus):
    return sim_corpus


def figures(report: dict) -> dict:
    return {
        Path(s["session"]).name: {k: v for k, v in s["overall"].items() if k not in TIMING} for s in report["sessions"]
    }


def test_workers_give_the_figures_one_process_gives(corpus):
    sessions = resolve_sessions([corpus])
    alone = evaluate_corpus(sessions)
    workers = evaluate_corpus(sessions, executor=LocalExecutor(2, PRELOAD))
    assert alone.report["corpus"]["executor"] == "in-process" and workers.report["corpus"]["workers"] == 2
    assert figures(workers.report) == figures(alone.report) and len(figures(alone.report)) == 3
    assert all(s["bit_identical"] for s in workers.report["sessions"])
    ranked = workers.report["sessions"]
    assert [s["rank"] for s in ranked] == [1, 2, 3]
    assert [badness(s) for s in ranked] == sorted((badness(s) for s in ranked), reverse=True)


def test_a_worker_that_dies_is_retried_once_then_its_session_reported_failed(corpus, monkeypatch, tmp_path):
    paths = [str(p) for p in resolve_sessions([corpus])]
    monkeypatch.setenv(FAULT_ENV, "b.mcap@1")  # b's worker dies on the first attempt only
    outcomes = LocalExecutor(2, PRELOAD).map(eval_one, EvalJob(), paths)
    assert [(Path(o.label).name, o.ok, o.attempts) for o in outcomes] == [
        ("a.mcap", True, 1),
        ("b.mcap", True, 2),
        ("c.mcap", True, 1),
    ]
    assert outcomes[1].value["bit_identical"] is True

    monkeypatch.setenv(FAULT_ENV, "b.mcap")  # and now on every attempt
    result = evaluate_corpus(paths, executor=LocalExecutor(2, PRELOAD), plots=tmp_path / "plots")
    assert list(result.failed) == [paths[1]]
    assert "its worker died on each of 2 attempts (last exit code 70)" in result.failed[paths[1]]
    assert sorted(Path(s["session"]).name for s in result.report["sessions"]) == ["a.mcap", "c.mcap"]
    assert result.report["corpus"] | {"wall_s": 0, "wall_realtime_x": 0} == {
        "sessions": 3,
        "evaluated": 2,
        "failed": 1,
        "executor": "local",
        "workers": 2,
        "wall_s": 0,
        "wall_realtime_x": 0,
    }
    pngs = sorted(p.name for p in (tmp_path / "plots").iterdir())
    assert pngs == ["a_episode0.png", "c_episode0.png", "corpus.png"]
    assert all((tmp_path / "plots" / p).read_bytes()[:4] == b"\x89PNG" for p in pngs)


def test_the_cli_reports_a_corpus_worst_first_and_exits_1_on_a_failed_session(corpus, tmp_path):
    folder = tmp_path / "sessions"
    shutil.copytree(corpus, folder)
    (folder / "broken.mcap").write_bytes(b"\x89MCAP0\r\n" + os.urandom(4000))  # not a readable session
    out, base = tmp_path / "report.json", tmp_path / "baseline.json"
    run = [sys.executable, "-m", "teleprev.cli.app", "eval", f"{folder}/*.mcap", "-j", "2", "--out", str(out)]
    first = subprocess.run(run, capture_output=True, text=True, env=os.environ | {"COLUMNS": "120"})
    assert first.returncode == 1, first.stderr
    assert "1 session(s) could not be evaluated" in first.stdout and "broken.mcap" in first.stdout
    report = json.loads(out.read_text())
    assert [f["session"] for f in report["failed"]] == [str(folder / "broken.mcap")]
    assert len(report["sessions"]) == 3
    # a baseline in which c's hand moved half as fast: c regressed, so it is the worst session now
    for s in report["sessions"]:
        if s["session"].endswith("c.mcap"):
            s["overall"]["hand_speed_max"] *= 0.5
    base.write_text(json.dumps(report))
    (folder / "broken.mcap").unlink()
    again = subprocess.run(
        run + ["--baseline", str(base)], capture_output=True, text=True, env=os.environ | {"COLUMNS": "120"}
    )
    assert again.returncode == 0, again.stdout + again.stderr  # the overall figures did not move past their tolerance
    ranked = json.loads(out.read_text())["sessions"]
    assert Path(ranked[0]["session"]).name == "c.mcap" and ranked[0]["rank"] == 1
    assert any("hand_speed_max" in r for r in ranked[0]["regressions"]) and ranked[1]["regressions"] == []
    assert "c.mcap: hand_speed_max" in again.stdout
