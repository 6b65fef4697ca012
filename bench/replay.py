"""Evaluation figures: how fast `teleprev eval` re-runs a recording, and whether it reproduces it.

    python bench/replay.py [--json] [--quick] [--rig RIG] [--busy N]

Records a session of the default sim rig (LEAP Hand, shipped models; two episodes, engaged after 2 s)
through the real recording path, then re-runs it as `teleprev eval` does: raw input streams and mode
switches through the pipeline, camera frames never decoded. eval_realtime_x = recorded seconds per
second of wall time (building the pipeline, file reading, the pipeline, the metrics, one process);
eval_cpu_realtime_x the same per second of the process's CPU time, which on a shared machine is the fairer
one-core figure; eval_warm_realtime_x the median of three more evals of the same file in the same process,
whose pipeline is built already, as for the sessions of a corpus after the first of a rig;
eval_process_realtime_x the same session through `teleprev eval` in a fresh process, as a user runs it:
the interpreter's start, the imports, numba's own start and loading the kernels from its cache included
(the figures above run where a recording has done all that already).
bit_identical is this fresh session's and every older format's fixture's (tests/fixtures/sim_v1..v3.mcap,
each re-run with its own format's arithmetic): bit_identical_format<N> each, bit_identical all of them.

JSON keys:
    eval_realtime_x          float
    bit_identical            bool
    recorded_s               float
    eval_wall_s              float
    eval_warm_realtime_x     float
    eval_process_realtime_x  float
    eval_cpu_realtime_x      float
    steps                    int
    step_ms_p50              float
    rerun_only_realtime_x    float
    collision_after_frac     float
    corrected_frac           float
    busy_processes           int
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402


def main() -> None:
    p = common.parser(__doc__)
    p.add_argument("--rig", default=None, help="rig file to record with (default: the all-sim LEAP rig)")
    p.add_argument("--busy", type=int, default=0, help="busy processes beside the evals (not the recording)")
    args = p.parse_args()
    seconds = 6.0 if args.quick else 30.0

    from teleprev.evaluation.evaluate import evaluate
    from teleprev.live.record.session import LiveSession, RecordOptions

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.mcap"
        rec = LiveSession(RecordOptions(out=path, rig=args.rig))
        rec.start()
        try:
            for _ in range(2):
                rec.loop.start_episode("pick_place")
                time.sleep(2.0)
                rec.loop.engage("bench")
                time.sleep(seconds / 2 - 2.0)
                rec.loop.to_preview("bench")
                rec.loop.stop_episode()
        finally:
            rec.stop()
        load = common.Load(args.busy).__enter__()  # left at the end of the fixtures' evals below
        t0, c0 = time.perf_counter(), time.process_time()
        result = evaluate([path])
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        # The same session again in this process: its pipeline is built (0.05-0.3 s), as for every session
        # of a corpus after the first of its rig; what remains is the per-session cost.
        warm = []
        for _ in range(3):
            t1 = time.perf_counter()
            again = evaluate([path])
            warm.append(time.perf_counter() - t1)
        assert again.report["sessions"][0]["bit_identical"] == result.report["sessions"][0]["bit_identical"]
        cli, cli_report = Path(sys.executable).with_name("teleprev"), Path(tmp) / "cli.json"
        if not cli.exists():
            sys.exit(f"bench/replay.py: no {cli}: run it with the project's environment (.venv/bin/python)")
        t2 = time.perf_counter()
        subprocess.run([str(cli), "eval", str(path), "--out", str(cli_report)], check=True, capture_output=True)
        process_wall = time.perf_counter() - t2
        assert json.loads(cli_report.read_text())["sessions"][0]["bit_identical"]
    o = result.report["overall"]
    from teleprev.topics import FORMAT_VERSION

    formats = {f"bit_identical_format{FORMAT_VERSION}": bool(result.report["sessions"][0]["bit_identical"])}
    for fixture in sorted((Path(__file__).resolve().parents[1] / "tests" / "fixtures").glob("sim_v*.mcap")):
        formats[f"bit_identical_format{fixture.stem[5:]}"] = bool(
            evaluate([fixture]).report["sessions"][0]["bit_identical"]
        )
    load.__exit__(None, None, None)
    figures = {
        "eval_realtime_x": o["duration_s"] / wall,
        "bit_identical": all(formats.values()),
        **dict(sorted(formats.items())),
        "recorded_s": o["duration_s"],
        "eval_wall_s": wall,
        "eval_warm_realtime_x": o["duration_s"] / common.percentile(warm, 50),  # pipeline already built
        "eval_process_realtime_x": o["duration_s"] / process_wall,  # `teleprev eval` in a fresh process
        "eval_cpu_realtime_x": o["duration_s"] / cpu,  # per second of this process's CPU time: the one-core
        # figure when other processes share the core (wall time then counts their turns too)
        "steps": o["steps"],
        "step_ms_p50": o["latency_ms_p50"],
        "rerun_only_realtime_x": o["realtime_x"],
        "collision_after_frac": o.get("collision_after_frac", 0.0),
        "corrected_frac": (o.get("ccn", 0) + o.get("fallback", 0)) / max(o["steps"], 1),
        "busy_processes": args.busy,
    }
    targets = {"eval_realtime_x": ">= 100 (cold, one process, video not decoded)", "eval_cpu_realtime_x": ">= 150",
               "bit_identical": "true, every session format"}
    common.report(
        f"bench/replay.py: re-running a recorded session, {args.busy} busy processes beside it",
        figures,
        targets,
        args.json,
    )


if __name__ == "__main__":
    main()
