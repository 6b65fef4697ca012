"""Real faults for tests and bench/faults.py: a disk that fills up, the CLI in a subprocess, signals.

A full disk is a small tmpfs mounted for the test where this machine allows it (root, and mount
permitted), else a file-size limit (RLIMIT_FSIZE) on the child process, whose writes then fail with
EFBIG once a file reaches the limit (SIGXFSZ is ignored in the child so that it sees the error).
"""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

from tests.helpers.wait import WaitTimeout, wait_until

ROOT = Path(__file__).resolve().parents[2]
TELEPREV = [sys.executable, "-c", "from teleprev.cli.app import main; main()"]


@contextmanager
def small_disk(parent: Path, size_bytes: int):
    """(folder, preexec_fn): a folder on which a child process runs out of space after about
    `size_bytes`. preexec_fn is None when the folder is a real small tmpfs."""
    folder = Path(parent) / "small_disk"
    folder.mkdir(parents=True, exist_ok=True)
    mounted = False
    if os.geteuid() == 0:
        size_kib = max(64, size_bytes // 1024)
        mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kib}k", "tmpfs", str(folder)],
                                 capture_output=True).returncode == 0
    try:
        yield folder, (None if mounted else fsize_limit(size_bytes))
    finally:
        if mounted:
            subprocess.run(["umount", "-l", str(folder)], capture_output=True)


def fsize_limit(size_bytes: int):
    def preexec():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (size_bytes, size_bytes))

    return preexec


def run_cli(args: list[str], *, cwd: Path | None = None, preexec_fn=None, timeout: float = 120.0,
            env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(TELEPREV + [str(a) for a in args], cwd=cwd or ROOT, capture_output=True, text=True,
                          timeout=timeout, preexec_fn=preexec_fn, env=_env(env))


def start_cli(args: list[str], *, cwd: Path | None = None, preexec_fn=None, env: dict | None = None,
              new_session: bool = False) -> subprocess.Popen:
    return subprocess.Popen(TELEPREV + [str(a) for a in args], cwd=cwd or ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, preexec_fn=preexec_fn, env=_env(env),
                            start_new_session=new_session)


def _env(extra: dict | None) -> dict:
    env = dict(os.environ)
    env.setdefault("COLUMNS", "200")
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.update(extra or {})
    return env


def wait_for_file(path: Path, min_bytes: int = 1, timeout: float = 60.0) -> None:
    wait_until(lambda: path.exists() and path.stat().st_size >= min_bytes, timeout,
               what=f"{path} to hold {min_bytes} bytes", poll_s=0.02)


def has_traceback(text: str) -> bool:
    return "Traceback (most recent call last)" in text


def descendants(pid: int) -> set[int]:
    """Every process below `pid` (children, their children, ...), from /proc."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        children.setdefault(ppid, []).append(int(entry.name))
    out, todo = set(), [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            if c not in out:
                out.add(c)
                todo.append(c)
    return out


def workers_of(pid: int) -> set[int]:
    """The processes below `pid` that run teleprev's work: every descendant but multiprocessing's
    resource tracker (it holds no task and ends when the last process using it has gone)."""
    out = set()
    for p in descendants(pid):
        try:
            cmdline = Path(f"/proc/{p}/cmdline").read_bytes()
        except OSError:
            continue
        if b"resource_tracker" not in cmdline:
            out.add(p)
    return out


def alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def survivors(pids: set[int], timeout_s: float = 3.0) -> list[int]:
    """Those of `pids` still alive after up to timeout_s (the kernel ends a killed parent's workers at once)."""
    try:
        wait_until(lambda: not any(alive(p) for p in pids), timeout_s, poll_s=0.05)
    except WaitTimeout:
        pass
    return [p for p in pids if alive(p)]


def chunk_spans(path: Path) -> list[tuple[int, int, int, int]]:
    """(offset, length, start_ns, end_ns) of every chunk record of a complete session, in file order."""
    from teleprev.session.reader import SessionReader

    with SessionReader(path) as reader:
        return sorted((c.offset, c.length, c.start_ns, c.end_ns) for c in reader._chunks)


def flip_byte(path: Path, offset: int, mask: int = 0xFF) -> None:
    with open(path, "r+b") as f:
        f.seek(offset)
        b = f.read(1)
        f.seek(offset)
        f.write(bytes([b[0] ^ mask]))


def damage_chunk(path: Path, index: int, where: float = 0.5) -> tuple[int, int]:
    """Flip one byte inside the compressed records of the index-th chunk (in file order), `where` of the
    way through them; returns the chunk's (start_ns, end_ns)."""
    offset, length, start, end = chunk_spans(path)[index]
    flip_byte(path, offset + 9 + 60 + int((length - 9 - 60) * where))  # past the chunk's header fields
    return start, end


def mcap_opens(path: Path) -> bool:
    """What `mcap doctor` checks, with the mcap library's own readers: every record of the file in order
    with chunk CRCs validated, then the summary and every message through the index."""
    from mcap.reader import make_reader
    from mcap.stream_reader import StreamReader

    try:
        with open(path, "rb") as f:
            for _ in StreamReader(f, validate_crcs=True).records:
                pass
        with open(path, "rb") as f:
            reader = make_reader(f, validate_crcs=True)
            if reader.get_summary() is None:
                return False
            for _ in reader.iter_messages(log_time_order=False):
                pass
        return True
    except Exception:
        return False
