"""Where each LeRobot episode came from, as extra columns of lerobot's per-episode metadata
(meta/episodes/chunk-*/file-*.parquet): outcome, participant, condition, source_session, source_episode.

lerobot 0.6.1 has no API for per-episode fields of one's own, but its metadata loader keeps every column
of those files (io_utils.load_episodes drops only "stats/..."), so they come back in
`LeRobotDatasetMetadata.episodes` and `LeRobotDataset(..., episode_filter=...)` can select on them. They
are added after finalize(), when lerobot has written its last row.
"""

from __future__ import annotations

from pathlib import Path

from teleprev.export.report import SessionReport
from teleprev.export.selection import EpisodeFacts

COLUMNS = ("outcome", "participant", "condition", "source_session", "source_episode")
_MISSING = {"outcome": "", "participant": "", "condition": "", "source_session": "", "source_episode": -1}


def rows_for(reports: list[SessionReport], facts: list[EpisodeFacts]) -> list[dict]:
    """One row per LeRobot episode the reports wrote, in the dataset's order (a recorded episode split at
    gaps gives each piece the same row)."""
    known = {f.key: f for f in facts}
    rows = []
    for r in reports:
        for e in r.episodes:
            f = known.get((r.session, e.index))
            row = {
                "outcome": f.outcome if f else "",
                "participant": f.participant if f else "",
                "condition": f.condition if f else "",
                "source_session": Path(r.session).name,
                "source_episode": e.index,
            }
            rows += [row] * e.pieces
    return rows


def write_columns(root: Path, first_index: int, rows: list[dict]) -> None:
    """Set the columns of episodes first_index, first_index + 1, ... to `rows`; episodes before them keep
    theirs (an appended dataset's), or get empty values if they were exported without them."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    by_index = {first_index + i: row for i, row in enumerate(rows)}
    for path in sorted((Path(root) / "meta" / "episodes").rglob("*.parquet")):
        table = pq.read_table(path)
        indices = table.column("episode_index").to_pylist()
        for name in COLUMNS:
            old = table.column(name).to_pylist() if name in table.column_names else [None] * len(indices)
            values = [by_index[i][name] if i in by_index else (o if o is not None else _MISSING[name])
                      for i, o in zip(indices, old)]
            column = pa.array(values, type=pa.int64() if name == "source_episode" else pa.string())
            if name in table.column_names:
                table = table.set_column(table.column_names.index(name), name, column)
            else:
                table = table.append_column(name, column)
        pq.write_table(table, path)
