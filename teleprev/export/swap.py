"""Putting a finished dataset in place of an existing one atomically, and cleaning up after exports that
were killed.

On Linux the new folder and the old one trade places in one system call (renameat2 with
RENAME_EXCHANGE): at every instant the target is either the whole old dataset or the whole new one.
Where the file system cannot exchange (or off Linux), a journal in the staging folder records the two
renames (old out, new in) before they happen; a kill between them leaves the old dataset in the
staging folder and the journal saying where it belongs, and the next export to that target puts it
back before it does anything else.

A staging folder (`.<target name>.export-*`) carries an `owner` file naming the process that made it
(pid and start time, so a reused pid is not mistaken for it); one whose owner is gone was left by a
killed export, and is removed by the next export to the same target.
"""

from __future__ import annotations

import ctypes
import errno
import os
import shutil
import sys
import time
from pathlib import Path

OWNER = "owner"
JOURNAL = "journal"
PREVIOUS = "previous"  # the old dataset, while the journal's swap is under way
FAULT_ENV = "TELEPREV_FAULT_EXPORT_COMMIT"  # drills: "exchange" | "journal": die at that scheme's riskiest point
_AT_FDCWD = -100
_RENAME_EXCHANGE = 2
_NO_OWNER_GRACE_S = 60.0  # a folder without an owner file may be one being created right now


def staging_prefix(target: Path) -> str:
    return f".{target.name}.export-"


def process_identity(pid: int | None = None) -> str:
    """"pid starttime" (the start time from /proc, so that a reused pid reads as another process)."""
    pid = os.getpid() if pid is None else pid
    return f"{pid} {_start_time(pid)}"


def _start_time(pid: int) -> str:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        return stat.rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return "?"


def _owner_alive(identity: str) -> bool:
    try:
        pid_text, start = identity.split()
        pid = int(pid_text)
        os.kill(pid, 0)
    except (ValueError, ProcessLookupError):
        return False
    except PermissionError:
        return True  # someone else's live process
    return start == "?" or _start_time(pid) in (start, "?")


def claim(folder: Path) -> None:
    """Mark a new staging folder as this process's."""
    (folder / OWNER).write_text(process_identity())


def exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (renameat2 RENAME_EXCHANGE); False where the system or the file system
    cannot, in which case nothing happened."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP):
        return False
    raise OSError(code, os.strerror(code), str(b))


def replace_dir(new: Path, target: Path, staging: Path) -> None:
    """Put the folder `new` at `target`, which exists: after this returns the old dataset is somewhere
    inside `staging` (to be removed with it); if the process dies inside, `recover_stale` finishes or
    undoes what was started."""
    scheme = os.environ.get(FAULT_ENV, "")
    if scheme != "journal" and exchange(new, target):
        _sync_dir(target.parent)
        if scheme == "exchange":
            _die()
        return
    journal = staging / JOURNAL
    journal.write_text(f"{target}\n")
    _fsync(journal)
    os.rename(target, staging / PREVIOUS)
    if scheme == "journal":
        _die()
    os.rename(new, target)
    _sync_dir(target.parent)
    journal.unlink()


def clean_stale(target: Path) -> list[str]:
    """Remove the staging folders of killed exports to `target`, putting back an old dataset that a
    swap was interrupted in; what was done, one line each."""
    done = []
    parent = target.parent
    if not parent.is_dir():
        return done
    for folder in sorted(parent.glob(staging_prefix(target) + "*")):
        if not folder.is_dir() or not _stale(folder):
            continue
        journal, previous = folder / JOURNAL, folder / PREVIOUS
        if journal.exists() and previous.is_dir() and not target.exists():
            os.rename(previous, target)
            _sync_dir(parent)
            done.append(f"put the dataset back at {target} from {folder.name} (an export was killed while "
                        "replacing it)")
        shutil.rmtree(folder, ignore_errors=True)
        done.append(f"removed {folder.name}, left by a killed export")
    return done


def _stale(folder: Path) -> bool:
    owner = folder / OWNER
    try:
        identity = owner.read_text().strip()
    except OSError:
        try:
            return time.time() - folder.stat().st_mtime > _NO_OWNER_GRACE_S
        except OSError:
            return False
    return not _owner_alive(identity)


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _sync_dir(path: Path) -> None:
    try:
        _fsync(path)
    except OSError:
        pass  # not every file system lets a folder be fsynced


def _die() -> None:
    import signal

    os.kill(os.getpid(), signal.SIGKILL)
