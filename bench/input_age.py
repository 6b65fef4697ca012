"""How old a glove sample is when the pipeline step takes it, and where that age comes from (issue 42).

    python bench/input_age.py [--json] [--quick] [--busy N] [--seconds S]

A LiveSession on a rig with a VMC glove and suit (tests/helpers/vmc.py rig_text) and the simulated arm and
hand; a child process sends a whole VMC frame at 120 Hz over loopback UDP, its /VMC/Ext/T the instant it
sends (time.monotonic, the same clock the session clock runs on), so that a sender the load delays sends
late, not old. The session is engaged (execute), so that the command sender ticks and the loop records its
ticks too. Every glove sample is timed at each stage, on the session clock:

    sent      the sender's send instant (its /VMC/Ext/T)
    read      the VMC decoding process read the datagram (Frame.receive_ns; devices/vmc/decoding_process.py,
              at SCHED_FIFO where permitted)
    decoded   the session's receiver read the decoded frame from that process's pipe
    handed    the device's runner handed the sample to the loop's queue (its log time)
    stepped   the session loop fed it to the pipeline step (a sample with a newer one queued behind it is
              recorded but not stepped: "superseded", counted apart)

and its age when the step takes it (stepped - its stamp: the acquisition time on the session clock,
ClockSync's mapping of /VMC/Ext/T) is the figure. Measured quiet, then under --busy busy processes (made
here, bench/common.py Load) beside the session; the sender is not raised above them.

input_age_ms_p95_loaded   p95 of the age under the load (issue 42: <= 50)

--compare adds a loaded session with the decoding process, the receiving and the runner threads put back at
ordinary scheduling, nice 0 (before issue 42).
The load average is printed too: other work on the machine delays the session as the busy processes do.
--quick: sessions of 3 s beside 2 busy processes.

JSON keys:
    input_age_ms_p95_loaded   float
"""

from __future__ import annotations

import json
import multiprocessing
import os
import socket
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402  (sets one-thread environment before numpy loads)

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

RATE_HZ = 120.0
GLOVE = "/glove/glove/hand"
STAGES = ("read", "decoded", "handed", "stepped")


def _sender(port: int, seconds: float, ready, go, out) -> None:
    """A 120 Hz VMC glove and suit, stamped when sent; a frame due while the last was late is skipped
    (a device's own clock does not send a backlog)."""
    from teleprev.thread_priority import raise_this_thread
    from tests.helpers.vmc import arm_messages, bundle, finger_messages

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    raise_this_thread(thread="the bench's glove")  # a glove's clock is not on this machine's CPUs
    ready.set()
    go.wait()
    start, k, sent = time.monotonic(), 0, 0
    late = []
    while k < seconds * RATE_HZ:
        t = k / RATE_HZ
        flex = np.full(5, 0.6 + 0.4 * np.sin(2 * np.pi * 0.7 * t))
        now = time.monotonic()
        sock.sendto(bundle(*arm_messages(t=now), *finger_messages(flex)).dgram, ("127.0.0.1", port))
        late.append(time.monotonic() - now)
        sent += 1
        k = max(k + 1, int((time.monotonic() - start) * RATE_HZ))
        time.sleep(max(0.0, start + k / RATE_HZ - time.monotonic()))
    out.put((sent, late))


def measure(folder: Path, seconds: float, busy: int, input_nice: int | None = None) -> dict:
    """One session of `seconds` beside `busy` busy processes: each stage's age (ms, from the stamp) per
    glove sample, the frames sent and stepped, and how long the sender took to send (ms). `input_nice`:
    put the decoding process (not real-time), the receiving and runner threads at this nice value (0: as
    before issue 42) instead of their own."""
    from teleprev.live.record.session import LiveSession, RecordOptions
    from tests.helpers.ports import free_port
    from tests.helpers.vmc import rig_text
    from tests.helpers.wait import wait_until

    port = free_port()
    name = f"age_busy{busy}_nice{input_nice}"
    rig = folder / f"{name}.toml"
    rig.write_text(rig_text(port))
    rec = LiveSession(RecordOptions(out=folder / f"{name}.mcap", rig=rig))
    clock = rec.clock
    read: dict[int, int] = {}
    decoded: dict[int, int] = {}
    handed: dict[int, int] = {}
    stepped: dict[int, int] = {}

    feed = rec.driver.feed

    def timed_feed(msg, *a):
        now = clock.now_ns()
        out = feed(msg, *a)
        if msg.topic == GLOVE and out.result is not None:  # (a superseded sample steps nothing)
            stepped.setdefault(msg.payload.stamp_ns, now)
        return out

    rec.driver.feed = timed_feed
    runner = rec.runners["glove"]
    sink = runner.sink

    def timed_sink(sample, receive_ns):
        if sample.topic == GLOVE:
            handed.setdefault(sample.payload.stamp_ns, receive_ns)
        sink(sample, receive_ns)

    runner.sink = timed_sink
    ctx = multiprocessing.get_context("spawn")
    ready, go, out = ctx.Event(), ctx.Event(), ctx.Queue()
    proc = ctx.Process(target=_sender, args=(port, seconds, ready, go, out), daemon=True)
    proc.start()
    ready.wait(60)
    with common.Load(busy):
        rec.start()
        try:
            wait_until(lambda: rec.runners["glove"].connected, 60.0, what="the glove's receiver opened")
            if input_nice is not None:  # the input threads put back where they were before issue 42
                receiver = rec.devices["glove"]._receiver
                os.sched_setscheduler(receiver._process.pid, os.SCHED_OTHER, os.sched_param(0))
                for tid in (*(r._thread.native_id for r in rec.runners.values()), receiver._thread.native_id,
                            receiver._process.pid):
                    os.setpriority(os.PRIO_PROCESS, tid, input_nice)
            fanout = rec.devices["glove"]._receiver.fanout
            publish = fanout.publish

            def timed_publish(frame):
                read.setdefault(frame.stamp_ns, frame.receive_ns)
                decoded.setdefault(frame.stamp_ns, clock.now_ns())
                publish(frame)

            fanout.publish = timed_publish
            go.set()
            time.sleep(0.5)
            rec.loop.engage("bench")
            sent, late = out.get(timeout=seconds + 60)
            time.sleep(0.3)
        finally:
            rec.stop()
            proc.join(10)
    skip = 60  # the first half second: the clock sync locking, the engage ramp
    stamps = sorted(stepped)[skip:]
    ages = {stage: np.array([(times[s] - s) / 1e6 for s in stamps if s in times])
            for stage, times in zip(STAGES, (read, decoded, handed, stepped))}
    return {"sent": sent, "send_ms": np.array(late) * 1e3, "stepped": len(stepped), "ages": ages,
            "superseded": rec.loop.stats.superseded}


def summary(result: dict) -> dict:
    """Counts, the sender's own send time, and each stage's age: p50, p95, max (ms)."""
    out = {"sent": result["sent"], "stepped": result["stepped"], "superseded": result["superseded"],
           "send_p95": float(np.percentile(result["send_ms"], 95)) if len(result["send_ms"]) else float("nan")}
    for stage, a in result["ages"].items():
        for name, value in (("p50", np.percentile(a, 50)), ("p95", np.percentile(a, 95)), ("max", a.max())):
            out[f"{stage}_{name}"] = float(value) if len(a) else float("nan")
    return out


def input_age(seconds: float, busy: int = 4, quiet: bool = True, compare: bool = False) -> dict[str, dict]:
    """{"quiet": ..., "loaded": ..., "loaded_input_nice_0": ...}: the summary of each session run."""
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        if quiet:
            runs["quiet"] = summary(measure(Path(tmp), seconds, 0))
        runs["loaded"] = summary(measure(Path(tmp), seconds, busy))
        if compare:
            runs["loaded_input_nice_0"] = summary(measure(Path(tmp), seconds, busy, input_nice=0))
    return runs


def describe(name: str, s: dict) -> str:
    stages = "; ".join(f"{st} {s[f'{st}_p50']:.1f}/{s[f'{st}_p95']:.1f}/{s[f'{st}_max']:.1f}" for st in STAGES)
    return (f"{name}: {s['sent']} frames sent (send p95 {s['send_p95']:.1f} ms), {s['stepped']} stepped "
            f"({s['superseded']} superseded: recorded, not stepped); age from the stamp, p50/p95/max ms: {stages}")


def main() -> None:
    p = common.parser(__doc__.splitlines()[0])
    p.add_argument("--busy", type=int, default=4, help="busy processes beside the loaded session (default 4)")
    p.add_argument("--seconds", type=float, default=10.0, help="seconds per session (default 10; --quick 3)")
    p.add_argument("--compare", action="store_true",
                   help="also a loaded session with the input process and threads at nice 0 (as before issue 42)")
    args = p.parse_args()
    runs = input_age(3.0 if args.quick else args.seconds, 2 if args.quick else args.busy, compare=args.compare)
    for name, s in runs.items():
        print(describe(name, s), file=sys.stderr if args.json else sys.stdout)
    steal = common.steal_ms()
    figures = {"input_age_ms_p95_loaded": round(runs["loaded"]["stepped_p95"], 2)}
    extra = {"input_age_ms_p50_loaded": round(runs["loaded"]["stepped_p50"], 2),
             "input_age_ms_p95_quiet": round(runs["quiet"]["stepped_p95"], 2)}
    if args.compare:
        extra["input_age_ms_p95_loaded_input_nice_0"] = round(runs["loaded_input_nice_0"]["stepped_p95"], 2)
    if not args.json:
        print(f"(load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs; steal so far {steal} ms)")
    common.report("bench/input_age.py: a 120 Hz glove's sample age when the step takes it", {**figures, **extra},
                  {"input_age_ms_p95_loaded": "<= 50"})
    if args.json:
        print(json.dumps(figures))


if __name__ == "__main__":
    main()
