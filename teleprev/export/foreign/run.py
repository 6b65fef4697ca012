"""`teleprev import`: foreign recordings into a LeRobot dataset with the export's own machinery (one
process; the files are opened through open_foreign instead of as teleprev sessions)."""

from __future__ import annotations

from functools import partial
from pathlib import Path

from teleprev.errors import SessionError
from teleprev.export.foreign.config import ImportRecipe
from teleprev.export.foreign.foxglove import FoxgloveReader
from teleprev.export.foreign.ros import RosBagReader
from teleprev.export.report import ExportReport
from teleprev.export.run import ExportOptions, export
from teleprev.export.session import Reporter, no_progress
from teleprev.export.video import VideoSettings


def detect_format(path: Path) -> str:
    """"ros2" (a rosbag2 folder, a .db3, or an MCAP whose messages are CDR) or "foxglove" (an MCAP of
    protobuf / JSON messages)."""
    path = Path(path)
    if path.is_dir():
        if not (path / "metadata.yaml").is_file():
            raise SessionError("a folder, but not a rosbag2 recording (no metadata.yaml)", str(path))
        return "ros2"
    if not path.is_file():
        raise SessionError("no such file or folder", str(path))
    if path.suffix == ".db3":
        return "ros2"
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except (McapError, OSError, ValueError) as exc:
        raise SessionError(f"not a readable MCAP file ({exc})", str(path)) from None
    if summary is None:  # no summary section: teleprev's reader indexes it by a scan (protobuf / JSON only)
        return "foxglove"
    encodings = {c.message_encoding for c in summary.channels.values()}
    # teleprev's own sessions carry one CDR channel (/robot_description) beside their protobuf ones
    return "ros2" if "cdr" in encodings and "protobuf" not in encodings else "foxglove"


def open_foreign(path: Path, recipe: ImportRecipe):
    return (RosBagReader if detect_format(path) == "ros2" else FoxgloveReader)(path, recipe)


def import_files(
    paths: list[Path],
    recipe: ImportRecipe,
    repo_id: str,
    root: Path,
    *,
    fps: int = 0,
    append: bool = False,
    video: VideoSettings | None = None,
    report: Reporter = no_progress,
) -> ExportReport:
    options = ExportOptions(list(paths), repo_id, Path(root), recipe.recipe, fps=fps, append=append, video=video,
                            open_reader=partial(open_foreign, recipe=recipe))
    return export(options, report)
