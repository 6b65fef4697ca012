"""Dataset figures of issue 28: a LeRobot dataset episode replayed to the sim robot, and an export of the
episodes marked successful.

    python bench/dataset_figures.py [--json] [--folder DIR]

dataset_replay_ok: a short sim session is recorded through the live path and exported; episode 0 of that
dataset is replayed to the sim robot (`teleprev replay DATASET --episode 0 --to sim --smooth --out`), and
the recorded replay holds commands for both sides and passes `teleprev audit`.
filtered_export_ok: two sessions with y / f / unmarked / discarded episodes exported `--only success`; the
dataset, loaded back with lerobot, holds exactly the episodes marked y (by source session and episode),
each with next.success and next.done on its last frame only.

`measure(folder)` gives both (bench/rollout.py calls it); everything is written under `folder`.

JSON keys:
    dataset_replay_ok   bool
    filtered_export_ok  bool
"""

from __future__ import annotations

import io
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SIM_RIG = ROOT / "rigs" / "sim.toml"


def _record(path: Path, seconds: float = 3.0, engage_after: float = 0.5) -> None:
    """One pick_place episode on the default sim rig, engaged `engage_after` s in (asked again until it is)."""
    from teleprev.live.record.session import LiveSession, RecordOptions

    rec = LiveSession(RecordOptions(out=path, rig=SIM_RIG, task="pick_place"))
    rec.start()
    try:
        rec.loop.start_episode("pick_place")
        time.sleep(engage_after)
        end = time.monotonic() + seconds - engage_after
        while time.monotonic() < end:
            if rec.loop.stats.engages == 0:
                rec.loop.engage("bench")
            time.sleep(min(0.25, max(0.0, end - time.monotonic())))
        rec.loop.to_preview("bench")
        rec.loop.stop_episode()
    finally:
        rec.stop()


def dataset_replay_ok(folder: Path) -> bool:
    from rich.console import Console

    from teleprev.evaluation.audit import audit_session
    from teleprev.export.recipe import load_recipe
    from teleprev.export.run import ExportOptions, export
    from teleprev.live.replay.playback import play
    from teleprev.session.reader import SessionReader

    session, root, out = folder / "sim.mcap", folder / "sim_dataset", folder / "replay.mcap"
    _record(session)
    export(ExportOptions([session], "bench/sim", root, load_recipe("default")))
    quiet = Console(file=io.StringIO())
    play(root, 0, 1.0, "sim", SIM_RIG, 0.0, quiet, "side", False, smoothed=True, out=out)
    with SessionReader(out) as reader:
        sides = {t: sum(1 for _ in reader.messages([t])) for t in ("/command/arm", "/command/hand")}
        episodes = reader.episodes()
    return len(episodes) == 1 and min(sides.values()) > 100 and audit_session(out).ok


def filtered_export_ok(folder: Path) -> bool:
    import numpy as np
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from teleprev.export.recipe import load_recipe
    from teleprev.export.run import ExportOptions, export
    from teleprev.export.selection import Selection, plan_exports, read_facts
    from teleprev.export.synthetic import EpisodeSpec as E
    from teleprev.export.synthetic import SyntheticSession, write_session

    def session(name, episodes, seed):
        return write_session(folder / name, SyntheticSession(episodes, width=160, height=120, pause_s=0.5, seed=seed))

    paths = [session("a.mcap", (E("pick_place", 1.0, outcome="success"), E("pick_place", 1.0, outcome="failure"),
                                E("pour", 1.0, outcome="success")), 1),
             session("b.mcap", (E("pour", 1.0), E("pick_place", 1.0, outcome="success"),
                                E("pick_place", 1.0, outcome="success", discarded=True)), 2)]
    marked_y = [
        (Path(f.session).name, f.index) for f in read_facts(paths) if f.outcome == "success" and not f.discarded
    ]
    root = folder / "success"
    options = ExportOptions(paths, "bench/success", root, load_recipe("default"))
    (only,), _ = plan_exports(options, Selection(only="success"), None, "session", 0)
    export(only)
    ds = LeRobotDataset("bench/success", root=root, video_backend="pyav")
    meta = ds.meta.episodes
    got = [(meta["source_session"][i], meta["source_episode"][i]) for i in range(len(meta))]
    table = ds.hf_dataset.with_format("numpy")
    episode = np.asarray(table["episode_index"])
    last = np.r_[episode[1:] != episode[:-1], True]
    done, success = (np.asarray(table[k]).reshape(-1) for k in ("next.done", "next.success"))
    return got == marked_y and len(got) == 3 and bool((done == last).all() and (success == last).all())


def measure(folder: Path) -> dict:
    import os

    import datasets

    folder = Path(folder)
    for part in ("replay", "filtered", "hf_cache"):
        (folder / part).mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("HF_HUB_OFFLINE", "1")  # all local: nothing may reach for the Hub
    cache = datasets.config.HF_DATASETS_CACHE
    datasets.config.HF_DATASETS_CACHE = folder / "hf_cache"  # loading a dataset back caches its tables here
    try:
        return {"dataset_replay_ok": dataset_replay_ok(folder / "replay"),
                "filtered_export_ok": filtered_export_ok(folder / "filtered")}
    finally:
        datasets.config.HF_DATASETS_CACHE = cache


def main() -> None:
    p = common.parser(__doc__)
    p.add_argument("--folder", type=Path, default=None, help="where to write (default: a temporary folder)")
    args = p.parse_args()
    if args.folder is not None:
        figures = measure(args.folder)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            figures = measure(Path(tmp))
    common.report("dataset replay and filtered export (issue 28)", figures,
                  {"dataset_replay_ok": "true", "filtered_export_ok": "true"}, args.json)


if __name__ == "__main__":
    main()
