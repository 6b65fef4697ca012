"""The export summary: narrow enough for an 80-column terminal, and every episode that was left out,
split or trimmed is named under it."""

from pathlib import Path


def test_export_summary_fits_80_columns_and_lists_what_was_left_out():
    from rich.console import Console

    from teleprev.export.report import EpisodeReport, ExportReport, SessionReport, export_notes, summary_table

    kept = EpisodeReport("s.mcap", 0, "pick_place", pieces=1, frames=300, duration_s=10.0,
                         notes=["left out 3 frames at 0.03 s (shorter than min_episode_s)"])
    gone = EpisodeReport("s.mcap", 1, "pick_place", dropped="discarded by the operator")
    report = ExportReport(Path("out"), "local/x", 30, [SessionReport("s.mcap", 2, [kept, gone])], wall_s=1.0)
    console = Console(width=80, record=True, color_system=None)
    console.print(summary_table(report))
    text = console.export_text()
    assert max(len(line) for line in text.splitlines()) <= 80
    row = next(line for line in text.splitlines() if line.startswith("│ s.mcap"))
    assert row.split("│")[-2].strip() == "2"  # two notes for this session, each listed below the table
    notes = export_notes(report)
    assert "s.mcap ep 1 left out: discarded by the operator" in notes
    assert any(n.startswith("s.mcap ep 0: left out 3 frames") for n in notes)
    assert "10.0x real time" in notes[-1]
