"""Session recorder figures: drops and writer CPU at the reference load, headroom, data lost to SIGKILL,
reader speed.

    python bench/recorder.py [--json] [--quick] [--seconds S] [--queue-size N]

Reference load (execute mode, every stream the session loop records): glove 120 Hz (45 values), suit
60 Hz (wrist pose and 66 body values), two 640x480 cameras at 30 fps as JPEG (32 distinct frames per
camera, encoded once with OpenCV and cycled: JPEG encoding is not the recorder's cost), arm state
100 Hz, hand state 90 Hz, and the pipeline outputs at glove rate (retargeted, corrected, arm target,
step report, arm and hand commands, /tf with the xArm6 + LEAP Hand links). One producer thread logs
the merged schedule on the session clock, as the session loop does; the recorder encodes, compresses
(zstd), writes and fsyncs on its own thread.

JSON keys:
    dropped                  int
    recorder_cpu_frac        float
    headroom_x               int
    recover_lost_s           float
    sync_err_ms_max          float
    sync_unmatched           int
    reference_msgs_per_s     float
    reference_mb_per_s       float
    reference_seconds        float
    messages_written         int
    jpeg_kb                  float
    log_call_us              float
    writer_alone_us_per_msg  float
    writer_alone_cpu_frac    float
    max_queue_depth          int
    queue_size               int
    headroom_queue_size      int
    headroom_step_s          float
    headroom_limited_by      str
    recover_trials           int
    recover_messages_min     int
    reader_msgs_per_s        float
    reader_realtime_x        float
    reader_all_msgs_per_s    float
    reader_all_realtime_x    float
    load_avg_start           float
    load_avg_end             float
"""

from __future__ import annotations

import argparse
import heapq
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402  (sets one-thread environment before numpy loads)

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
MIN_SLEEP_S = 0.001  # the producer logs what is due at most every 1 ms, as a loop draining device queues does
HEADROOM_MULTIPLES = (1, 2, 4, 6, 8, 10, 12, 14, 16, 20, 24, 28, 32, 40, 48, 64)


@dataclass
class Stream:
    topic: str
    rate_hz: float
    make: Callable[[int, int], object]  # (stamp_ns, k) -> payload


def _jpegs(seed: int, n: int) -> list[bytes]:
    """n 640x480 scene-like frames (gradients and blocks, fresh sensor noise per frame) as quality-90
    JPEGs (~50 KB). Encoded once here: JPEG encoding is the camera's cost, not the recorder's. Distinct
    frames, because zstd would squeeze a repeated frame to nothing and understate the writer's work."""
    import cv2

    rng = np.random.default_rng(seed)
    h, w = 480, 640
    y, x = np.mgrid[0:h, 0:w]
    scene = np.stack([x * 255.0 / w, y * 255.0 / h, (x + y) * 128.0 / (w + h)], axis=-1)
    for _ in range(12):
        x0, y0 = int(rng.integers(0, w - 100)), int(rng.integers(0, h - 100))
        x1, y1 = x0 + int(rng.integers(20, 150)), y0 + int(rng.integers(20, 150))
        cv2.rectangle(scene, (x0, y0), (x1, y1), rng.integers(0, 255, 3).tolist(), -1)
    frames = []
    for _ in range(n):
        img = np.clip(scene + rng.normal(0, 4, scene.shape), 0, 255).astype(np.uint8)
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 90])
        assert ok
        frames.append(buf.tobytes())
    return frames


def reference_streams(seed: int = 0) -> list[Stream]:
    from teleprev import topics as T
    from teleprev.human.smplx import BODY_JOINTS, HAND_POSE_NAMES
    from teleprev.messages import Event, ImageSample, JointSample, PoseSample, Transform, TransformsSample
    from teleprev.robot.model import load_robot

    rng = np.random.default_rng(seed)
    robot = load_robot("xarm6_leap_hand")
    arm_names, hand_names = robot.joint_names[:6], robot.joint_names[6:]
    body_names = tuple(f"{j}.{c}" for j in BODY_JOINTS for c in "xyz")
    pool = 64

    def joints(names, velocities: bool):
        pos = [rng.uniform(-1.5, 1.5, len(names)) for _ in range(pool)]
        vel = [rng.uniform(-2, 2, len(names)) for _ in range(pool)] if velocities else None
        names = tuple(names)
        return lambda stamp, k: JointSample(stamp, names, pos[k % pool], None if vel is None else vel[k % pool])

    def unit_quats(n):
        q = rng.normal(size=(n, 4))
        return q / np.linalg.norm(q, axis=1, keepdims=True)

    wrist_p, wrist_q = rng.uniform(-0.5, 0.5, (pool, 3)), unit_quats(pool)
    links = robot.link_names
    tf_pool = [
        tuple(Transform(links[0], child, rng.uniform(-0.6, 0.6, 3), q)
              for child, q in zip(links[1:], unit_quats(len(links) - 1)))
        for _ in range(8)
    ]
    images = {name: _jpegs(seed + i, 32) for i, name in enumerate(("front", "wrist"))}  # > 1 chunk's worth
    correctors = ("untouched", "untouched", "untouched", "ccn", "fallback")

    def report(stamp, k):
        return Event(stamp, "teleprev.StepReport", {
            "step": k, "mode": "execute", "corrector": correctors[k % len(correctors)],
            "colliding_links": ["thumb_tip", "index_tip"] if k % 5 == 3 else [], "deviation_rad": 0.01 * (k % 7),
            "ik_converged": True, "flags": [], "latency_us": 850.0 + k % 100,
        })

    glove_rate = 120.0
    streams = [
        Stream(T.device_topic("glove", "right", "hand"), glove_rate, joints(HAND_POSE_NAMES, False)),
        Stream(T.device_topic("suit", "body", "wrist"), 60.0,
               lambda stamp, k: PoseSample(stamp, "world", wrist_p[k % pool], wrist_q[k % pool])),
        Stream(T.device_topic("suit", "body", "body"), 60.0, joints(body_names, False)),
        Stream(T.device_topic("arm", "xarm", "state"), 100.0, joints(arm_names, True)),
        Stream(T.device_topic("hand", "leap", "state"), 90.0, joints(hand_names, True)),
        Stream(T.RETARGETED, glove_rate, joints(hand_names, False)),
        Stream(T.CORRECTED, glove_rate, joints(hand_names, False)),
        Stream(T.ARM_TARGET, glove_rate, joints(arm_names, False)),
        Stream(T.STEP_REPORT, glove_rate, report),
        Stream(T.COMMAND_ARM, glove_rate, joints(arm_names, False)),
        Stream(T.COMMAND_HAND, glove_rate, joints(hand_names, False)),
        Stream(T.TF, glove_rate, lambda stamp, k: TransformsSample(stamp, tf_pool[k % len(tf_pool)])),
    ]
    for name, frames in images.items():
        streams.append(Stream(T.device_topic("camera", name, "image"), 30.0,
                              lambda stamp, k, f=frames, name=name: ImageSample(stamp, name, f[k % len(f)], "jpeg")))
    return streams


@dataclass
class LoadResult:
    emitted: int
    target: int
    seconds: float
    log_ns: int  # time spent inside Recorder.log
    max_lag_ms: float  # how late the producer emitted a message at worst


def run_load(recorder, streams: list[Stream], clock, multiple: float, seconds: float, seed: int = 1) -> LoadResult:
    """Log every stream at `multiple` x its rate for `seconds`, on one producer thread."""
    from teleprev.messages import Logged

    rng = np.random.default_rng(seed)
    now = clock.now_ns
    t0 = now()
    end = t0 + int(seconds * 1e9)
    periods = [1e9 / (s.rate_hz * multiple) for s in streams]
    heap = [(t0 + rng.uniform(0, p), i) for i, p in enumerate(periods)]  # random phases
    heapq.heapify(heap)
    counters = [0] * len(streams)
    topics = [s.topic for s in streams]
    makers = [s.make for s in streams]
    log = recorder.log
    perf = time.perf_counter_ns
    emitted = log_ns = 0
    max_lag = 0.0
    while True:
        t = now()
        if t >= end:
            break
        while heap[0][0] <= t:
            due, i = heap[0]
            k = counters[i]
            counters[i] = k + 1
            msg = Logged(topics[i], t, makers[i](t - 200_000, k))  # acquired 0.2 ms before it arrived
            a = perf()
            log(msg)
            log_ns += perf() - a
            emitted += 1
            max_lag = max(max_lag, t - due)
            heapq.heapreplace(heap, (due + periods[i], i))
        wait = (heap[0][0] - now()) / 1e9
        if wait > 0:
            time.sleep(max(wait, MIN_SLEEP_S))
    target = int(sum(seconds * s.rate_hz * multiple for s in streams))
    return LoadResult(emitted, target, seconds, log_ns, max_lag / 1e6)


def record_reference(path: Path, streams, seconds: float, queue_size: int, multiple: float = 1.0):
    from teleprev.clock import SessionClock
    from teleprev.session.recorder import Recorder

    clock = SessionClock()
    rec = Recorder(path, {"session": {"operator": "bench", "task": "reference load"}}, queue_size=queue_size).start()
    load = run_load(rec, streams, clock, multiple, seconds)
    summary = rec.close()
    return load, summary


def child(path: str) -> None:
    """Recorder at the reference load until killed (for recover_lost_s)."""
    from teleprev.clock import SessionClock
    from teleprev.session.recorder import Recorder

    streams = reference_streams()
    clock = SessionClock()
    rec = Recorder(path, {"session": {"operator": "bench", "task": "sigkill"}}).start()
    print("ready", flush=True)
    run_load(rec, streams, clock, 1.0, 3600.0)


def kill_and_recover(tmp: Path, trial: int, seconds: float) -> tuple[float, int]:
    """Seconds of log time lost between the last recovered message and a SIGKILL, and messages saved."""
    from teleprev.session.reader import SessionReader
    from teleprev.session.recover import recover

    path = tmp / f"killed{trial}.mcap"
    proc = subprocess.Popen([sys.executable, __file__, "--child", str(path)], stdout=subprocess.PIPE, text=True,
                            cwd=ROOT)
    try:
        line = proc.stdout.readline()
        if line.strip() != "ready":
            raise RuntimeError(f"child recorder did not start: {line!r}")
        time.sleep(seconds)
        kill_ns = time.time_ns()
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    result = recover(path)
    with SessionReader(result.dst) as reader:  # the recovered file must open
        n = sum(t.message_count for t in reader.topics.values())
    return (kill_ns - result.end_ns) / 1e9, n


def writer_cost(streams, tmp: Path, seconds: float = 5.0, repeat: int = 3) -> float:
    """CPU seconds per message of McapSessionWriter alone (encode, chunk, zstd, write; no threads,
    no queue) over `seconds` of the reference load, flushed every 0.5 s: the writer's own cost, apart
    from what the machine's other work does to the recorder thread."""
    from teleprev.messages import Logged
    from teleprev.session.writer import McapSessionWriter

    t0 = 1_700_000_000_000_000_000
    msgs = sorted((Logged(s.topic, t0 + int(k * 1e9 / s.rate_hz), s.make(t0 + int(k * 1e9 / s.rate_hz), k))
                   for s in streams for k in range(int(s.rate_hz * seconds))), key=lambda m: m.log_time_ns)
    best = float("inf")
    for i in range(repeat):
        path = tmp / f"writer{i}.mcap"
        cpu = time.process_time()
        with McapSessionWriter(path, {}) as w:
            next_flush = t0 + 500_000_000
            for m in msgs:
                w.write(m)
                if m.log_time_ns >= next_flush:
                    w.flush()
                    next_flush += 500_000_000
        best = min(best, time.process_time() - cpu)
        path.unlink()
    return best / len(msgs)


def reader_speed(path: Path, repeat: int) -> dict:
    """Messages per CPU second reading the file back (best of `repeat`; CPU time, since these machines
    are shared), for the joint, pose and event streams and for everything."""
    from teleprev.session.reader import SessionReader

    with SessionReader(path) as reader:
        duration = reader.duration_s
        topics = list(reader.topics)
        jpe = [t for t in topics if not t.startswith("/camera/") and t != "/tf"]
        out = {}
        for label, sel in (("jpe", jpe), ("all", topics)):
            best = float("inf")
            for _ in range(repeat):
                t = time.process_time()
                n = sum(1 for _ in reader.messages(sel))
                best = min(best, time.process_time() - t)
            out[label] = (n, best, duration)
    return out


def sync_error(tmp: Path, seconds: float) -> dict:
    """Record the simulated rig through the real session path (devices -> runners -> loop -> recorder)
    and compare every recorded acquisition stamp with the time the sim device truly acquired it.

    The sim devices stamp samples with their own clocks (offset, drift) and deliver them after a
    transport delay; they convert back to the session clock with ClockSync, as real devices do."""
    import time as _time

    from teleprev.live.record.session import LiveSession, RecordOptions
    from teleprev.rig import default_rig_path
    from teleprev.session.reader import SessionReader
    from teleprev.topics import parse_device_topic

    path = tmp / "sync.mcap"
    rec = LiveSession(RecordOptions(out=path, rig=default_rig_path().parent / "sim_gripper.toml"))
    rec.start()
    rec.loop.start_episode("pick_place")
    _time.sleep(seconds)
    rec.stop()
    truth = rec.context.shared["sim.truth"]
    worst: dict[str, float] = {}
    missing = 0
    with SessionReader(path) as reader:
        for msg in reader.messages():
            if parse_device_topic(msg.topic) is None:
                continue
            true_ns = truth.true_ns(msg.topic, msg.payload.stamp_ns)
            if true_ns is None:
                missing += 1
                continue
            worst[msg.topic] = max(worst.get(msg.topic, 0.0), abs(msg.payload.stamp_ns - true_ns) / 1e6)
    return {"sync_err_ms_max": max(worst.values()), "sync_err_ms_by_stream": worst, "sync_unmatched": missing}


def main() -> None:
    p = common.parser(__doc__)
    p.add_argument("--seconds", type=float, default=None, help="reference run length (default 60, --quick 3)")
    p.add_argument("--queue-size", type=int, default=None, help="recorder queue size (default: the Recorder's)")
    p.add_argument("--child", help=argparse.SUPPRESS)  # internal: the recorder that recover_lost_s kills
    args = p.parse_args()
    if args.child:
        child(args.child)
        return

    from teleprev.session.recorder import DEFAULT_QUEUE_SIZE

    load_start = os.getloadavg()[0]
    queue_size = args.queue_size or DEFAULT_QUEUE_SIZE
    seconds = args.seconds or (3.0 if args.quick else 60.0)
    multiples = HEADROOM_MULTIPLES[:2] if args.quick else HEADROOM_MULTIPLES
    streams = reference_streams()
    ref_rate = sum(s.rate_hz for s in streams)
    jpeg_sizes = [len(s.make(0, 0).data) for s in streams if s.topic.startswith("/camera/")]

    with tempfile.TemporaryDirectory(prefix="teleprev-bench-") as tmpdir:
        tmp = Path(tmpdir)
        ref_path = tmp / "reference.mcap"
        load, summary = record_reference(ref_path, streams, seconds, queue_size)
        speed = reader_speed(ref_path, 1 if args.quick else 5)
        writer_s_per_msg = writer_cost(streams, tmp, 1.0 if args.quick else 5.0)
        file_mb = summary.file_bytes / 1e6

        steps = []
        step_s = 1.0 if args.quick else 4.0
        headroom, limited = 0, ""
        for m in multiples:
            # A second try where the first dropped: on a shared machine another process can take the
            # CPU for longer than the queue lasts, which is not the writer's limit.
            for attempt in (1, 2):
                path = tmp / f"x{m}.mcap"
                step_load, step = record_reference(path, streams, step_s, queue_size, multiple=m)
                path.unlink()
                reached = step_load.emitted / step_load.target
                steps.append((m, attempt, step.dropped, step.writer_cpu_s / step.wall_s, step.max_queue_depth, reached))
                if not step.dropped:
                    break
            if step.dropped:
                limited = f"drops at {m}x"
                break
            if reached < 0.95:
                limited = f"the load generator (it reached {reached:.0%} of {m}x)"
                break
            headroom = m
        else:
            limited = f"the largest multiple tried ({multiples[-1]}x)"

        trials = 1 if args.quick else 3
        kills = [kill_and_recover(tmp, i, 2.0 if args.quick else 4.0) for i in range(trials)]
        sync = sync_error(tmp, 2.0 if args.quick else 20.0)

    from rich.console import Console
    from rich.table import Table

    console = Console(stderr=args.json)
    t = Table(title=f"headroom steps ({step_s:g} s each, queue_size {queue_size})", title_justify="left")
    for col in ("multiple", "try", "msgs/s", "dropped", "writer CPU", "max queue depth", "generator reached"):
        t.add_column(col, justify="right")
    for m, attempt, dropped, cpu, depth, reached in steps:
        t.add_row(f"{m}x", str(attempt), f"{m * ref_rate:.0f}", str(dropped), f"{cpu:.0%}", str(depth),
                  f"{reached:.0%}")
    console.print(t)
    console.print(f"headroom limited by {limited}")

    n_jpe, s_jpe, dur = speed["jpe"]
    n_all, s_all, _ = speed["all"]
    figures = {
        "dropped": summary.dropped,
        "recorder_cpu_frac": summary.writer_cpu_s / summary.wall_s,
        "headroom_x": headroom,
        "recover_lost_s": max(k[0] for k in kills),
        "sync_err_ms_max": sync["sync_err_ms_max"],
        **{f"sync_err_ms[{topic}]": v for topic, v in sync["sync_err_ms_by_stream"].items()},
        "sync_unmatched": sync["sync_unmatched"],
        "reference_msgs_per_s": load.emitted / load.seconds,
        "reference_mb_per_s": file_mb / seconds,
        "reference_seconds": seconds,
        "messages_written": summary.written,
        "jpeg_kb": float(np.mean(jpeg_sizes)) / 1e3,
        "log_call_us": load.log_ns / max(load.emitted, 1) / 1e3,
        "writer_alone_us_per_msg": writer_s_per_msg * 1e6,
        "writer_alone_cpu_frac": writer_s_per_msg * ref_rate,  # of one core, at the reference load
        "max_queue_depth": summary.max_queue_depth,
        "queue_size": queue_size,
        "headroom_queue_size": queue_size,
        "headroom_step_s": step_s,
        "headroom_limited_by": limited,
        "recover_trials": trials,
        "recover_messages_min": min(k[1] for k in kills),
        "reader_msgs_per_s": n_jpe / s_jpe,
        "reader_realtime_x": dur / s_jpe,
        "reader_all_msgs_per_s": n_all / s_all,
        "reader_all_realtime_x": dur / s_all,
        # 1-minute load average before and after: these machines are shared, and every figure above
        # that is a rate or a CPU share moves with what else runs.
        "load_avg_start": load_start,
        "load_avg_end": os.getloadavg()[0],
    }
    targets = {
        "dropped": "== 0",
        "recorder_cpu_frac": "reported (writer thread / one core)",
        "headroom_x": ">= 10",
        "recover_lost_s": "<= 1",
        "sync_err_ms_max": "<= 1 (sim rig through the whole recording path)",
        "reader_realtime_x": ">= 100 (joint, pose and event streams)",
    }
    common.report("bench/recorder.py: session recorder at the reference load", figures, targets, args.json)


if __name__ == "__main__":
    main()
