"""The command path on a busy machine: unattended `teleprev record` sessions while 8 busy processes load
this 2-core machine (4 per core), the preview rendering into a pseudo-terminal at 80x24 and 120x45 and the
sim camera at 30 fps; every session then measured as a controller would see it.

Sessions (10; --quick: 3 of 4 s, the sim rig at 80x24, the fault and the wrist twist, beside 1 busy process,
and the mechanisms for 1 s each):
    default sim rig (the simulated operator at its tasks), preview in a pty, 80x24 and 120x45 in turn
    a human-like VMC glove and suit over UDP (tests/helpers/vmc.py: HumanLikeSender), preview at 80x24
    the sim rig with a controller fault mid-episode (sim.arm fault_after_s), two episodes
    a VMC operator turning the wrist into the last joint's limit (WristTwister), headless

Figures (issue 23):
    loaded_sessions                  sessions recorded under the load
    arm_faults                       controller faults the sim arm raised (the injected one not counted)
    audit_failures                   sessions `teleprev audit` fails
    command_gap_ms_max               the longest interval between two commands of one engaged run (stamps)
    command_late_ms_p99              how late the sender's ticks woke, p99 over every tick
    reengaged_after_fault            unattended engages after the injected fault
    limit_approach_accel_ratio_max   the wrist-twist session's arm acceleration / limit (audit's)
    export_action_audit_ratio_max    our own export of two sessions, `teleprev audit DATASET`: worst ratio
    eval_audit_jerk_agree            eval's arm jerk max equals audit's on every session
    resume_jumps                     runs after a pause whose first commands do not start from rest
    hand_tracking_r_min              /command/hand against /pipeline/retargeted: the worst joint's correlation
    hand_lag_ms_p50                  and the median lag, per joint of every session (execute only)
and the mechanism measured under the same load (why the sender is a SCHED_FIFO process), thread vs
process, with and without real-time priority: mechanism_<kind>_late_ms_p99 / _max, _gaps_over_25ms.

--rig physics: the same check on the physics rig (rigs/sim_physics.toml, issue 39), the world stepping in
a process of its own; sessions of two episodes each, preview in a pty at 80x24, beside the busy processes
(default 8, --quick 1; --sessions, default 4, --quick 1). bench/physics.py reports these figures too:
    realtime_physics_sessions      sessions recorded under the load
    realtime_physics_arm_faults    controller faults the sim arm raised
    realtime_physics_gap_ms_max    the longest interval between two commands of one engaged run (stamps)
    realtime_physics_late_ms_p99   how late the sender's ticks woke, p99 over every tick
    realtime_physics_audit_failures  sessions `teleprev audit` fails

JSON keys:
    loaded_sessions                        int
    arm_faults                             int
    audit_failures                         int
    command_gap_ms_max                     float
    command_late_ms_p99                    float
    command_late_ms_max                    float
    reengaged_after_fault                  int
    limit_approach_accel_ratio_max         float
    export_action_audit_ratio_max          float
    eval_audit_jerk_agree                  bool
    bit_identical                          bool
    resume_jumps                           int
    hand_tracking_r_min                    float
    hand_lag_ms_p50                        float
    sender_realtime                        bool
    busy_processes                         int
    mechanism_thread_late_ms_p99           float
    mechanism_thread_late_ms_max           float
    mechanism_thread_gaps_over_25ms        int
    mechanism_thread_fifo_late_ms_p99      float
    mechanism_thread_fifo_late_ms_max      float
    mechanism_thread_fifo_gaps_over_25ms   int
    mechanism_process_late_ms_p99          float
    mechanism_process_late_ms_max          float
    mechanism_process_gaps_over_25ms       int
    mechanism_process_fifo_late_ms_p99     float
    mechanism_process_fifo_late_ms_max     float
    mechanism_process_fifo_gaps_over_25ms  int
"""

from __future__ import annotations

import fcntl
import multiprocessing as mp
import os
import pty
import re
import select
import struct
import subprocess
import sys
import tempfile
import termios
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# this checkout first, then what the caller had on the path (its device plugins, say)
PYTHONPATH = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import common  # noqa: E402  (sets one-thread environment before numpy loads)

import numpy as np  # noqa: E402

CLI = [sys.executable, "-m", "teleprev.cli.app"]
TARGETS = {"loaded_sessions": ">= 10", "arm_faults": "0", "audit_failures": "0", "command_gap_ms_max": "<= 25",
           "command_late_ms_p99": "reported", "reengaged_after_fault": "0", "limit_approach_accel_ratio_max": "<= 1.05",
           "export_action_audit_ratio_max": "<= 1.05", "eval_audit_jerk_agree": "true", "resume_jumps": "0",
           "hand_tracking_r_min": "reported", "hand_lag_ms_p50": "reported"}


# ---- sessions ------------------------------------------------------------------------------------------
def _drain(fd: int, stop: threading.Event, tail: bytearray) -> None:
    """Read the preview's pty until stopped, keeping the last 8 KiB in `tail` (why a session failed)."""
    while not stop.is_set():
        if select.select([fd], [], [], 0.2)[0]:
            try:
                chunk = os.read(fd, 65536)
            except OSError:
                return
            if not chunk:
                return
            tail += chunk
            del tail[:-8192]


def record(rig: Path, out: Path, seconds: float, episodes: int, engage_after: float, size=None) -> int:
    """`teleprev record` unattended; with `size` (columns, rows) its preview renders into a pty that big."""
    cmd = [*CLI, "record", str(rig), "--out", str(out), "--duration", str(seconds), "--episodes", str(episodes),
           "--engage-after", str(engage_after)]
    env = {**os.environ, "PYTHONPATH": PYTHONPATH}
    if size is None:
        done = subprocess.run([*cmd, "--no-preview"], capture_output=True, text=True, env=env, timeout=seconds + 120)
        if done.returncode != 0 and done.stderr.strip():  # (the fault session exits 1, saying nothing)
            print(
                f"{out.name}: teleprev record exited {done.returncode}: {done.stderr.strip()[-2000:]}", file=sys.stderr
            )
        return done.returncode
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", size[1], size[0], 0, 0))
    stop, tail = threading.Event(), bytearray()
    reader = threading.Thread(target=_drain, args=(master, stop, tail), daemon=True)
    reader.start()
    try:
        proc = subprocess.Popen(cmd, stdin=slave, stdout=slave, stderr=slave, env={**env, "TERM": "xterm-256color"},
                                start_new_session=True)
        code = proc.wait(timeout=seconds + 120)
    finally:
        stop.set()
        os.close(slave)
        reader.join(2)
        os.close(master)
    if code != 0:  # the lines after the preview closed, without the terminal's escape sequences
        said = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]|\x1b[()][A-Z0-9]|\r", "", tail.decode(errors="replace"))
        print(f"{out.name}: teleprev record exited {code}: {' '.join(said.split()[-60:])}", file=sys.stderr)
    return code


class ExternalDevice:
    """A VMC sender in a process of its own with real-time priority (where permitted): a glove and suit
    are devices outside this machine, whose frames the load here does not hold up."""

    def __init__(self, sender, rate_hz: float = 60.0):
        self.sender, self.rate_hz = sender, rate_hz
        self.proc = mp.get_context("fork").Process(target=self._run, daemon=True)

    def _run(self) -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(40))
        except (PermissionError, OSError):
            pass
        self.sender.start(self.rate_hz)
        self.sender.join(1e9)

    def __enter__(self):
        self.proc.start()
        return self

    def __exit__(self, *exc):
        self.proc.terminate()
        self.proc.join()


def vmc_rig(folder: Path, port: int) -> Path:
    text = (ROOT / "rigs" / "sim.toml").read_text()
    head, _, rest = text.partition("[devices.glove]")
    devices = rest[rest.index("[devices.cam_front]"):]
    rig = folder / f"vmc_{port}.toml"
    rig.write_text(head + f'[devices.glove]\nplugin = "vmc.glove"\nport = {port}\n\n'
                   f'[devices.suit]\nplugin = "vmc.suit"\nport = {port}\n\n' + devices)
    return rig


def fault_rig(folder: Path, after_s: float) -> Path:
    rig = folder / "fault.toml"
    rig.write_text((ROOT / "rigs" / "sim.toml").read_text().replace(
        'plugin = "sim.arm"', f'plugin = "sim.arm"\nfault_after_s = {after_s}'))
    return rig


# ---- measuring a session -------------------------------------------------------------------------------
def _joint_stream(reader, topic: str):
    from teleprev.messages import JointSample

    rows = [m.payload for m in reader.messages([topic]) if isinstance(m.payload, JointSample)]
    return np.array([p.stamp_ns for p in rows], dtype=np.int64), np.array([p.positions for p in rows])


def resume_jumps(t, q, history, accel_limit: float, jerk_limit: float | None) -> int:
    """Runs after a pause whose first commands, measured from where the controller starts them, break
    the acceleration (or jerk) limit by more than the controller's 10%."""
    from teleprev.pipeline.derivatives import runs, stream_peaks

    bad = 0
    pieces = runs(t)
    for k, run in enumerate(pieces[1:], start=1):
        head = slice(run.start, min(run.stop, run.start + 4))
        before = q[pieces[k - 1].stop - 1]
        rest = history.rests(k, int(t[run.start]), before, int(t[pieces[k - 1].stop - 1])) if history else None
        start = before if rest is None else rest
        peaks = stream_peaks(t[head], q[head], rests=lambda *_: start)
        if peaks.acceleration.max() > 1.1 * accel_limit or (jerk_limit and peaks.jerk.max() > 1.1 * jerk_limit):
            bad += 1
    return bad


def hand_tracking(reader) -> tuple[list[float], list[float]]:
    """Per hand joint that moved: the correlation of /command/hand with /pipeline/retargeted while
    commanded (both on one 240 Hz grid), at the lag that best aligns them, and that lag in ms."""
    from teleprev import topics

    tc, qc = _joint_stream(reader, topics.COMMAND_HAND)
    tr, qr = _joint_stream(reader, topics.RETARGETED)
    if len(tc) < 100 or len(tr) < 100:
        return [], []
    grid = np.arange(tc[0], tc[-1], 4_166_667)
    gaps = np.interp(grid, tc[1:], np.diff(tc)) < 60_000_000  # inside runs of commands
    rs, lags = [], []
    for j in range(qc.shape[1]):
        c = np.interp(grid, tc, qc[:, j])
        r = np.interp(grid, tr, qr[:, j])
        if np.std(r[gaps]) < 0.05:
            continue
        best = (-2.0, 0)
        for shift in range(0, 73):  # up to 300 ms of lag, the command behind the target
            a, b = c[shift:], r[: len(r) - shift]
            m = gaps[shift:] & gaps[: len(gaps) - shift]
            if m.sum() < 50:
                continue
            rho = float(np.corrcoef(a[m], b[m])[0, 1])
            if rho > best[0]:
                best = (rho, shift)
        rs.append(best[0])
        lags.append(best[1] * 4.166667)
    return rs, lags


def measure(path: Path, kind: str, fault: bool) -> dict:
    from teleprev import topics
    from teleprev.evaluation.audit import actuator_history, audit_session
    from teleprev.evaluation.evaluate import evaluate
    from teleprev.session.reader import SessionReader
    from teleprev.session.summary import summarize

    s = summarize(path)
    audit = audit_session(path)
    arm_audit = audit.streams[0]
    ev = evaluate([path]).report["overall"]
    with SessionReader(path) as reader:
        faults = [e for e in s.device_events if e.device == "arm" and e.event == "error"]
        injected = [e for e in faults if "injected" in e.message]
        first_fault = min((e.log_time_ns for e in faults), default=None)
        modes = [(m.log_time_ns, m.payload.data) for m in reader.messages([topics.MODE])]
        reengaged = sum(1 for t, d in modes if first_fault is not None and t > first_fault
                        and d.get("mode") == "execute" and d.get("reason") == "script")
        t, q = _joint_stream(reader, topics.COMMAND_ARM)
        names = tuple(next(iter(reader.messages([topics.COMMAND_ARM]))).payload.names) if len(t) else ()
        history = actuator_history(reader, "arm", names) if len(t) else None
        jumps = resume_jumps(t, q, history, arm_audit.accel_limit, arm_audit.jerk_limit) if len(t) > 4 else 0
        rs, lags = hand_tracking(reader)
    return {
        "kind": kind, "ok": s.sender is not None and len(t) > 100,
        "arm_faults": len(faults) - len(injected), "audit_ok": audit.ok,
        "accel_ratio": arm_audit.ratios.get("accel", 0.0), "jerk_ratio": arm_audit.ratios.get("jerk", 0.0),
        "gap_ms": s.sender.gap_ms_max if s.sender else float("nan"),
        "late_ms_p99": s.sender.late_ms_p99 if s.sender else float("nan"),
        "late_ms": s.sender.late_ms_max if s.sender else float("nan"),
        "realtime": s.sender.realtime if s.sender else None,
        "reengaged": reengaged if fault else 0,
        "jerk_agree": abs(ev["arm_jerk_max"] - arm_audit.jerk_max) <= 1e-9 * max(1.0, arm_audit.jerk_max),
        "bit_identical": bool(ev.get("reproduced")), "resume_jumps": jumps, "hand_r": rs, "hand_lag_ms": lags,
    }


def export_audit(sessions: list[Path], folder: Path) -> float:
    from teleprev.evaluation.audit import audit_dataset

    root = folder / "dataset"
    done = subprocess.run([*CLI, "export", *map(str, sessions), "--repo-id", "bench/realtime", "--root", str(root)],
                          capture_output=True, text=True, timeout=900,
                          env={**os.environ, "PYTHONPATH": PYTHONPATH, "HF_HUB_OFFLINE": "1"})
    if done.returncode != 0:
        print(done.stdout[-2000:], done.stderr[-2000:], file=sys.stderr)
        return float("nan")
    report = audit_dataset(root, ROOT / "rigs" / "sim.toml")
    return max(v for st in report.streams for v in st.ratios.values())


# ---- the physics rig -------------------------------------------------------------------------------------
PHYSICS_RIG = ROOT / "rigs" / "sim_physics.toml"
PHYSICS_TARGETS = {"realtime_physics_arm_faults": "0", "realtime_physics_gap_ms_max": "<= 25",
                   "realtime_physics_audit_failures": "0"}


def physics_figures(sessions: int, seconds: float, busy: int, folder: Path) -> dict:
    """The loaded real-time check on the physics rig: `sessions` unattended recordings of two episodes each,
    preview in a pty at 80x24, beside `busy` busy processes, each measured as the sim rig's are."""
    results = []
    with common.Load(busy):
        for k in range(sessions):
            out = folder / f"physics_{k:02d}.mcap"
            code = record(PHYSICS_RIG, out, seconds, 2, 1.0, (80, 24))
            m = measure(out, "physics", False)
            m["returncode"] = code
            results.append(m)
            print(f"{out.name}: rc {code}, faults {m['arm_faults']}, audit {'ok' if m['audit_ok'] else 'FAILED'}, "
                  f"gap {m['gap_ms']:.1f} ms, late p99 {m['late_ms_p99']:.2f} ms", file=sys.stderr, flush=True)
    return {
        "realtime_physics_sessions": sum(m["ok"] for m in results),
        "realtime_physics_arm_faults": sum(m["arm_faults"] for m in results),
        "realtime_physics_gap_ms_max": max(m["gap_ms"] for m in results),
        "realtime_physics_late_ms_p99": max(m["late_ms_p99"] for m in results),
        "realtime_physics_audit_failures": sum(not m["audit_ok"] for m in results),
    }


# ---- the mechanism -------------------------------------------------------------------------------------
PERIOD = 1 / 120


def _tick_work():
    a = np.arange(16.0)
    for _ in range(20):
        a = a * 1.0001 + 0.1
    return a


def _pacer(duration: float, fifo: bool, out) -> None:
    if fifo:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))
        except (PermissionError, OSError):
            pass
    t0, n, late, sends = time.monotonic(), 0, [], []
    while True:
        due = t0 + n * PERIOD
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        now = time.monotonic()
        if now - t0 > duration:
            break
        late.append(now - due)
        _tick_work()
        sends.append(now)
        n = int((now - t0) / PERIOD) + 1
    out.put((late, sends)) if hasattr(out, "put") else out.append((late, sends))


def _session_like(stop: threading.Event) -> None:
    """What a session process runs beside a sender thread: a loop thread, a preview and a camera."""

    def loop():
        x = np.random.rand(64)
        while not stop.is_set():
            t = time.perf_counter()
            while time.perf_counter() - t < 0.0004:
                x = np.sin(x) + 0.1
            time.sleep(0.002)

    def preview():
        while not stop.is_set():
            t, s = time.perf_counter(), []
            while time.perf_counter() - t < 0.015:
                s.append(str(len(s)) * 3)
            time.sleep(0.025)

    def camera():
        img = np.random.randint(0, 255, (480, 640, 3), np.uint8)
        while not stop.is_set():
            t = time.perf_counter()
            _ = (img.astype(np.float32) * 0.5).astype(np.uint8)
            time.sleep(max(0.0, 1 / 30 - (time.perf_counter() - t)))

    for f in (loop, preview, camera):
        threading.Thread(target=f, daemon=True).start()


def mechanisms(seconds: float) -> dict:
    stop = threading.Event()
    _session_like(stop)
    out = {}
    ctx = mp.get_context("fork")
    for name, fifo, process in (("thread", False, False), ("thread_fifo", True, False), ("process", False, True),
                                ("process_fifo", True, True)):
        if process:
            q = ctx.Queue()
            p = ctx.Process(target=_pacer, args=(seconds, fifo, q))
            p.start()
            late, sends = q.get()
            p.join()
        else:
            got: list = []
            th = threading.Thread(target=_pacer, args=(seconds, fifo, got))
            th.start()
            th.join()
            late, sends = got[0]
        late_ms, gaps = np.array(late) * 1e3, np.diff(np.array(sends)) * 1e3
        out[f"mechanism_{name}_late_ms_p99"] = float(np.percentile(late_ms, 99))
        out[f"mechanism_{name}_late_ms_max"] = float(late_ms.max())
        out[f"mechanism_{name}_gaps_over_25ms"] = int((gaps > 25).sum())
    stop.set()
    return out


# ---- main ----------------------------------------------------------------------------------------------
def main() -> None:
    p = common.parser(__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=20.0, help="each session's length")
    p.add_argument("--busy", type=int, default=None, help="busy processes beside the sessions (default 8, --quick 1)")
    p.add_argument("--keep", type=Path, default=None, help="keep the sessions in this folder")
    p.add_argument("--rig", choices=("sim", "physics"), default="sim",
                   help="physics: the check on the physics rig alone (realtime_physics_* figures)")
    p.add_argument("--sessions", type=int, default=None, help="with --rig physics: sessions (default 4, --quick 1)")
    args = p.parse_args()
    from tests.helpers.ports import free_port
    from tests.helpers.vmc import HumanLikeSender, WristTwister

    seconds = 4.0 if args.quick else args.seconds
    if args.busy is None:
        args.busy = 1 if args.quick else 8
    folder = args.keep or Path(tempfile.mkdtemp(prefix="realtime-"))
    folder.mkdir(parents=True, exist_ok=True)
    if args.rig == "physics":
        sessions = args.sessions or (1 if args.quick else 4)
        common.report(f"bench/realtime.py --rig physics: {sessions} sessions of {seconds:g} s beside {args.busy} busy "
                      "processes", physics_figures(sessions, seconds, args.busy, folder), PHYSICS_TARGETS, args.json)
        return
    sim = ROOT / "rigs" / "sim.toml"
    plan = [("sim", sim, (80, 24)), ("sim", sim, (120, 45))] * (1 if args.quick else 3)
    plan = plan[:1] if args.quick else plan
    plan += [("vmc_human", None, (80, 24))] * (0 if args.quick else 2)
    plan += [("fault", fault_rig(folder, 0.4 * seconds), None)]
    plan += [("limit", None, None)]
    results, recorded = [], []
    with common.Load(args.busy):
        for k, (kind, rig, size) in enumerate(plan):
            out = folder / f"{k:02d}_{kind}.mcap"
            device = None
            if kind in ("vmc_human", "limit"):
                port = free_port()
                rig = vmc_rig(folder, port)
                device = ExternalDevice(HumanLikeSender(port, seed=k) if kind == "vmc_human" else WristTwister(port))
                device.__enter__()
            stolen = common.steal_ms()
            try:
                code = record(rig, out, seconds, 2, 1.5 if kind == "limit" or args.quick else 3.0, size)
            finally:
                if device is not None:
                    device.__exit__()
            after = common.steal_ms()
            m = measure(out, kind, kind == "fault")
            m["returncode"] = code
            m["steal_ms"] = None if stolen is None or after is None else after - stolen
            results.append(m)
            recorded.append(out)
            print(f"{out.name}: rc {code}, faults {m['arm_faults']}, audit {'ok' if m['audit_ok'] else 'FAILED'}, "
                  f"gap {m['gap_ms']:.1f} ms, late p99 {m['late_ms_p99']:.2f} ms, accel x{m['accel_ratio']:.3f}, "
                  f"jerk x{m['jerk_ratio']:.3f}, reproduces {m['bit_identical']}, host steal {m['steal_ms']} ms",
                  file=sys.stderr, flush=True)
        mech = mechanisms(1.0 if args.quick else 10.0)
    export_ratio = export_audit([r for r, m in zip(recorded, results) if m["kind"] == "sim"][:2], folder)
    rs = [r for m in results for r in m["hand_r"]]
    lags = [lag for m in results for lag in m["hand_lag_ms"]]
    limit = [m["accel_ratio"] for m in results if m["kind"] == "limit"]
    figures = {
        "loaded_sessions": sum(m["ok"] for m in results),
        "arm_faults": sum(m["arm_faults"] for m in results),
        "audit_failures": sum(not m["audit_ok"] for m in results),
        "command_gap_ms_max": max(m["gap_ms"] for m in results),
        "command_late_ms_p99": max(m["late_ms_p99"] for m in results),
        "command_late_ms_max": max(m["late_ms"] for m in results),
        "reengaged_after_fault": sum(m["reengaged"] for m in results),
        "limit_approach_accel_ratio_max": max(limit) if limit else float("nan"),
        "export_action_audit_ratio_max": export_ratio,
        "eval_audit_jerk_agree": all(m["jerk_agree"] for m in results),
        "bit_identical": all(m["bit_identical"] for m in results),
        "resume_jumps": sum(m["resume_jumps"] for m in results),
        "hand_tracking_r_min": min(rs) if rs else float("nan"),
        "hand_lag_ms_p50": float(np.median(lags)) if lags else float("nan"),
        "sender_realtime": all(bool(m["realtime"]) for m in results),
        "busy_processes": args.busy,
        "host_steal_ms_max": max((m["steal_ms"] for m in results if m["steal_ms"] is not None), default=None),
        **mech,
    }
    common.report(f"bench/realtime.py: {len(results)} sessions of {seconds:g} s beside {args.busy} busy processes",
                  figures, TARGETS, args.json)


if __name__ == "__main__":
    main()
