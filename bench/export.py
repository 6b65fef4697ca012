"""Export figures: speed against real time, alignment error, memory against session length.

    python bench/export.py [--json] [--quick] [--keep DIR]

Sessions are synthetic sim sessions written with the session writer (teleprev/export/synthetic.py):
one 640x480 camera at 30 fps (JPEG quality 85, ~19 KB a frame like the sim camera's), arm state
100 Hz, hand state 90 Hz, glove 120 Hz, suit 60 Hz, pipeline outputs and commands at glove rate, every
stream with its own clock drift, jitter and delay. Each export runs in a fresh process with the
default recipe and video settings; its peak RSS is that process's.

Figures:
  realtime_x            seconds of recording exported per second of wall time (60 s session, 2 episodes),
                        from the start of the export; lerobot's import (once per command) is startup_s
  realtime_x_with_startup   the same, counting the import
  realtime_x_lerobot_encoder  the same export with lerobot's own streaming encoder thread
  realtime_x_av1        the same with AV1 (SVT-AV1 preset 12, crf 30: lerobot's default codec)
  backlog_realtime_x_workers1/2  two 60 s sessions in one export, in one process or in two workers,
                        lerobot's import, the workers' start and the merge (aggregate_datasets) included
  psnr_db_min           worst PSNR of 60 decoded frames against the recorded ones (and _av1)
  dataset_mb_per_min    dataset size per minute of recording (and _av1)
  max_align_err_ms      worst distance between a frame's time and the state/action samples used for it
  image_err_ms          worst distance between a frame's grid time and its camera frame
  peak_rss_mb           exporting a 10-minute session (ten 1-minute episodes); peak_rss_mb_1min for a
                        1-minute one; peak_rss_mb_10min_one_episode for ten minutes in a single episode
                        (LeRobot buffers an episode's frame values until save_episode, and so do we
                        its joint samples: memory follows the longest episode, not the session)
  rss_after_import_mb   the process after importing lerobot, before exporting

--quick: a 6 s session at 320x240, exported four ways (ours, lerobot's encoder, AV1, two workers), two
exports at a time; no backlog_realtime_x_workers1 and no memory figures (they need long sessions).

JSON keys:
    realtime_x                   float
    realtime_x_with_startup      float
    realtime_x_lerobot_encoder   float
    realtime_x_av1               float
    backlog_realtime_x_workers2  float
    startup_s                    float
    frames_per_s                 float
    max_align_err_ms             float
    image_err_ms                 float
    held_frames                  int
    psnr_db_min                  float
    dataset_mb_per_min           float
    psnr_db_min_av1              float
    dataset_mb_per_min_av1       float
    cores                        int
    load_avg_at_start            float
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402  (sets one-thread environment before numpy loads)

ROOT = Path(__file__).resolve().parent.parent


def make_sessions(folder: Path, quick: bool) -> dict[str, Path]:
    from teleprev.export.synthetic import EpisodeSpec, SyntheticSession

    if quick:
        return {"speed": _write(folder, SyntheticSession((EpisodeSpec("pick_place", 3.0), EpisodeSpec("pour", 3.0)),
                                                         width=320, height=240, seed=1)),
                "short": _write(folder, SyntheticSession((EpisodeSpec("pick_place", 3.0),), width=320, height=240,
                                                         seed=2), "short")}
    speed_s, long_s = 60.0, 600.0
    specs = {
        "speed": SyntheticSession(
            (EpisodeSpec("pick_place", speed_s / 2), EpisodeSpec("pour", speed_s / 2)), width=640, height=480, seed=1
        ),
        # memory (frames from a bank of 300): one minute; ten minutes in one-minute episodes; and ten
        # minutes in one episode, the worst case for the per-episode buffers (ours and lerobot's)
        "short": SyntheticSession((EpisodeSpec("pick_place", 60.0),), width=640, height=480, frame_bank=300, seed=2),
        "long": SyntheticSession(
            tuple(EpisodeSpec("pick_place", long_s / 10) for _ in range(10)),
            width=640,
            height=480,
            frame_bank=300,
            pause_s=0.2,
            seed=3,
        ),
        "long1": SyntheticSession((EpisodeSpec("pick_place", long_s),), width=640, height=480, frame_bank=300, seed=4),
    }
    return {name: _write(folder, spec, name) for name, spec in specs.items()}


def _write(folder: Path, spec, name: str = "speed") -> Path:
    """The session `spec` in folder (kept from an earlier run with --keep)."""
    from teleprev.export.synthetic import write_session

    path = folder / f"{name}-{int(sum(e.duration_s for e in spec.episodes))}s-{len(spec.episodes)}ep-{spec.width}.mcap"
    if not path.exists():
        t = time.perf_counter()
        tmp = path.with_suffix(".partial")
        tmp.unlink(missing_ok=True)
        write_session(tmp, spec)
        tmp.rename(path)
        print(f"wrote {path.name} in {time.perf_counter() - t:.0f} s", file=sys.stderr)
    return path


def min_psnr(session: Path, root: Path, samples: int = 60) -> float:
    """The worst PSNR (dB) of `samples` dataset frames, decoded with lerobot's decoder, against the
    recorded frames they came from (told apart by the frame number each synthetic frame carries)."""
    import cv2
    import numpy as np
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from lerobot.datasets.video_utils import decode_video_frames

    from teleprev.export.synthetic import read_frame_code
    from teleprev.session.reader import SessionReader

    ds = LeRobotDataset("bench/export", root=root, video_backend="pyav")
    key = ds.meta.video_keys[0]
    decoded = []
    for e, ep in enumerate(ds.meta.episodes):
        n = int(ep["length"])
        picks = np.linspace(0, n - 1, max(2, samples // len(ds.meta.episodes))).round().astype(int)
        ts = [float(ep[f"videos/{key}/from_timestamp"]) + int(k) / ds.fps for k in picks]
        frames = decode_video_frames(
            root / ds.meta.get_video_file_path(e, key), ts, 1e-4, backend="pyav", return_uint8=True
        )
        decoded.extend(frames.permute(0, 2, 3, 1).numpy())
    wanted = {read_frame_code(img): img for img in decoded}
    worst = float("inf")
    with SessionReader(session) as r:
        for m in r.messages([t for t in r.topics if t.startswith("/camera/")]):
            src = cv2.imdecode(np.frombuffer(m.payload.data, np.uint8), cv2.IMREAD_COLOR_RGB)
            img = wanted.pop(read_frame_code(src), None)
            if img is not None:
                mse = np.mean((img.astype(float) - src.astype(float)) ** 2)
                worst = min(worst, 10 * np.log10(255.0**2 / max(mse, 1e-12)))
    if wanted:
        raise SystemExit(f"{len(wanted)} decoded frames match no recorded frame")
    return worst


def child(session: str, root: str, encoder: str, codec: str = "h264", psnr: str = "", workers: str = "1") -> None:
    """One export in this (fresh) process; prints a JSON line with its figures."""
    import resource

    t0 = time.perf_counter()  # the process started a moment ago: interpreter and numpy only
    if int(workers) == 1:  # with workers, lerobot is imported by their fork server, inside the export
        import lerobot.datasets.lerobot_dataset  # noqa: F401  (the one-time import, timed apart)

    startup = time.perf_counter() - t0
    rss_start = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    from teleprev.export.recipe import load_recipe
    from teleprev.export.run import ExportOptions, export, with_video

    recipe = load_recipe()
    video = with_video(recipe, encoder=encoder, codec=codec)
    paths = [Path(p) for p in session.split(",")]
    report = export(ExportOptions(paths, "bench/export", Path(root), recipe, video=video, workers=int(workers)))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    sess = report.sessions[0]
    total = time.perf_counter() - t0
    print(json.dumps({
        "total_s": total,
        "psnr_db_min": min_psnr(paths[0], Path(root)) if psnr else None,
        "wall_s": report.wall_s, "startup_s": startup, "recorded_s": report.duration_s, "frames": report.frames,
        "realtime_x": report.realtime_x, "align_err_ms": report.align_err_ms, "image_err_ms": sess.image_err_ms,
        "held": sum(e.held_frames for e in sess.episodes), "size_mb": report.size_bytes / 1e6,
        "rss_after_import_mb": rss_start, "peak_rss_mb": peak,
    }))


def run_child(session: Path | list[Path], out: Path, encoder: str = "teleprev", codec: str = "h264", psnr: bool = False,
              workers: int = 1) -> dict:
    sessions = session if isinstance(session, list) else [session]
    root = out / f"ds-{sessions[0].stem}-{encoder}-{codec}-{workers}"
    shutil.rmtree(root, ignore_errors=True)
    env = dict(os.environ, HF_HUB_OFFLINE="1", HF_DATASETS_CACHE=str(out / "hf_cache"))
    proc = subprocess.run([sys.executable, __file__, "--child", ",".join(map(str, sessions)), str(root), encoder, codec,
                           "1" if psnr else "", str(workers)],
                          capture_output=True, text=True, env=env, cwd=ROOT)
    if proc.returncode != 0:
        raise SystemExit(f"export of {sessions[0].name} failed:\n{proc.stderr[-3000:]}")
    shutil.rmtree(root, ignore_errors=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(*sys.argv[2:8])
        return
    p = common.parser(__doc__)
    p.add_argument("--keep", type=Path, help="keep the generated sessions in this folder (and reuse them)")
    args = p.parse_args()
    folder = args.keep or Path(tempfile.mkdtemp(prefix="teleprev-bench-export-"))
    folder.mkdir(parents=True, exist_ok=True)
    try:
        sessions = make_sessions(folder, args.quick)
        load = os.getloadavg()[0]
        if args.quick:  # every kind of export once, two at a time: a smoke run, not figures
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(2) as pool:
                speed, stock, av1, two = pool.map(lambda kw: run_child(**kw), [
                    dict(session=sessions["speed"], out=folder, psnr=True),
                    dict(session=sessions["speed"], out=folder, encoder="lerobot"),
                    dict(session=sessions["speed"], out=folder, codec="av1", psnr=True),
                    dict(session=[sessions["speed"], sessions["short"]], out=folder, workers=2)])
            one = short = long = long1 = None
        else:
            speed = run_child(sessions["speed"], folder, psnr=True)
            stock = run_child(sessions["speed"], folder, encoder="lerobot")
            av1 = run_child(sessions["speed"], folder, codec="av1", psnr=True)
            backlog = [sessions["speed"], sessions["short"]]
            one = run_child(backlog, folder)
            two = run_child(backlog, folder, workers=2)
            short = run_child(sessions["short"], folder)
            long = run_child(sessions["long"], folder)
            long1 = run_child(sessions["long1"], folder)
    finally:
        if args.keep is None:
            shutil.rmtree(folder, ignore_errors=True)
    figures = {
        "realtime_x": round(speed["realtime_x"], 2),
        "realtime_x_with_startup": round(speed["recorded_s"] / (speed["wall_s"] + speed["startup_s"]), 2),
        "realtime_x_lerobot_encoder": round(stock["realtime_x"], 2),
        "realtime_x_av1": round(av1["realtime_x"], 2),
        "backlog_realtime_x_workers2": round(two["recorded_s"] / two["total_s"], 2),
        "startup_s": round(speed["startup_s"], 2),
        "frames_per_s": round(speed["frames"] / speed["wall_s"], 1),
        "max_align_err_ms": round(speed["align_err_ms"], 2),
        "image_err_ms": round(speed["image_err_ms"], 2),
        "held_frames": speed["held"],
        "psnr_db_min": round(speed["psnr_db_min"], 1),
        "dataset_mb_per_min": round(speed["size_mb"] * 60 / speed["recorded_s"], 2),
        "psnr_db_min_av1": round(av1["psnr_db_min"], 1),
        "dataset_mb_per_min_av1": round(av1["size_mb"] * 60 / av1["recorded_s"], 2),
        "cores": os.cpu_count(),
        "load_avg_at_start": round(load, 2),
    }
    if not args.quick:
        figures |= {
            "backlog_realtime_x_workers1": round(one["recorded_s"] / one["total_s"], 2),
            "peak_rss_mb": round(long["peak_rss_mb"], 1),
            "peak_rss_mb_1min": round(short["peak_rss_mb"], 1),
            "peak_rss_mb_10min_one_episode": round(long1["peak_rss_mb"], 1),
            "rss_after_import_mb": round(long["rss_after_import_mb"], 1),
            "long_session_s": round(long["recorded_s"], 1),
            "realtime_x_long": round(long["realtime_x"], 2),
        }
    targets = {"realtime_x": ">= 10", "max_align_err_ms": f"<= {1000 / 30 / 2:.1f} (half a frame at 30 fps)",
               "psnr_db_min": ">= 30",
               "peak_rss_mb": "flat: ~ peak_rss_mb_1min"}
    common.report("teleprev export", figures, targets, args.json)


if __name__ == "__main__":
    main()
