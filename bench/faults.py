"""Fault matrix: every fault a lab meets, on the real CLI in subprocesses, seeded.

    python bench/faults.py [--json] [--quick] [--seed N] [--details FILE]

Faults (times and offsets drawn from the seed):
  record   SIGKILL / SIGTERM / SIGHUP at a random time of `teleprev record` (unattended, engaged); a full
           disk (a small tmpfs of random size where mount works, else RLIMIT_FSIZE); a device dying mid-
           session (a camera playing a clip that ends)
  export   SIGKILL / SIGTERM / SIGHUP at a random time of `teleprev export --append` onto an existing
           dataset (one in three with -j 2); appending on a full disk
  recover  SIGKILL / SIGTERM / SIGHUP at a random time of `teleprev recover`
  file     one flipped bit at a random offset of a recorded session; the session cut at a random offset
  input    while `teleprev record` executes on a VMC glove and suit (real OSC bundles on loopback), the
           sender goes silent or sends NaN for a short time (within the rig's input_loss_to_preview_s) or
           a long one (past it); the record process frozen (SIGSTOP, then SIGCONT) for 2 s
Every family runs twice, quiet and then under 8 busy processes (common.Load), from one table (FAMILIES) and
one runner; the files they fault (a clean recording, a cut copy, a base dataset and the sessions appended to it)
are made once, on first use, and shared by both halves. Families that measure time (seconds lost, a resume)
run their faults one at a time; beside the load, it is stopped while the faulted command starts up (imports
and numba take 3 s quiet and 48-84 s beside 8 busy processes on 2 shared cores: not what a fault measures)
and while its output is checked, and it runs from the moment the recording is under way to the command's
end. The other families run together, 4 faults at once, the load never stopped.
Per fault: the exit code, the seconds of recording lost, whether the output opens with the checks of
`mcap doctor` (the mcap library's readers with CRC validation: every record, the summary, every message),
and whether the old dataset survived (byte for byte, or the whole new one in its place).

Seconds lost: signals and record on a full disk: from the last message kept to the signal (or to the
moment the disk filled: the file reached the disk's size); a device dying: the longest silence of the
streams that did not die, over 0.1 s; flips and cuts: the log time the kept messages no longer cover,
minus the damaged range (the chunk the flipped byte is in; everything after a cut).
Figures:
  faults_run        faults run: delivered, and what came of them judged (target: >= 300)
  faults_run_loaded those of them under load (target: half)
  faults_timed_out  runs that did not do in a bounded time what the fault needs: get under way (START_TIMEOUT_S,
                    the load stopped) or end after the fault (END_TIMEOUT_S); the first kind is not run (target: 0)
  bench_errors      faults the bench itself failed on (the exception is printed; the run goes on) (target: 0)
  data_lost_s_max   the largest of those (target: <= 1.0 s)
  silent_failures   faults that lost data (or a dataset) without a non-zero exit and a one-line message,
                    either from the faulted command or from `teleprev info` on what it left
  tracebacks_shown  runs that printed a Python traceback
  datasets_lost     exports after which the old dataset was neither intact nor replaced by the whole new one
  resumed_without_operator  long losses and freezes after which the commands moved again with no engage
                    since the loss (target: 0); a short loss must resume, at the engage speed
The machine is shared with other work: times are not figures here, only what happened.
--quick: every family once (one signal each), quiet only, a 3 s clean recording, exports of 1-2 s
sessions; of the input family one long NaN loss and one freeze.
--only GROUP: one group of families (record, input, device, recover, export, file, options), quiet and loaded;
repeatable (two runs of complementary groups at once: their --details files together are the full run).

JSON keys:
    faults_run        int
    faults_run_loaded int
    faults_timed_out  int
    bench_errors      int
    data_lost_s_max   float
    data_lost_s_max_quiet   float
    data_lost_s_max_loaded  float
    resumed_without_operator  int
    silent_failures   int
    tracebacks_shown  int
    datasets_lost     int
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402  (sets one-thread environment before numpy loads)

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
from tests.helpers.faults import (  # noqa: E402
    alive,
    descendants,
    fsize_limit,
    has_traceback,
    mcap_opens,
    run_cli,
    small_disk,
    start_cli,
    wait_for_file,
    workers_of,
)
from tests.helpers.option_sweep import FIXTURE as SWEEP_FIXTURE  # noqa: E402
from tests.helpers.option_sweep import BadValue, Sweep, names_option, sweep  # noqa: E402

SIGNALS = (signal.SIGKILL, signal.SIGTERM, signal.SIGHUP)
LOST_EPS_S = 0.02  # below this a loss is rounding, not data
LOADS = {"quiet": 0, "loaded": 8}  # busy processes beside each half of the faults (common.Load)


@dataclass
class Row:
    kind: str
    detail: str
    exit_code: int | None
    lost_s: float = 0.0
    opens: bool | None = None
    dataset_ok: bool | None = None
    announced: bool = True  # a non-zero exit and one line, from the command or from `info` on its output
    traceback: bool = False
    resumed_without_operator: bool = False
    load: str = "quiet"  # "quiet", or "loaded": LOADS' busy processes beside it
    took_s: float = 0.0  # the fault's wall time, checks included
    timed_out: str = ""  # what did not happen in its bounded time (the run got no verdict)
    refused: bool | None = None  # a bad option value: refused before the work (exit 2, one line naming it, no file)
    error: str = ""  # the bench itself failed on this fault (its exception)

    @property
    def ran(self) -> bool:
        """The fault was delivered and the bench judged what came of it."""
        return not self.error and not self.timed_out.startswith((NOT_UNDER_WAY, NO_VERDICT))

    @property
    def silent(self) -> bool:
        accepted = self.refused is False and self.exit_code == 0  # a bad value taken without a word
        return accepted or (not self.announced and (self.lost_s > LOST_EPS_S or self.dataset_ok is False))


NOT_UNDER_WAY = "not under way"  # a timed_out that means the fault was never delivered
NO_VERDICT = "no verdict"  # a timed_out that means what came of the fault could not be judged
START_TIMEOUT_S = 60.0  # a command's start-up to its output under way (3 s quiet; the load is stopped meanwhile)
END_TIMEOUT_S = 180.0  # a faulted command's end after its fault (finalizing under the load)
CHECK_TIMEOUT_S = 600.0  # a check's command (info, recover) to its end: a start-up took over 120 s at load 57


def started(path: Path, min_bytes: int, timeout: float) -> bool:
    """Whether the recording reached min_bytes in time (wait_for_file raises when it did not)."""
    from tests.helpers.wait import WaitTimeout

    try:
        wait_for_file(path, min_bytes, timeout=timeout)
    except WaitTimeout:
        return False
    return True


@dataclass
class Faulted:
    """A run of the CLI that a fault hit while it ran."""

    code: int | None
    stdout: str = ""
    stderr: str = ""
    timed_out: str = ""  # what it did not do in its bounded time: get under way, or end after the fault
    noted: object = None  # what the fault noted (the times it acted)

    @property
    def traceback(self) -> bool:
        return has_traceback(self.stdout + self.stderr)


def during(args: list, out: Path, min_bytes: int, fault, load: common.Load, preexec_fn=None) -> Faulted:
    """`teleprev args`; once `out` holds min_bytes, `fault(proc)` (what it returns is kept as `noted`); then
    the run's end. The load is stopped while the command starts up (what a fault needs is the recording under
    way, not the imports) and runs from then to the command's end. A run that does not get under way in
    START_TIMEOUT_S, or does not end END_TIMEOUT_S after its fault, is killed and marked timed out."""
    with load.paused():
        proc = start_cli(args, preexec_fn=preexec_fn)
        began = started(out, min_bytes, timeout=START_TIMEOUT_S)
    try:
        if not began:
            proc.kill()
            stdout, stderr = proc.communicate()
            return Faulted(proc.returncode, stdout, stderr, f"{NOT_UNDER_WAY} ({out.name} under {min_bytes} bytes "
                                                            f"after {START_TIMEOUT_S:.0f} s)")
        noted = fault(proc)
        stdout, stderr, late = ended(proc, END_TIMEOUT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
    return Faulted(proc.returncode, stdout, stderr, "not ended after its fault" if late else "", noted=noted)


def ended(proc, timeout: float) -> tuple[str, str, bool]:
    """(stdout, stderr, late): the process's end, killed if it has not ended in `timeout` s (late)."""
    try:
        return *proc.communicate(timeout=timeout), False
    except subprocess.TimeoutExpired:
        proc.kill()
        return *proc.communicate(), True


def one_line(run) -> bool:
    return run.returncode != 0 and len([x for x in run.stderr.splitlines() if x.strip()]) == 1


def info_announces(path: Path) -> tuple[bool, bool]:
    """(`teleprev info` exits non-zero with one line, it printed a traceback)."""
    run = run_cli(["info", path], timeout=CHECK_TIMEOUT_S)
    return one_line(run), has_traceback(run.stdout + run.stderr)


def last_log_ns(path: Path) -> int | None:
    from teleprev.session.reader import SessionReader

    with SessionReader(path) as reader:
        return reader.end_ns


def message_times(path: Path):
    """Every message's log time, all topics, sorted (from the index: no decoding)."""
    import numpy as np

    from teleprev.session.reader import SessionReader

    with SessionReader(path) as reader:
        parts = [reader.log_times(t) for t in reader.topics]
    return np.sort(np.concatenate(parts)) if parts else np.zeros(0, np.int64)


def uncovered_s(clean, kept) -> float:
    """Log time the kept messages no longer cover: for each run of missing messages (in the clean file's
    order), from the last kept message before it to the first kept one after (or the run's end)."""
    import numpy as np

    if len(clean) == 0:
        return 0.0
    have = np.isin(clean, kept)
    lost, k, n = 0, 0, len(clean)
    while k < n:
        if have[k]:
            k += 1
            continue
        j = k
        while j < n and not have[j]:
            j += 1
        lo = clean[k - 1] if k > 0 else clean[k]
        hi = clean[j] if j < n else clean[j - 1]
        lost += int(hi - lo)
        k = j
    return lost / 1e9


def tree(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


# -- record ------------------------------------------------------------------------------------------------


RECORD = ["record", "--duration", "60", "--no-preview", "--engage-after", "0.3"]


def record_signal(work: Path, k: int, sig: int, after_s: float, load: common.Load) -> Row:
    out = work / f"rec_sig{k}.mcap"

    def fault(proc) -> int:
        time.sleep(after_s)
        sent_ns = time.time_ns()
        proc.send_signal(sig)
        return sent_ns

    ran = during(RECORD + ["-o", out], out, 150_000, fault, load)
    row = Row("record", f"{sig.name} at {after_s:.2f} s", ran.code, traceback=ran.traceback, timed_out=ran.timed_out)
    if ran.noted is None:
        return row
    with load.paused():
        return record_signal_checks(work, k, out, sig, ran.code, ran.noted, row)


def record_signal_checks(work: Path, k: int, out: Path, sig: int, code: int | None, sent_ns: int, row: Row) -> Row:
    final = out
    if sig == signal.SIGKILL:
        row.announced, tb = info_announces(out)
        row.traceback |= tb
        final = work / f"rec_sig{k}.recovered.mcap"
        run = run_cli(["recover", out, "-o", final], timeout=CHECK_TIMEOUT_S)
        row.traceback |= has_traceback(run.stdout + run.stderr)
    else:
        row.announced = code == 128 + sig
    row.opens = mcap_opens(final)
    end = last_log_ns(final) if final.exists() else None
    row.lost_s = max(0.0, (sent_ns - end) / 1e9) if end is not None else float("inf")
    return row


def record_full_disk(work: Path, k: int, size: int, load: common.Load) -> Row:
    with small_disk(work / f"disk{k}", size) as (disk, preexec):
        out = disk / "x.mcap"
        limit = size if preexec is not None else None

        def fault(proc) -> int | None:
            """The moment the file reaches the disk's size (the disk is full), if it did before the end."""
            deadline = time.monotonic() + END_TIMEOUT_S
            while proc.poll() is None and time.monotonic() < deadline:
                st = os.statvfs(disk)
                if (limit is not None and out.stat().st_size >= limit - 65536) or \
                        (limit is None and st.f_bavail * st.f_frsize < 65536):
                    return time.time_ns()
                time.sleep(0.005)
            return None

        ran = during(RECORD + ["-o", out], out, 1, fault, load, preexec_fn=preexec)
        full_ns = ran.noted
        row = Row("record", f"full disk at {size // 1000} kB", ran.code, timed_out=ran.timed_out,
                  announced=one_line(proc_result(ran.code, ran.stderr)), traceback=ran.traceback)
        if not out.exists():
            return row
        saved = work / f"disk{k}.recovered.mcap"
        with load.paused():
            run = run_cli(["recover", out, "-o", saved], timeout=CHECK_TIMEOUT_S)
    row.traceback |= has_traceback(run.stdout + run.stderr)
    with load.paused():
        return full_disk_checks(saved, full_ns, row)


def full_disk_checks(saved: Path, full_ns: int | None, row: Row) -> Row:
    row.opens = mcap_opens(saved)
    end = last_log_ns(saved) if saved.exists() else None
    if end is None or full_ns is None:
        row.lost_s = float("inf") if end is None else 0.0
    else:
        row.lost_s = max(0.0, (full_ns - end) / 1e9)
    return row


class _LossySender:
    """A VMC glove and suit on loopback whose frames can stop ("silent") or turn to NaN ("nan")."""

    def __init__(self, port: int):
        import math

        from tests.helpers.vmc import VmcSender, arm_messages, bundle, finger_messages

        class Sender(VmcSender):
            loss = ""

            def frame(self, k, rate_hz):
                if self.loss == "nan":
                    return bundle(*arm_messages(root_pos=(math.nan,) * 3, t=100.0 + k / rate_hz),
                                  *finger_messages(math.nan)).dgram
                return super().frame(k, rate_hz)

            def send(self, datagram):
                if self.loss != "silent":
                    super().send(datagram)

        self.sender = Sender(port)


def commands_moved_after(path: Path, after_ns: int) -> bool:
    """Whether the arm or hand commands changed after `after_ns` (session clock: wall-clock ns)."""
    import numpy as np

    from teleprev import topics
    from teleprev.session.reader import SessionReader

    reader = SessionReader(path)
    for topic in (topics.COMMAND_ARM, topics.COMMAND_HAND):
        if topic not in reader.topics:
            continue
        q = [m.payload.positions for m in reader.messages([topic]) if m.log_time_ns > after_ns]
        if len(q) > 1 and np.abs(np.diff(np.array(q), axis=0)).max() > 1e-6:
            return True
    return False


def engaged_after(path: Path, after_ns: int) -> bool:
    from teleprev import topics
    from teleprev.session.reader import SessionReader

    return any(m.payload.data.get("mode") == "execute" and m.log_time_ns > after_ns
               for m in SessionReader(path).messages([topics.MODE]))


def input_loss(work: Path, k: int, loss: str, lost_s: float, load: common.Load) -> Row:
    """`record` on a VMC rig, engaged; `loss` ("silent", "nan") for lost_s seconds, 2.5 s into the recording."""
    from tests.helpers.ports import free_port
    from tests.helpers.vmc import rig_text

    port = free_port()
    rig = work / f"vmc{k}.toml"
    rig.write_text(rig_text(port))
    out = work / f"loss{k}.mcap"
    lossy = _LossySender(port).sender.start(rate_hz=60.0)

    def fault(proc) -> tuple[int, int]:
        time.sleep(2.5)
        lossy.loss = loss
        lost_ns = time.time_ns()
        time.sleep(lost_s)
        lossy.loss = ""
        return lost_ns, time.time_ns()

    try:
        ran = during(["record", rig, "--duration", "6", "--no-preview", "--engage-after", "0.5", "-o", out], out,
                     100_000, fault, load)
    finally:
        lossy.stop()
    row = Row("input", f"{loss} {lost_s:.1f} s", ran.code, traceback=ran.traceback, timed_out=ran.timed_out)
    if ran.noted is None:
        return row
    lost_ns, back_ns = ran.noted
    with load.paused():
        row.opens = mcap_opens(out)
        if lost_s > 1.0:  # past the default bound: nothing moves until an operator engages
            moved = commands_moved_after(out, back_ns + 300_000_000)
            row.resumed_without_operator = moved and not engaged_after(out, lost_ns)
    return row


def frozen_record(work: Path, k: int, frozen_s: float, load: common.Load) -> Row:
    out = work / f"frozen{k}.mcap"

    def fault(proc) -> tuple[int, int]:
        time.sleep(1.5)
        proc.send_signal(signal.SIGSTOP)
        stopped_ns = time.time_ns()
        time.sleep(frozen_s)
        proc.send_signal(signal.SIGCONT)
        return stopped_ns, time.time_ns()

    ran = during(["record", "--duration", "6", "--no-preview", "--engage-after", "0.3", "-o", out], out, 150_000,
                 fault, load)
    row = Row("freeze", f"SIGSTOP {frozen_s:.1f} s", ran.code, traceback=ran.traceback, timed_out=ran.timed_out)
    if ran.noted is None:
        return row
    stopped_ns, cont_ns = ran.noted
    with load.paused():
        row.opens = mcap_opens(out)
        moved = commands_moved_after(out, cont_ns + 300_000_000)
        row.resumed_without_operator = moved and not engaged_after(out, stopped_ns)
    return row


def proc_result(code: int | None, stderr: str):
    return subprocess.CompletedProcess([], code, "", stderr)


def device_dies(work: Path, k: int, clip_s: float, load: common.Load) -> Row:
    import cv2
    import numpy as np

    folder = work / f"dev{k}"
    folder.mkdir()
    writer = cv2.VideoWriter(str(folder / "clip.mp4"), cv2.VideoWriter_fourcc(*"mp4v"), 30.0, (64, 48))
    for i in range(int(clip_s * 30)):
        writer.write(np.full((48, 64, 3), i % 255, np.uint8))
    writer.release()
    rig_text = (ROOT / "rigs" / "sim.toml").read_text()
    rig_text += '\n[devices.cam_clip]\nplugin = "opencv.camera"\nsource = "clip.mp4"\n'
    (folder / "rig.toml").write_text(rig_text)
    out = folder / "s.mcap"
    ran = during(["record", folder / "rig.toml", "--duration", str(clip_s + 2.5), "--no-preview", "--engage-after",
                  "0.3", "-o", out], out, 1, lambda proc: True, load)
    row = Row("record", f"camera clip ends after {clip_s:.1f} s", ran.code, traceback=ran.traceback,
              timed_out=ran.timed_out)
    if ran.noted is None or not out.exists():
        return row
    with load.paused():
        return device_dies_checks(out, ran.code, row)


def device_dies_checks(out: Path, code: int | None, row: Row) -> Row:
    row.opens = mcap_opens(out)
    from teleprev.session.reader import SessionReader
    from teleprev.session.summary import summarize

    s = summarize(out)
    gaps = [st.max_gap_s or 0.0 for st in s.streams if st.topic.startswith(("/glove/", "/suit/", "/arm/", "/hand/"))]
    row.lost_s = max(0.0, max(gaps, default=0.0) - 0.1)
    with SessionReader(out) as reader:
        clip = reader.topics.get("/camera/cam_clip/image")
        marked = any(d.device == "cam_clip" for d in s.device_events)
    # The session goes on without it (exit 0); the dead device must be marked in the file.
    row.announced = code == 0 and clip is not None and marked
    row.dataset_ok = None
    if not marked:
        row.lost_s = max(row.lost_s, 2 * LOST_EPS_S)  # an unmarked death counts as silent
    return row


# -- recover ----------------------------------------------------------------------------------------------


def recover_signal(work: Path, k: int, src: Path, sig: int, after_s: float) -> Row:
    before = hashlib.sha256(src.read_bytes()).hexdigest()
    out = work / f"recsig{k}.mcap"
    proc = start_cli(["recover", src, "-o", out])
    time.sleep(after_s)
    proc.send_signal(sig)
    stdout, stderr, late = ended(proc, END_TIMEOUT_S)
    row = Row("recover", f"{sig.name} at {after_s:.2f} s", proc.returncode, traceback=has_traceback(stdout + stderr),
              timed_out="not ended after its fault" if late else "")
    intact = hashlib.sha256(src.read_bytes()).hexdigest() == before
    row.opens = (not out.exists()) or mcap_opens(out)  # nothing, or a whole file
    row.lost_s = 0.0 if intact else float("inf")
    row.announced = proc.returncode != 0 or (out.exists() and row.opens)
    for partial in work.glob(f".{out.name}.partial-*"):  # a SIGKILL cannot clean up; the next run may
        partial.unlink()
    return row


# -- export -----------------------------------------------------------------------------------------------


def export_signal(work: Path, k: int, base: Path, sessions: list[Path], sig: int, after_s: float, workers: int,
                  old_episodes: int, new_episodes: int) -> Row:
    root = work / f"ds_kill{k}"
    shutil.copytree(base, root)
    old = tree(root)
    args = ["export", *sessions, "--repo-id", "bench/faults", "--root", root, "--append"]
    if workers > 1:
        args += ["-j", str(workers)]
    proc = start_cli(args)
    time.sleep(after_s)
    children = workers_of(proc.pid)
    proc.send_signal(sig)
    stdout, stderr, late = ended(proc, END_TIMEOUT_S)
    deadline = time.monotonic() + 5
    while any(alive(p) for p in children) and time.monotonic() < deadline:
        time.sleep(0.05)
    outlived = [p for p in children if alive(p)]
    for p in outlived:
        os.kill(p, signal.SIGKILL)
    row = Row("export", f"{sig.name} at {after_s:.1f} s, -j {workers}", proc.returncode,
              traceback=has_traceback(stdout + stderr), timed_out="not ended after its fault" if late else "")
    if root.is_dir() and tree(root) == old:
        row.dataset_ok = True
    else:
        row.dataset_ok = root.is_dir() and whole_dataset(root, old_episodes + new_episodes)
    if outlived:
        row.dataset_ok = False  # a worker that outlives its export may still write
        row.detail += f" ({len(outlived)} workers outlived it)"
    from teleprev.export.swap import clean_stale

    clean_stale(root)
    shutil.rmtree(root, ignore_errors=True)
    return row


def whole_dataset(root: Path, episodes: int) -> bool:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    try:
        ds = LeRobotDataset("bench/faults", root=root, video_backend="pyav")
        return ds.num_episodes == episodes and ds[len(ds) - 1] is not None
    except Exception:
        return False


def export_full_disk(work: Path, name: int, k: int, base: Path, session: Path) -> Row:
    """The k-th of the family: 150 kB + 40 kB k left on the disk (too little for the append)."""
    with small_disk(work / f"xdisk{name}", 40_000_000) as (disk, preexec):
        root = disk / "ds"
        shutil.copytree(base, root)
        old = tree(root)
        if preexec is None:
            st = os.statvfs(disk)
            (disk / "filler").write_bytes(b"\0" * max(0, st.f_bavail * st.f_frsize - 150_000 - 40_000 * k))
        else:
            preexec = fsize_limit(150_000 + 40_000 * k)
        run = run_cli(["export", session, "--repo-id", "bench/faults", "--root", root, "--append"], preexec_fn=preexec,
                      timeout=300)
        row = Row("export", "full disk", run.returncode, announced=one_line(run),
                  traceback=has_traceback(run.stdout + run.stderr))
        row.dataset_ok = tree(root) == old and not list(disk.glob(".ds.export-*"))
    return row


# -- files ------------------------------------------------------------------------------------------------


def damaged_file(work: Path, k: int, clean: Path, clean_times, chunks, kind: str, rng: random.Random) -> Row:
    data = bytearray(clean.read_bytes())
    path = work / f"{kind}{k}.mcap"
    if kind == "flip":
        at = rng.randrange(len(data))
        data[at] ^= 1 << rng.randrange(8)
        hit = [c for c in chunks if c[0] <= at < c[0] + c[1]]
        damaged_s = (hit[0][3] - hit[0][2]) / 1e9 if hit else 0.0
        detail = f"bit flip at byte {at}" + (" (in a chunk)" if hit else "")
    else:
        at = rng.randrange(8, len(data))
        del data[at:]
        after = [c for c in chunks if c[0] + c[1] > at]
        damaged_s = (clean_times[-1] - min(c[2] for c in after)) / 1e9 if after else 0.0
        detail = f"cut at byte {at}"
    path.write_bytes(bytes(data))
    info = run_cli(["info", path], timeout=CHECK_TIMEOUT_S)
    row = Row("file", detail, info.returncode, traceback=has_traceback(info.stdout + info.stderr))
    row.announced = one_line(info)
    if info.returncode == 0:  # info found nothing wrong: then what is read back must be the recording
        row.announced = same_messages(clean, path)
    out = work / f"{kind}{k}.saved.mcap"
    run = run_cli(["recover", path, "-o", out], timeout=CHECK_TIMEOUT_S)
    row.traceback |= has_traceback(run.stdout + run.stderr)
    if run.returncode != 0 or not out.exists():
        row.opens = False
        row.lost_s = float("inf")
        row.announced = row.announced and one_line(run)
        return row
    row.opens = mcap_opens(out)
    kept = message_times(out)
    row.lost_s = max(0.0, uncovered_s(clean_times, kept) - damaged_s)
    return row


def same_messages(a: Path, b: Path) -> bool:
    from mcap.reader import make_reader

    def raw(p):
        with open(p, "rb") as f:
            return [(c.topic, m.log_time, m.data) for _, c, m in make_reader(f, validate_crcs=True).iter_messages()]

    try:
        return raw(a) == raw(b)
    except Exception:
        return False


# -- option values -----------------------------------------------------------------------------------------


# A refusal costs a start-up (1-3 s of CPU); a bad value accepted does the work, and is cut short once it has
# used OPTION_CPU_S of CPU. CPU, not wall time: at load 57 a refusal's start-up took over 120 s of wall time.
OPTION_CPU_S = 20.0
OPTION_WALL_S = 900.0  # no verdict by then: counted as a timeout


def cpu_s(pid: int) -> float:
    """CPU seconds of a process, its ended children and its living descendants (from /proc)."""
    total = 0
    for p in (pid, *descendants(pid)):
        try:
            fields = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        total += sum(int(x) for x in fields[11:15 if p == pid else 13])  # utime stime (cutime cstime)
    return total / os.sysconf("SC_CLK_TCK")


def bounded_by_cpu(args: list, cwd: Path) -> tuple[subprocess.CompletedProcess | None, str]:
    """`teleprev args` in cwd to its end, or killed (with its descendants) once it has used OPTION_CPU_S of CPU
    (the work) or run OPTION_WALL_S: (the run, or None; why it was cut short)."""
    proc = start_cli(args, cwd=cwd, new_session=True)
    t0 = time.monotonic()
    why = ""
    while proc.poll() is None:
        if cpu_s(proc.pid) > OPTION_CPU_S:
            why = f"not refused: {OPTION_CPU_S:.0f} s of CPU into the work"
        elif time.monotonic() - t0 > OPTION_WALL_S:
            why = f"{NO_VERDICT} in {OPTION_WALL_S:.0f} s"
        if why:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
            return None, why
        time.sleep(0.2)
    stdout, stderr = proc.communicate()
    return subprocess.CompletedProcess(args, proc.returncode, stdout, stderr), ""


def option_refused(sh: Shared, bad: BadValue) -> Row:
    """`teleprev` with one bad option value, in an empty folder: refused before the work (exit 2, one line
    naming the option, nothing written in the folder), or not."""
    folder = sh.work / f"option{next(sh.ids)}"
    folder.mkdir()
    copy = folder / "session.mcap"
    if "{copy}" in bad.args:
        shutil.copyfile(SWEEP_FIXTURE, copy)
    before = set(folder.rglob("*"))
    if "{collision}" in bad.args:
        sh.prepare(("collision_data",))  # made once, by the first fault that needs it
    args = [a.format(session=SWEEP_FIXTURE, copy=copy, collision=sh.work / "collision") for a in bad.args]
    row = Row("option", bad.where, None)
    run, why = bounded_by_cpu(args, folder)
    if run is None:
        if why.startswith(NO_VERDICT):
            row.timed_out = why
        else:
            row.refused = row.announced = False
            row.detail += f" ({bad.why}): {why}"
        shutil.rmtree(folder, ignore_errors=True)
        return row
    made = sorted(str(p.relative_to(folder)) for p in set(folder.rglob("*")) - before)
    lines = [x for x in run.stderr.splitlines() if x.strip()]
    row.exit_code = run.returncode
    row.traceback = has_traceback(run.stdout + run.stderr)
    row.refused = run.returncode == 2 and len(lines) == 1 and names_option(lines[0], bad.names) and not made
    row.announced = row.refused
    if not row.refused:
        row.detail += f" ({bad.why}): said {lines[-1][:80] if lines else 'nothing'!r}" + (f", wrote {made}" if made
                                                                                        else "")
    shutil.rmtree(folder, ignore_errors=True)
    return row


@functools.cache
def option_sweep() -> Sweep:
    return sweep()


def option_fault(sh: Shared, k: int, rng: random.Random, load: common.Load) -> Row:
    """The k-th bad option value of the sweep; past them, an option or command it does not classify."""
    found = option_sweep()
    if k < len(found.bad):
        return option_refused(sh, found.bad[k])
    what = found.unclassified[k - len(found.bad)]
    return Row("option", what, None, error="not classified in tests/helpers/option_sweep.py: cannot be swept")


# -- the matrix -------------------------------------------------------------------------------------------


class Shared:
    """What the families fault, made once on first use (in the quiet half) and shared by both halves."""

    def __init__(self, work: Path, quick: bool):
        self.work, self.quick = work, quick
        self.ids = itertools.count()  # every fault's files apart
        self.lock = threading.Lock()  # faults run in threads, and cached_property does not lock (3.12)

    def prepare(self, needs: tuple[str, ...]) -> None:
        """Make what a family faults (its `needs`), once, before its faults run in parallel."""
        with self.lock:
            for name in needs:
                getattr(self, name)

    @functools.cached_property
    def clean(self) -> tuple[Path, list, object]:
        """A clean recording: (path, its chunks' spans, every message's log time)."""
        from tests.helpers.faults import chunk_spans

        clean = self.work / "clean.mcap"
        run = run_cli(["record", "--duration", "3" if self.quick else "6", "--no-preview", "--engage-after", "0.5",
                       "-o", clean], timeout=180)
        assert run.returncode == 0, run.stderr
        return clean, chunk_spans(clean), message_times(clean)

    @functools.cached_property
    def collision_data(self) -> Path:
        """A small collision dataset (`collision dataset`): what the collision trainers of the option sweep read."""
        out = self.work / "collision"
        run = run_cli(["collision", "dataset", out, "--uniform", "300", "--boundary", "300", "--shard-size", "100",
                       "--workers", "1"], timeout=600)
        assert run.returncode == 0, run.stderr
        return out

    @functools.cached_property
    def cut(self) -> Path:
        """The clean recording cut at 90 %: what `recover` is signalled while rewriting."""
        cut = self.work / "cut.mcap"
        clean = self.clean[0]
        cut.write_bytes(clean.read_bytes()[: int(clean.stat().st_size * 0.9)])
        return cut

    @functools.cached_property
    def dataset(self) -> tuple[Path, list[Path], float]:
        """(a base dataset of one episode, two sessions to append to it, seconds an append takes quiet)."""
        from teleprev.export.synthetic import EpisodeSpec, SyntheticSession, write_session

        short, long = (1.0, 2.0) if self.quick else (3.0, 6.0)
        s0 = write_session(self.work / "s0.mcap", SyntheticSession((EpisodeSpec("pour", short),), seed=1))
        s1 = write_session(self.work / "s1.mcap", SyntheticSession((EpisodeSpec("pour", long),), seed=2))
        s2 = write_session(self.work / "s2.mcap", SyntheticSession((EpisodeSpec("hang", long),), seed=3))
        base = self.work / "base"
        run = run_cli(["export", s0, "--repo-id", "bench/faults", "--root", base], timeout=600)
        assert run.returncode == 0, run.stderr
        t0 = time.monotonic()
        timing_root = self.work / "timing"
        shutil.copytree(base, timing_root)
        run = run_cli(["export", s1, s2, "--repo-id", "bench/faults", "--root", timing_root, "--append"], timeout=600)
        assert run.returncode == 0, run.stderr
        export_s = time.monotonic() - t0
        shutil.rmtree(timing_root)
        return base, [s1, s2], export_s


def nth_signal(k: int, first: int) -> signal.Signals:
    """The signals in turn, from SIGNALS[first] (so that --quick's one fault of each family differs)."""
    return SIGNALS[(first + k) % len(SIGNALS)]


# the input family in turn; --quick runs the first two (a long NaN loss, a freeze)
INPUT_FAULTS = (("nan", 1.5), ("freeze", 2.0), ("silent", 0.4), ("nan", 0.4), ("silent", 1.5))


def input_fault(sh: Shared, k: int, rng: random.Random, load: common.Load) -> Row:
    loss, seconds = INPUT_FAULTS[k % len(INPUT_FAULTS)]
    if loss == "freeze":
        return frozen_record(sh.work, next(sh.ids), seconds, load)
    return input_loss(sh.work, next(sh.ids), loss, seconds, load)


def export_signal_fault(sh: Shared, k: int, rng: random.Random, load: common.Load) -> Row:
    base, sessions, export_s = sh.dataset
    workers = 2 if k % 3 == 2 else 1  # one in three with -j 2
    return export_signal(sh.work, next(sh.ids), base, sessions, nth_signal(k, 2), rng.uniform(0.3, export_s * 1.1),
                         workers, 1, 2)


def damaged_fault(kind: str):
    def run(sh: Shared, k: int, rng: random.Random, load: common.Load) -> Row:
        clean, chunks, times = sh.clean
        k = next(sh.ids)
        try:
            return damaged_file(sh.work, k, clean, times, chunks, kind, rng)
        finally:
            for f in sh.work.glob(f"{kind}{k}.*"):
                f.unlink()

    return run


@dataclass(frozen=True)
class Family:
    group: str  # what --only names
    name: str
    per_load: int  # faults of a full run, in each half (quiet, loaded)
    # the k-th fault of the family, its draws from the rng given, beside the load given
    fault: Callable[[Shared, int, random.Random, common.Load], Row]
    quick: int = 1  # faults of a --quick run (quiet only)
    # Timed: what it measures is time (seconds of recording lost, a resume after a loss), so its faults run one
    # at a time, the load stopped while each command starts up and while its output is checked. Untimed
    # families (what a file or dataset keeps) run all together, their faults in parallel, the load never
    # stopped.
    timed: bool = False
    needs: tuple[str, ...] = ()  # what of Shared it faults (made before its faults run in parallel)


FAMILIES = (  # the record faults first: their seconds lost under load are the figure most at risk
    Family("record", "record signal", 24, lambda sh, k, rng, load: record_signal(
        sh.work, next(sh.ids), nth_signal(k, 0), rng.uniform(0.5, 3.5), load), timed=True),
    Family("record", "record full disk", 8, lambda sh, k, rng, load: record_full_disk(
        sh.work, next(sh.ids), rng.randrange(400_000, 2_500_000), load), timed=True),
    Family("input", "input loss and freeze", 15, input_fault, quick=2, timed=True),
    Family("device", "device dies", 2,
           lambda sh, k, rng, load: device_dies(sh.work, next(sh.ids), rng.uniform(1.0, 2.5), load), timed=True),
    Family("file", "bit flip", 54, damaged_fault("flip"), quick=2, needs=("clean",)),
    Family("file", "cut", 22, damaged_fault("cut"), needs=("clean",)),
    Family("recover", "recover signal", 18, lambda sh, k, rng, load: recover_signal(
        sh.work, next(sh.ids), sh.cut, nth_signal(k, 1), rng.uniform(0.05, 1.2)), needs=("cut",)),
    Family("export", "export signal", 6, export_signal_fault, needs=("dataset",)),
    Family("export", "export full disk", 2, lambda sh, k, rng, load: export_full_disk(
        sh.work, next(sh.ids), k, sh.dataset[0], sh.dataset[1][0]), needs=("dataset",)),
    Family("options", "option value out of range", len(option_sweep().bad) + len(option_sweep().unclassified),
           option_fault, quick=3),
)
# untimed faults run at once, quiet and beside the load (what a file keeps does not depend on the time it took).
# Not more beside the load: the bench's processes share one autogroup's part of the CPUs whatever their
# number, so 8 at once doubled each one's wall time (120 s timeouts at load 57) and added nothing.
UNTIMED_AT_ONCE = {"quiet": 4, "loaded": 4}


@dataclass(frozen=True)
class Job:
    """One fault to run: the k-th of its family, with its own generator."""

    family: Family
    k: int
    rng: random.Random


def run_job(job: Job, shared: Shared, load: common.Load) -> Row:
    """The fault, timed; a fault the bench itself fails on is a row with its error (the run goes on)."""
    t = time.monotonic()
    try:
        row = job.family.fault(shared, job.k, job.rng, load)
    except subprocess.TimeoutExpired as exc:  # a check (info, recover, export) that did not end in its time
        row = Row(job.family.group, f"{job.family.name} {job.k}", None,
                  timed_out=f"{NO_VERDICT}: {' '.join(map(str, exc.cmd[3:5]))} did not end in {exc.timeout:.0f} s")
    except Exception as exc:  # noqa: BLE001 - reported as the bench's own failure, in its row and figure
        traceback.print_exc()
        row = Row(job.family.group, f"{job.family.name} {job.k}", None, error=f"{type(exc).__name__}: {exc}")
    row.took_s = time.monotonic() - t
    return row


def run_matrix(families, shared: Shared, loads: dict[str, int], seed: int, add) -> None:
    """Every timed family's faults one at a time, quiet then beside `loads[load]` busy processes, family by
    family (so that a run cut short has both halves of the families it ran); then every untimed family's faults
    together, UNTIMED_AT_ONCE[load] at a time, quiet and then loaded. Each fault draws from a generator of its own
    (seeded in a fixed order), so the draws do not depend on which parallel fault ran first."""
    draws = random.Random(seed)

    def jobs(family: Family) -> list[Job]:
        n = family.quick if shared.quick else family.per_load
        return [Job(family, k, random.Random(draws.getrandbits(64))) for k in range(n)]

    planned = [(f, load, jobs(f)) for f in families for load in loads]  # every draw made in one order
    for family, load, todo in planned:
        if family.timed:
            with common.Load(loads[load]) as busy:
                for job in todo:
                    add(run_job(job, shared, busy), load)
    for load in loads:
        todo = [job for family, half, js in planned if half == load and not family.timed for job in js]
        for family in {job.family for job in todo}:
            shared.prepare(family.needs)
        with common.Load(loads[load]) as busy, ThreadPoolExecutor(UNTIMED_AT_ONCE[load]) as pool:
            for row in pool.map(lambda job: run_job(job, shared, busy), todo):
                add(row, load)


def main() -> None:
    p = common.parser(__doc__)
    p.add_argument("--seed", type=int, default=16)
    p.add_argument("--details", type=Path, help="write every fault's row to this JSON file")
    p.add_argument("--only", choices=sorted({f.group for f in FAMILIES}), action="append",
                   help="only this group of families, quiet and loaded (repeatable)")
    args = p.parse_args()
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    rows: list[Row] = []
    started_at = time.monotonic()

    def add(row: Row, load: str) -> None:
        row.load = load
        rows.append(row)
        print(f"{len(rows):4d} {load:6s} {row.kind:8s} {row.detail:42s} exit {row.exit_code!s:5s} lost "
              f"{row.lost_s:7.3f} s opens {row.opens!s:5s} dataset {row.dataset_ok!s:5s} {row.took_s:5.1f} s"
              f"{' SILENT' if row.silent else ''}{' TRACEBACK' if row.traceback else ''}"
              f"{' RESUMED WITHOUT OPERATOR' if row.resumed_without_operator else ''}"
              f"{' TIMED OUT: ' + row.timed_out if row.timed_out else ''}{' ERROR: ' + row.error if row.error else ''}",
              file=sys.stderr, flush=True)

    families = [f for f in FAMILIES if args.only is None or f.group in args.only]
    loads = {"quiet": LOADS["quiet"]} if args.quick else LOADS
    with tempfile.TemporaryDirectory(prefix="teleprev-faults-") as tmp:
        run_matrix(families, Shared(Path(tmp), args.quick), loads, args.seed, add)
    took_s = time.monotonic() - started_at

    finite = [r.lost_s for r in rows]

    figures = {
        "faults_run": sum(r.ran for r in rows),
        "faults_run_loaded": sum(r.ran and r.load == "loaded" for r in rows),
        "faults_timed_out": sum(bool(r.timed_out) for r in rows),
        "bench_errors": sum(bool(r.error) for r in rows),
        "data_lost_s_max": round(max(finite, default=0.0), 3),
        **{f"data_lost_s_max_{load}": round(max((r.lost_s for r in rows if r.load == load), default=0.0), 3)
           for load in LOADS},
        "resumed_without_operator": sum(r.resumed_without_operator for r in rows),
        "silent_failures": sum(r.silent for r in rows),
        "tracebacks_shown": sum(r.traceback for r in rows),
        "datasets_lost": sum(r.dataset_ok is False for r in rows),
    }
    by_kind: dict[str, list[Row]] = {}
    for r in rows:
        what = r.detail.split(" at ")[0].split(" (")[0].split(" after ")[0]
        key = f"{r.kind} {what} {r.load}"
        by_kind.setdefault(key, []).append(r)
    from rich.console import Console
    from rich.table import Table

    table = Table(title="faults by kind", title_justify="left")
    for col in ("fault", "runs", "exit codes", "max lost s", "opens", "dataset kept", "silent", "tracebacks",
                "resumed"):
        table.add_column(col)
    for key, rs in by_kind.items():
        opens = [r.opens for r in rs if r.opens is not None]
        kept = [r.dataset_ok for r in rs if r.dataset_ok is not None]
        table.add_row(key, str(len(rs)), " ".join(sorted({str(r.exit_code) for r in rs})),
                      f"{max(r.lost_s for r in rs):.3f}", f"{sum(opens)}/{len(opens)}" if opens else "-",
                      f"{sum(kept)}/{len(kept)}" if kept else "-", str(sum(r.silent for r in rs)),
                      str(sum(r.traceback for r in rs)), str(sum(r.resumed_without_operator for r in rs)))
    Console(stderr=args.json, width=max(100, shutil.get_terminal_size().columns)).print(table)
    if args.details:
        args.details.write_text(json.dumps([asdict(r) for r in rows], indent=1, default=str))
    print(f"{len(rows)} faults in {took_s / 60:.1f} min", file=sys.stderr)
    targets = {"faults_run": ">= 300", "faults_run_loaded": ">= half",
               "data_lost_s_max": "<= 1.0 (flips and cuts: beyond the damaged range)",
               "faults_timed_out": "0", "bench_errors": "0",
               "silent_failures": "0", "tracebacks_shown": "0", "datasets_lost": "0", "resumed_without_operator": "0",
               **{f"data_lost_s_max_{load}": "<= 1.0" for load in LOADS}}
    common.report("bench/faults.py: the fault matrix on the real CLI", figures, targets, args.json)


if __name__ == "__main__":
    main()
