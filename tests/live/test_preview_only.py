"""A session recorded without ever engaging: record, info and export all say why it has no commands."""

import json

from teleprev.session.summary import PREVIEW_ONLY, summarize
from tests.helpers.cli import teleprev as cli


def test_a_preview_only_session_is_explained_by_record_info_and_export(tmp_path, sim_session):
    out = tmp_path / "p.mcap"
    run = cli("record", "--out", out, "--duration", "1.5", "--no-preview", columns=80)  # unattended, no --engage-after
    assert run.returncode == 0, run.stderr
    said = " ".join(run.stdout.split())
    assert f"preview only: {PREVIEW_ONLY}" in said

    assert summarize(out).preview_only
    info = " ".join(cli("info", out, columns=80).stdout.split())
    assert f"commands none: {PREVIEW_ONLY}" in info

    export = cli("export", out, "--repo-id", "lab/p", "--root", tmp_path / "ds", columns=80)
    assert export.returncode != 0
    err = " ".join(export.stderr.split())
    assert "is not in this session" in err and PREVIEW_ONLY in err
    assert not (tmp_path / "ds").exists()

    # among other sessions it is left out and listed, and does not stop them
    export = cli("export", out, sim_session, "--repo-id", "lab/two", "--root", tmp_path / "two", "--json")
    assert export.returncode == 0, export.stderr
    summary = json.loads(export.stdout.strip().splitlines()[-1])
    assert summary["skipped"] == {str(out): "recorded in preview only: no commands to export"}
    assert [s["session"] for s in summary["sessions"]] == [str(sim_session)] and summary["total_episodes"] == 1
    table = cli("export", out, sim_session, "--repo-id", "lab/three", "--root", tmp_path / "three", columns=80).stdout
    assert "…" not in table and sim_session.name in table  # 80 columns: the summary widens rather than cut a cell
    assert f"1 session(s) skipped: {out}: recorded in preview only" in " ".join(table.split())


def test_an_engaged_session_is_not_called_preview_only(sim_session):
    assert not summarize(sim_session).preview_only
