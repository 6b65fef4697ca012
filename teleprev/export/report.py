"""What an export did, per episode and session, and the summary table the CLI prints at the end."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass
class EpisodeReport:
    session: str
    index: int
    task: str
    pieces: int = 0  # LeRobot episodes made from it (more than one: split at gaps)
    frames: int = 0
    duration_s: float = 0.0
    dropped: str = ""  # why it was left out, "" when exported
    gaps: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    trimmed_s: float = 0.0
    held_frames: int = 0  # frames whose reference camera image is the previous one (a dropped camera frame)
    align_err_ms: float = 0.0  # worst distance between a frame's time and its state/action samples
    image_err_ms: float = 0.0  # worst distance between a frame's grid time and its camera frame (or a hold's age)


@dataclass
class SessionReport:
    session: str
    source_episodes: int
    episodes: list[EpisodeReport] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def exported(self) -> list[EpisodeReport]:
        return [e for e in self.episodes if not e.dropped]

    @property
    def frames(self) -> int:
        return sum(e.frames for e in self.episodes)

    @property
    def duration_s(self) -> float:
        return sum(e.duration_s for e in self.episodes)

    @property
    def lerobot_episodes(self) -> int:
        return sum(e.pieces for e in self.episodes)

    @property
    def align_err_ms(self) -> float:
        return max((e.align_err_ms for e in self.exported), default=0.0)

    @property
    def image_err_ms(self) -> float:
        return max((e.image_err_ms for e in self.exported), default=0.0)


@dataclass
class ExportReport:
    root: Path
    repo_id: str
    fps: int
    sessions: list[SessionReport]
    wall_s: float = 0.0
    startup_s: float = 0.0  # of wall_s, loading lerobot (once per process)
    size_bytes: int = 0
    total_episodes: int = 0  # in the dataset after the export (appending: with the earlier ones)
    total_frames: int = 0
    failed: dict[str, str] = field(default_factory=dict)  # session -> why it was left out (its task failed)
    skipped: dict[str, str] = field(default_factory=dict)  # session -> why it was not exported (no commands)
    cleaned: list[str] = field(default_factory=list)  # what was cleaned up after earlier, killed exports
    selection: dict[str, int] = field(default_factory=dict)  # "recorded", then each filter: episodes left after it

    @property
    def frames(self) -> int:
        return sum(s.frames for s in self.sessions)

    @property
    def duration_s(self) -> float:
        return sum(s.duration_s for s in self.sessions)

    @property
    def episodes(self) -> int:
        return sum(s.lerobot_episodes for s in self.sessions)

    @property
    def align_err_ms(self) -> float:
        return max((s.align_err_ms for s in self.sessions), default=0.0)

    @property
    def realtime_x(self) -> float:
        return self.duration_s / self.wall_s if self.wall_s > 0 else 0.0


def folder_size(root: Path) -> int:
    return sum(p.stat().st_size for p in Path(root).rglob("*") if p.is_file())


def summary_table(report: ExportReport):
    """A rich Table: one row per session, totals last. Which episodes were left out, split or trimmed,
    and why, is listed under it (`export_notes`), so the table stays narrow enough for 80 columns."""
    from rich.table import Table

    table = Table(title=f"{report.repo_id} -> {report.root} ({report.size_bytes / 1e6:.1f} MB)", title_justify="left")
    longest = max((len(Path(s.session).name) for s in report.sessions), default=0)
    table.add_column("session", min_width=min(longest, 9))
    for name in ("rec.", "dropped", "episodes", "frames", "duration", "align err", "held"):
        table.add_column(name, justify="right")

    def dropped(s: SessionReport) -> int:
        return sum(1 for e in s.episodes if e.dropped)

    for s in report.sessions:
        table.add_row(
            Path(s.session).name, str(s.source_episodes), str(dropped(s)), str(s.lerobot_episodes), str(s.frames),
            f"{s.duration_s:.1f} s", f"{s.align_err_ms:.1f} ms", str(sum(e.held_frames for e in s.episodes)),
        )
    table.add_section()
    table.add_row(
        "total", str(sum(s.source_episodes for s in report.sessions)), str(sum(dropped(s) for s in report.sessions)),
        str(report.episodes), str(report.frames), f"{report.duration_s:.1f} s", f"{report.align_err_ms:.1f} ms", "",
    )
    table.caption = (
        f"rec.: episodes recorded; dropped: left out; episodes: LeRobot episodes made of the rest (more where "
        f"a gap split one); {report.fps} fps; align err: worst distance between a frame's time and the "
        "state/action samples used for it; held: frames whose camera image is the previous one"
    )
    return table


def _session_notes(s: SessionReport) -> list[str]:
    dropped = [f"ep {e.index} left out: {e.dropped}" for e in s.episodes if e.dropped]
    split = [f"ep {e.index} split in {e.pieces} ({'; '.join(e.gaps)})" for e in s.episodes if e.pieces > 1]
    trimmed = [f"ep {e.index}: {n}" for e in s.episodes if not e.dropped for n in e.notes]
    return dropped + split + trimmed + s.notes


def export_notes(report: ExportReport) -> list[str]:
    """One line per episode that was left out, split or trimmed, and the export's totals."""
    lines = [f"{Path(s.session).name} {note}" for s in report.sessions for note in _session_notes(s)]
    if report.selection:
        lines.append("selected: " + "; ".join(f"{label} {n}" if label == "recorded" else f"{label} kept {n}"
                                              for label, n in report.selection.items()))
    speed = f"{report.realtime_x:.1f}x real time"
    if report.startup_s >= 0.1 * report.wall_s:
        working = max(report.wall_s - report.startup_s, 1e-9)
        speed += f"; {report.startup_s:.1f} s of it loading lerobot, {report.duration_s / working:.1f}x without"
    lines.append(f"exported {report.duration_s:.1f} s of recording in {report.wall_s:.1f} s ({speed}); "
                 f"the dataset now holds {report.total_episodes} episodes, {report.size_bytes / 1e6:.1f} MB")
    if report.skipped:
        from rich.markup import escape

        lines.append(f"[yellow]{len(report.skipped)} session(s) skipped[/]:")
        lines += [f"  {escape(session)}: {escape(why)}" for session, why in report.skipped.items()]
    if report.failed:
        lines.append(
            f"[red]{len(report.failed)} session(s) failed and were left out[/] (export them again with --append):"
        )
        from rich.markup import escape

        lines += [f"  [red]{escape(why)}[/]" for why in report.failed.values()]
    return lines
