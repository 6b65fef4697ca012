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
The input faults, the full disk and the record signals run twice: quiet, and under 8 busy processes.
Per fault: the exit code, the seconds of recording lost, whether the output opens with the checks of
`mcap doctor` (the mcap library's readers with CRC validation: every record, the summary, every message),
and whether the old dataset survived (byte for byte, or the whole new one in its place).

Seconds lost: signals and record on a full disk: from the last message kept to the signal (or to the
moment the disk filled: the file reached the disk's size); a device dying: the longest silence of the
streams that did not die, over 0.1 s; flips and cuts: the log time the kept messages no longer cover,
minus the damaged range (the chunk the flipped byte is in; everything after a cut).
Figures:
  faults_run        faults run
  data_lost_s_max   the largest of those (target: <= 1.0 s)
  silent_failures   faults that lost data (or a dataset) without a non-zero exit and a one-line message,
                    either from the faulted command or from `teleprev info` on what it left
  tracebacks_shown  runs that printed a Python traceback
  datasets_lost     exports after which the old dataset was neither intact nor replaced by the whole new one
  resumed_without_operator  long losses and freezes after which the commands moved again with no engage
                    since the loss (target: 0); a short loss must resume, at the engage speed
The machine is shared with other work: times are not figures here, only what happened.
--quick: every kind of fault once (one signal each), quiet only, a 3 s clean recording, exports of 1-2 s
sessions; of the input family one long NaN loss and one freeze.

JSON keys:
    faults_run        int
    data_lost_s_max   float
    data_lost_s_max_quiet   float
    data_lost_s_max_loaded  float
    resumed_without_operator  int
    silent_failures   int
    tracebacks_shown  int
    datasets_lost     int
"""

from __future__ import annotations

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
import time
from dataclasses import asdict, dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402  (sets one-thread environment before numpy loads)

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
from tests.helpers.faults import (  # noqa: E402
    alive,
    fsize_limit,
    has_traceback,
    mcap_opens,
    run_cli,
    small_disk,
    start_cli,
    wait_for_file,
    workers_of,
)

SIGNALS = (signal.SIGKILL, signal.SIGTERM, signal.SIGHUP)
LOST_EPS_S = 0.02  # below this a loss is rounding, not data
LOADS = {"quiet": 0, "loaded": 8}  # busy processes beside the record faults (common.Load)


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

    @property
    def silent(self) -> bool:
        return not self.announced and (self.lost_s > LOST_EPS_S or self.dataset_ok is False)


def started(path: Path, min_bytes: int, timeout: float) -> bool:
    """Whether the recording reached min_bytes in time (wait_for_file raises when it did not)."""
    from tests.helpers.wait import WaitTimeout

    try:
        wait_for_file(path, min_bytes, timeout=timeout)
    except WaitTimeout:
        return False
    return True


def one_line(run) -> bool:
    return run.returncode != 0 and len([x for x in run.stderr.splitlines() if x.strip()]) == 1


def info_announces(path: Path) -> tuple[bool, bool]:
    """(`teleprev info` exits non-zero with one line, it printed a traceback)."""
    run = run_cli(["info", path], timeout=120)
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


def record_signal(work: Path, k: int, sig: int, after_s: float) -> Row:
    out = work / f"rec_sig{k}.mcap"
    proc = start_cli(RECORD + ["-o", out])
    try:
        if not started(out, 150_000, timeout=120):
            proc.kill()
            return Row("record", f"{sig.name} (never started)", proc.wait(), traceback=True)
        time.sleep(after_s)
        sent_ns = time.time_ns()
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    row = Row("record", f"{sig.name} at {after_s:.2f} s", proc.returncode, traceback=has_traceback(stdout + stderr))
    final = out
    if sig == signal.SIGKILL:
        row.announced, tb = info_announces(out)
        row.traceback |= tb
        final = work / f"rec_sig{k}.recovered.mcap"
        run = run_cli(["recover", out, "-o", final], timeout=120)
        row.traceback |= has_traceback(run.stdout + run.stderr)
    else:
        row.announced = proc.returncode == 128 + sig
    row.opens = mcap_opens(final)
    end = last_log_ns(final) if final.exists() else None
    row.lost_s = max(0.0, (sent_ns - end) / 1e9) if end is not None else float("inf")
    return row


def record_full_disk(work: Path, k: int, size: int) -> Row:
    with small_disk(work / f"disk{k}", size) as (disk, preexec):
        out = disk / "x.mcap"
        limit = size if preexec is not None else None
        proc = start_cli(RECORD + ["-o", out], preexec_fn=preexec)
        full_ns = None
        try:
            while proc.poll() is None:  # the moment the file reaches the disk's size: the disk is full
                if full_ns is None and out.exists():
                    st = os.statvfs(disk)
                    if (limit is not None and out.stat().st_size >= limit - 65536) or \
                            (limit is None and st.f_bavail * st.f_frsize < 65536):
                        full_ns = time.time_ns()
                time.sleep(0.005)
            stdout, stderr = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
        row = Row(
            "record",
            f"full disk at {size // 1000} kB",
            proc.returncode,
            announced=one_line(proc_result(proc, stderr)),
            traceback=has_traceback(stdout + stderr),
        )
        saved = work / f"disk{k}.recovered.mcap"
        run = run_cli(["recover", out, "-o", saved], timeout=120)
        row.traceback |= has_traceback(run.stdout + run.stderr)
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


def input_loss(work: Path, k: int, loss: str, lost_s: float, load: str) -> Row:
    """`record` on a VMC rig, engaged; `loss` ("silent", "nan") for lost_s seconds, 2.5 s into the recording."""
    from tests.helpers.ports import free_port
    from tests.helpers.vmc import rig_text

    port = free_port()
    rig = work / f"vmc{k}.toml"
    rig.write_text(rig_text(port))
    out = work / f"loss{k}.mcap"
    lossy = _LossySender(port).sender.start(rate_hz=60.0)
    proc = start_cli(["record", rig, "--duration", "6", "--no-preview", "--engage-after", "0.5", "-o", out])
    try:
        if not started(out, 100_000, timeout=120):
            proc.kill()
            return Row("input", f"{loss} {lost_s:.1f} s {load} (never started)", proc.wait(), traceback=True)
        time.sleep(2.5)
        lossy.loss = loss
        lost_ns = time.time_ns()
        time.sleep(lost_s)
        lossy.loss = ""
        back_ns = time.time_ns()
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        lossy.stop()
        if proc.poll() is None:
            proc.kill()
    row = Row("input", f"{loss} {lost_s:.1f} s {load}", proc.returncode, traceback=has_traceback(stdout + stderr))
    row.opens = mcap_opens(out)
    if lost_s > 1.0:  # past the default bound: nothing moves until an operator engages
        moved = commands_moved_after(out, back_ns + 300_000_000)
        row.resumed_without_operator = moved and not engaged_after(out, lost_ns)
    return row


def frozen_record(work: Path, k: int, frozen_s: float, load: str) -> Row:
    out = work / f"frozen{k}.mcap"
    proc = start_cli(["record", "--duration", "6", "--no-preview", "--engage-after", "0.3", "-o", out])
    try:
        if not started(out, 150_000, timeout=120):
            proc.kill()
            return Row("freeze", f"SIGSTOP {frozen_s:.1f} s {load} (never started)", proc.wait(), traceback=True)
        time.sleep(1.5)
        proc.send_signal(signal.SIGSTOP)
        stopped_ns = time.time_ns()
        time.sleep(frozen_s)
        proc.send_signal(signal.SIGCONT)
        cont_ns = time.time_ns()
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    row = Row("freeze", f"SIGSTOP {frozen_s:.1f} s {load}", proc.returncode, traceback=has_traceback(stdout + stderr))
    row.opens = mcap_opens(out)
    moved = commands_moved_after(out, cont_ns + 300_000_000)
    row.resumed_without_operator = moved and not engaged_after(out, stopped_ns)
    return row


def proc_result(proc, stderr: str):
    return subprocess.CompletedProcess(proc.args, proc.returncode, "", stderr)


def device_dies(work: Path, k: int, clip_s: float) -> Row:
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
    run = run_cli(
        [
            "record",
            folder / "rig.toml",
            "--duration",
            str(clip_s + 2.5),
            "--no-preview",
            "--engage-after",
            "0.3",
            "-o",
            out,
        ],
        timeout=180,
    )
    row = Row(
        "record",
        f"camera clip ends after {clip_s:.1f} s",
        run.returncode,
        traceback=has_traceback(run.stdout + run.stderr),
    )
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
    row.announced = run.returncode == 0 and clip is not None and marked
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
    stdout, stderr = proc.communicate(timeout=60)
    row = Row("recover", f"{sig.name} at {after_s:.2f} s", proc.returncode, traceback=has_traceback(stdout + stderr))
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
    try:
        stdout, stderr = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        proc.kill()
        stdout, stderr = proc.communicate()
    deadline = time.monotonic() + 5
    while any(alive(p) for p in children) and time.monotonic() < deadline:
        time.sleep(0.05)
    outlived = [p for p in children if alive(p)]
    for p in outlived:
        os.kill(p, signal.SIGKILL)
    row = Row("export", f"{sig.name} at {after_s:.1f} s, -j {workers}", proc.returncode,
              traceback=has_traceback(stdout + stderr))
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


def export_full_disk(work: Path, k: int, base: Path, session: Path) -> Row:
    with small_disk(work / f"xdisk{k}", 40_000_000) as (disk, preexec):
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
    info = run_cli(["info", path], timeout=120)
    row = Row("file", detail, info.returncode, traceback=has_traceback(info.stdout + info.stderr))
    row.announced = one_line(info)
    if info.returncode == 0:  # info found nothing wrong: then what is read back must be the recording
        row.announced = same_messages(clean, path)
    out = work / f"{kind}{k}.saved.mcap"
    run = run_cli(["recover", path, "-o", out], timeout=120)
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


# -- the matrix -------------------------------------------------------------------------------------------


def others(work: Path, n: dict, rng: random.Random, add, quick: bool) -> None:
    """The faults that run quiet only: a device dying, recover and export signals, export on a full disk,
    flipped bits and cuts."""
    ids = itertools.count(10_000)  # file names apart from the record faults'
    clean = work / "clean.mcap"
    run = run_cli(["record", "--duration", "3" if quick else "6", "--no-preview", "--engage-after", "0.5",
                   "-o", clean], timeout=180)
    assert run.returncode == 0, run.stderr
    from tests.helpers.faults import chunk_spans

    chunks = chunk_spans(clean)
    clean_times = message_times(clean)

    for k in range(n["device"]):
        add(device_dies(work, k, rng.uniform(1.0, 2.5)))
    cut = work / "cut.mcap"
    cut.write_bytes(clean.read_bytes()[: int(clean.stat().st_size * 0.9)])
    for k in range(n["recover_signal"]):
        for sig in (signal.SIGTERM,) if quick else SIGNALS:
            add(recover_signal(work, next(ids), cut, sig, rng.uniform(0.05, 1.2)))

    from teleprev.export.synthetic import EpisodeSpec, SyntheticSession, write_session

    short, long = (1.0, 2.0) if quick else (3.0, 6.0)
    s0 = write_session(work / "s0.mcap", SyntheticSession((EpisodeSpec("pour", short),), seed=1))
    s1 = write_session(work / "s1.mcap", SyntheticSession((EpisodeSpec("pour", long),), seed=2))
    s2 = write_session(work / "s2.mcap", SyntheticSession((EpisodeSpec("hang", long),), seed=3))
    base = work / "base"
    run = run_cli(["export", s0, "--repo-id", "bench/faults", "--root", base], timeout=600)
    assert run.returncode == 0, run.stderr
    t0 = time.monotonic()
    timing_root = work / "timing"
    shutil.copytree(base, timing_root)
    run = run_cli(["export", s1, s2, "--repo-id", "bench/faults", "--root", timing_root, "--append"], timeout=600)
    assert run.returncode == 0, run.stderr
    export_s = time.monotonic() - t0
    shutil.rmtree(timing_root)
    for k in range(n["export_signal"]):
        for sig in (signal.SIGHUP,) if quick else SIGNALS:
            workers = 2 if (next(ids) % 3 == 0) else 1
            add(export_signal(work, next(ids), base, [s1, s2], sig, rng.uniform(0.3, export_s * 1.1), workers, 1, 2))
    for k in range(n["export_disk"]):
        add(export_full_disk(work, k, base, s1))

    for kind in ("flip", "cut"):
        for k in range(n[kind]):
            add(damaged_file(work, k, clean, clean_times, chunks, kind, rng))
            for f in work.glob(f"{kind}{k}*"):
                f.unlink()



def main() -> None:
    p = common.parser(__doc__)
    p.add_argument("--seed", type=int, default=16)
    p.add_argument("--details", type=Path, help="write every fault's row to this JSON file")
    p.add_argument("--only", choices=("record", "input"), help="only these families, quiet and loaded (record: "
                   "signals and full disks; input: losses and freezes)")
    args = p.parse_args()
    rng = random.Random(args.seed)
    # --quick: every kind of fault once, each signal once (SIGKILL to record, SIGTERM to recover, SIGHUP to export),
    # quiet only; the input family: one long loss (NaN) and one freeze
    n = (
        dict(
            record_signal=1,
            full_disk=1,
            device=1,
            recover_signal=1,
            export_signal=1,
            export_disk=1,
            flip=2,
            cut=1,
            input=1,
        )
        if args.quick
        else dict(
            record_signal=8,
            full_disk=8,
            device=4,
            recover_signal=5,
            export_signal=3,
            export_disk=3,
            flip=100,
            cut=40,
            input=3,
        )
    )
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    rows: list[Row] = []

    def add(row: Row, load: str = "quiet") -> None:
        row.load = load
        rows.append(row)
        print(f"{len(rows):4d} {row.kind:8s} {row.detail:42s} exit {row.exit_code!s:5s} lost {row.lost_s:7.3f} s "
              f"opens {row.opens!s:5s} dataset {row.dataset_ok!s:5s} {'SILENT' if row.silent else ''}"
              f"{' TRACEBACK' if row.traceback else ''}", file=sys.stderr, flush=True)

    with tempfile.TemporaryDirectory(prefix="teleprev-faults-") as tmp:
        work = Path(tmp)
        for load, busy in LOADS.items() if not args.quick else [("quiet", 0)]:
            with common.Load(busy):
                if args.only in (None, "record"):
                    for k in range(n["record_signal"]):
                        for sig in (signal.SIGKILL,) if args.quick else SIGNALS:
                            add(record_signal(work, len(rows), sig, rng.uniform(0.5, 3.5)), load)
                    for k in range(n["full_disk"]):
                        add(record_full_disk(work, len(rows), rng.randrange(400_000, 2_500_000)), load)
                if args.only in (None, "input"):
                    for k in range(n["input"]):
                        losses = (("nan", 1.5),) if args.quick else \
                            (("silent", 0.4), ("nan", 0.4), ("silent", 1.5), ("nan", 1.5))
                        for loss, lost_s in losses:
                            add(input_loss(work, len(rows), loss, lost_s, load), load)
                        add(frozen_record(work, len(rows), 2.0, load), load)
        if args.only is None:
            others(work, n, rng, add, args.quick)

    finite = [r.lost_s for r in rows]

    figures = {
        "faults_run": len(rows),
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
        key = f"{r.kind} {what} {r.load}" if r.kind in ("record", "input", "freeze") else f"{r.kind} {what}"
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
    targets = {"faults_run": ">= 200", "data_lost_s_max": "<= 1.0 (flips and cuts: beyond the damaged range)",
               "silent_failures": "0", "tracebacks_shown": "0", "datasets_lost": "0", "resumed_without_operator": "0",
               **{f"data_lost_s_max_{load}": "<= 1.0" for load in LOADS}}
    common.report("bench/faults.py: the fault matrix on the real CLI", figures, targets, args.json)


if __name__ == "__main__":
    main()
