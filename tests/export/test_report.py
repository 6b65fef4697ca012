"""The export summary: narrow enough for an 80-column terminal, and every episode that was left out,
split or trimmed is named under it."""

from pathlib import Path


def test_export_summary_fits_80_columns_and_lists_what_was_left_out():
    from rich.console import Console

    from teleprev.export.report import EpisodeReport, ExportReport, SessionReport, export_notes, summary_table

    kept = EpisodeReport("s.mcap", 0, "pick_place", pieces=1, frames=300, duration_s=10.0,
                         notes=["left out 3 frames at 0.03 s (shorter than min_episode_s)"])
    gone = EpisodeReport("s.mcap", 1, "pick_place", dropped="discarded by the operator")
    long_name = SessionReport("sessions/pick_place_participant_07_2026-11-22.mcap", 1, [])
    report = ExportReport(Path("out"), "local/x", 30, [SessionReport("s.mcap", 2, [kept, gone]), long_name], wall_s=1.0)
    console = Console(width=80, record=True, color_system=None)
    console.print(summary_table(report))
    lines = console.export_text().splitlines()
    header = next(line for line in lines if "session" in line)
    assert header.rstrip().endswith("held ┃")  # the last column is whole: nothing cropped at 80 columns
    row = next(line for line in lines if line.startswith("│ s.mcap"))
    assert [c.strip() for c in row.split("│")[2:5]] == ["2", "1", "1"]  # recorded, dropped, exported
    notes = export_notes(report)
    assert "s.mcap ep 1 left out: discarded by the operator" in notes
    assert any(n.startswith("s.mcap ep 0: left out 3 frames") for n in notes)
    assert "10.0x real time" in notes[-1]


def test_the_speed_line_separates_loading_lerobot_from_exporting():
    from teleprev.export.report import EpisodeReport, ExportReport, SessionReport, export_notes

    ep = EpisodeReport("s.mcap", 0, "pour", pieces=1, frames=300, duration_s=10.0)
    report = ExportReport(Path("out"), "local/x", 30, [SessionReport("s.mcap", 1, [ep])], wall_s=6.0, startup_s=4.0)
    assert (
        "10.0 s of recording in 6.0 s (1.7x real time; 4.0 s of it loading lerobot, 5.0x without)"
        in export_notes(report)[-1]
    )
    report.startup_s = 0.1  # lerobot already loaded (a second export in one process): nothing to separate
    assert "(1.7x real time)" in export_notes(report)[-1]
