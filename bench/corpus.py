"""Corpus figures: export and eval of 8 sessions with 2 workers against 1, and what Ray costs.

    python bench/corpus.py [--json] [--quick] [--no-ray] [--only eval|export] [--eval-s S] [--export-s S] [--runs N]
                           [--encoder-threads 0,1] [--busy N]

Every timing is a whole `teleprev` command in a fresh process (`python -m teleprev.cli.app ...`), as a
user runs it: interpreter start, imports (lerobot's for export), workers' start, the sessions, and for
export lerobot's aggregate_datasets merge of the parts.

  eval:    8 sessions of the default sim rig (LEAP Hand, shipped models): two recorded through the real
           recording path (one episode each, engaged 2 s in), each copied to 4 files: eval re-runs every
           file from scratch, so the copies are 8 sessions' work; `teleprev eval DIR -j N`.
  export:  8 synthetic sessions of 30 s (teleprev/export/synthetic.py: one 640x480 camera at 30 fps like
           the sim camera's, arm, hand, glove and suit streams, commands), default recipe and video;
           `teleprev export DIR -j N`.
  --quick: 4 sessions, not 8: eval's of 3 s (one recording, copied), export's of 2 s at 160x120; no
           eval_ray_wall_s (Ray's start and scheduling are still measured).

Figures:
  corpus_speedup_2_workers          the smaller of the two below (the issue's target: >= 1.7)
  corpus_speedup_2_workers_eval     wall time with -j 1 (in one process) over -j 2 (two worker processes)
  corpus_speedup_2_workers_export   the same for export (-j 1 writes one dataset; -j 2 writes parts and merges)
  ray_overhead_s                    starting a local Ray instance (2 CPUs) plus scheduling 8 no-op tasks on it
                                    (their worker processes start then), in one process: what --ray adds
  ray_start_s, ray_schedule_s       its two parts; ray_shutdown_s is paid at the end of a command
  eval_ray_wall_s                   `teleprev eval DIR --ray -j 2` (a local instance with 2 CPUs)
  *_cores_busy_workers1             CPU seconds over wall seconds of those runs: one export process already
                                    keeps more than a core busy (the video encoder's thread beside the
                                    reading and aligning one), so 2 workers on 2 cores gain at most
                                    2 / that on the sessions, before the serial merge and lerobot's import
  *_wall_s                          the commands' wall times behind the ratios (best of two runs, 1 and 2
                                    workers alternating, since other work shares the cores)
  export_sessions_per_min_workers{N}_threads{T}
                                    with --encoder-threads: export's sessions per minute with N workers and
                                    each worker's video encoder capped at T threads (0: the encoder's own
                                    choice, one per core), the recipe's [video] threads
The machine's cores are shared: cpu_count and the load average before the runs say how busy it was.
--busy N adds N busy processes of the bench's own beside every timed command (not the sessions' making).

Each command also pays costs that do not shrink with workers: the interpreter and imports (lerobot's
import alone is about 4 s, torch and torchvision inside it; eval's modules and its compiled kernels
about 1 s), opening and checking every session, and export's merge. --eval-s and --export-s set the
sessions' length (default 20 and 30 s) to see how the ratio grows as the sessions outweigh them.

JSON keys:
    cpu_count                        int
    load_avg_1min_before             float
    eval_cores_busy_workers1         float
    export_cores_busy_workers1       float
    corpus_speedup_2_workers_eval    float
    corpus_speedup_2_workers_export  float
    corpus_speedup_2_workers         float
    eval_wall_s_workers1             float
    export_wall_s_workers1           float
    eval_wall_s_workers2             float
    export_wall_s_workers2           float
    eval_recorded_s                  float
    export_recorded_s                float
    ray_overhead_s                   float
    ray_start_s                      float
    ray_schedule_s                   float
    ray_shutdown_s                   float
    load_avg_1min_after              float
    busy_processes                   int
"""

from __future__ import annotations

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
SESSIONS = 8


def record_eval_sessions(folder: Path, seconds: float, sessions: int, recordings: int = 2) -> None:
    from teleprev.live.record.session import LiveSession, RecordOptions

    folder.mkdir(parents=True)
    recorded = []
    for k in range(recordings):
        path = folder.parent / f"recorded{k}.mcap"
        rec = LiveSession(RecordOptions(out=path))
        rec.start()
        try:
            rec.loop.start_episode("pick_place")
            time.sleep(2.0)
            rec.loop.engage("bench")
            time.sleep(seconds - 2.0)
            rec.loop.to_preview("bench")
            rec.loop.stop_episode()
        finally:
            rec.stop()
        recorded.append(path)
    for i in range(sessions):
        shutil.copyfile(recorded[i % recordings], folder / f"s{i}.mcap")


def write_export_sessions(folder: Path, seconds: float, width: int, height: int, sessions: int) -> None:
    from teleprev.export.synthetic import EpisodeSpec, SyntheticSession, write_session

    folder.mkdir(parents=True)
    for i in range(sessions):
        write_session(folder / f"s{i}.mcap", SyntheticSession(
            (EpisodeSpec("pick_place", seconds / 2), EpisodeSpec("pour", seconds / 2)), width=width, height=height,
            frame_bank=100, seed=i))


BUSY: list[float] = []  # cores each command kept busy: its CPU seconds (and its children's) over its wall time


def timed(args: list[str]) -> float:
    import resource

    env = os.environ | {"HF_HUB_OFFLINE": "1", "COLUMNS": "100"}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "teleprev.cli.app", *args], capture_output=True, text=True, env=env, cwd=ROOT
    )
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    BUSY.append((after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime) / wall)
    if done.returncode != 0:
        raise SystemExit(
            f"teleprev {' '.join(args)} failed ({done.returncode}):\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
        )
    return wall


def noop(context, item, emit):
    return item


def ray_overhead(sessions: int) -> dict:
    from teleprev.corpus.executor import RayExecutor

    t0 = time.perf_counter()
    executor = RayExecutor("local", cpus=2)
    t1 = time.perf_counter()
    outcomes = executor.map(noop, None, list(range(sessions)))
    t2 = time.perf_counter()
    executor.close()
    t3 = time.perf_counter()
    assert all(o.ok for o in outcomes)
    return {"ray_overhead_s": t2 - t0, "ray_start_s": t1 - t0, "ray_schedule_s": t2 - t1, "ray_shutdown_s": t3 - t2}


def best_walls(argv: dict, commands: list[str], runs: int, tmp: Path, figures: dict) -> dict[str, float]:
    """Each command with 1 and 2 workers, `runs` times, alternating (the cores are shared with others): the
    best wall time of each, "<command>_wall_s_workers<n>"; the cores the best 1-worker run kept busy go
    into figures as "<command>_cores_busy_workers1"."""
    walls: dict[str, float] = {}
    for _ in range(runs):
        for n in (1, 2):
            for command in commands:
                key = f"{command}_wall_s_workers{n}"
                took = timed(argv[command](n))
                if took < walls.get(key, float("inf")):
                    walls[key] = took
                    if n == 1:  # (a fork server's workers are not the command's children: not counted)
                        figures[key.replace("wall_s", "cores_busy")] = BUSY[-1]
                shutil.rmtree(tmp / f"ds{n}", ignore_errors=True)
    return walls


def encoder_thread_figures(
    export_argv, thread_counts: list[int], runs: int, tmp: Path, sessions: int
) -> dict[str, float]:
    """Sessions per minute of the export with each worker's video encoder capped at each thread count, with 1
    and 2 workers (best of `runs`)."""
    figures = {}
    for threads in thread_counts:
        recipe = tmp / f"threads{threads}.toml"
        recipe.write_text((ROOT / "datasets" / "recipes" / "default.toml").read_text().replace(
            "[video]\n", f"[video]\nthreads = {threads}\n", 1))
        for n in (1, 2):
            best = float("inf")
            for _ in range(runs):
                best = min(best, timed([*export_argv(n), "--recipe", str(recipe)]))
                shutil.rmtree(tmp / f"ds{n}", ignore_errors=True)
            figures[f"export_sessions_per_min_workers{n}_threads{threads}"] = sessions * 60.0 / best
    return figures


def main() -> None:
    p = common.parser(__doc__)
    p.add_argument("--no-ray", action="store_true", help="leave out the Ray figures (without the ray extra)")
    p.add_argument("--only", choices=("eval", "export"), default=None, help="measure one of the two commands")
    p.add_argument("--eval-s", type=float, default=None, help="length of each eval session in seconds (default 20)")
    p.add_argument("--export-s", type=float, default=None, help="length of each export session in seconds (default 30)")
    p.add_argument("--runs", type=int, default=None, help="runs of each command, best kept (default 2)")
    p.add_argument("--busy", type=int, default=0, help="busy processes beside the timed commands")
    p.add_argument("--encoder-threads", default="", help="export again with the encoder capped at each of these "
                   "thread counts (comma-separated; 0: the encoder's own choice)")
    args = p.parse_args()
    eval_s, export_s, size = (3.0, 2.0, (160, 120)) if args.quick else (20.0, 30.0, (640, 480))
    sessions = 4 if args.quick else SESSIONS
    eval_s, export_s = args.eval_s or eval_s, args.export_s or export_s
    runs = args.runs or (1 if args.quick else 2)
    commands = [c for c in ("eval", "export") if args.only in (None, c)]
    figures: dict = {"cpu_count": os.cpu_count(), "load_avg_1min_before": round(os.getloadavg()[0], 2)}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if "eval" in commands:
            record_eval_sessions(tmp / "eval", eval_s, sessions, 1 if args.quick else 2)
            timed(["eval", str(tmp / "eval" / "s0.mcap")])  # warm the file cache and numba's kernel cache
        if "export" in commands:
            write_export_sessions(tmp / "export", export_s, *size, sessions)
        argv = {"eval": lambda n: ["eval", str(tmp / "eval"), "-j", str(n)],
                "export": lambda n: ["export", str(tmp / "export"), "--repo-id", "bench/corpus", "--root",
                                     str(tmp / f"ds{n}"), "-j", str(n), "--json"]}

        thread_counts = [int(t) for t in args.encoder_threads.split(",") if t.strip()] if "export" in commands else []
        with common.Load(args.busy):  # beside the timed commands only
            walls = best_walls(argv, commands, runs, tmp, figures)
            figures.update(encoder_thread_figures(argv["export"], thread_counts, runs, tmp, sessions))
        for command in commands:
            figures[f"corpus_speedup_2_workers_{command}"] = (
                walls[f"{command}_wall_s_workers1"] / walls[f"{command}_wall_s_workers2"]
            )
        figures["corpus_speedup_2_workers"] = min(figures[f"corpus_speedup_2_workers_{c}"] for c in commands)
        figures.update(walls)
        for command, seconds in (("eval", eval_s), ("export", export_s)):
            if command in commands:
                figures[f"{command}_recorded_s"] = sessions * seconds
        if not args.no_ray:
            figures.update(ray_overhead(sessions))
            if "eval" in commands and not args.quick:
                figures["eval_ray_wall_s"] = timed(["eval", str(tmp / "eval"), "--ray", "-j", "2"])
    figures["load_avg_1min_after"] = round(os.getloadavg()[0], 2)
    figures["busy_processes"] = args.busy
    figures = {k: round(v, 3) if isinstance(v, float) else v for k, v in figures.items()}
    targets = {"corpus_speedup_2_workers": ">= 1.7 (8 sessions, 2 workers vs 1)", "ray_overhead_s": "reported"}
    common.report("bench/corpus.py: a corpus of 8 sessions, 1 and 2 workers, and Ray", figures, targets, args.json)


if __name__ == "__main__":
    main()
