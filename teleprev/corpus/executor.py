"""Run one function per session, each session a task of its own: in local worker processes, or on a
Ray cluster.

    fn(context, item, emit) -> value        a module-level function (both executors ship it by name);
                                            `context` is what every task shares, `item` one session's
                                            input, `emit(event)` sends progress back (local workers only)

A task that raises is reported failed with its message (a TeleprevError keeps its class, message and
place) and is not tried again: the same input would fail the same way. A worker that *dies* under a
task (a crash in a decoder, the OOM killer, a lost node) is different: the task is run once more, on
a fresh worker, and reported failed only if that one dies too. Neither stops the other sessions.

Local workers come from a fork server that imports `preload` once (lerobot takes seconds to import),
and each talks to the parent over its own pipe, so the parent always knows which session a worker held
when it died, and a dying worker cannot leave a shared queue locked. Ray is imported only inside
RayExecutor, so the core installs and runs without it (`uv sync --extra ray` adds it).

Fault injection, for tests and drills: TELEPREV_FAULT_WORKER_EXIT="a.mcap,b.mcap@1" makes the worker
running a.mcap exit abruptly (os._exit) on every attempt and the one running b.mcap on its first attempt
only. The driver reads it and ships it with each task, so workers on other machines see it too.
"""

from __future__ import annotations

import os
import signal
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from teleprev.errors import ConfigError, TeleprevError

FAULT_ENV = "TELEPREV_FAULT_WORKER_EXIT"
FAULT_EXIT_CODE = 70
MAX_ATTEMPTS = 2  # a task whose worker died is run once more
RAY_MISSING = "--ray needs Ray, an optional extra: run `uv sync --extra ray` (or `pip install 'teleprev[ray]'`)"

Emit = Callable[[Any], None]


@dataclass
class Outcome:
    """One task's result: `value` when it succeeded, else `error` (and `kind`: the TeleprevError class
    name, "died" when its worker died on every attempt, "" for any other exception)."""

    index: int
    label: str
    value: Any = None
    error: str = ""
    kind: str = ""
    where: str | None = None
    attempts: int = 1

    @property
    def ok(self) -> bool:
        return not self.error

    def exception(self) -> TeleprevError:
        from teleprev import errors

        cls = getattr(errors, self.kind, None)
        if isinstance(cls, type) and issubclass(cls, TeleprevError):
            return cls(self.error, self.where)
        from teleprev.errors import SessionError

        return SessionError(self.error, self.where or self.label)


def fault_plan(text: str | None = None) -> dict[str, int]:
    """{file name: attempts on which its worker exits} from TELEPREV_FAULT_WORKER_EXIT."""
    text = os.environ.get(FAULT_ENV, "") if text is None else text
    plan = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        name, _, times = part.partition("@")
        plan[name] = int(times) if times else MAX_ATTEMPTS
    return plan


def run_task(
    fn: Callable, context: Any, item: Any, label: str, attempt: int, faults: dict[str, int], emit: Emit
) -> tuple:
    """One task inside a worker, as both executors run it: ("done", value) or ("error", kind, message, where)."""
    if attempt <= faults.get(Path(label).name, 0):
        os._exit(FAULT_EXIT_CODE)  # the injected fault: the worker vanishes mid-task, as a crash would
    try:
        return ("done", fn(context, item, emit))
    except TeleprevError as exc:
        return ("error", type(exc).__name__, exc.message, exc.where)
    except Exception as exc:  # a bug or an unexpected input: still this session's failure only
        return ("error", "", f"{type(exc).__name__}: {exc}", label)


def _ignore(event: Any) -> None:
    pass


# -- local worker processes ------------------------------------------------------------------------


def die_with_parent() -> None:
    """Ask the kernel to SIGKILL this process when its parent exits (Linux's PR_SET_PDEATHSIG)."""
    import sys

    if not sys.platform.startswith("linux"):
        return
    parent = os.getppid()
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # the parent went before the request was made
        os._exit(1)


def _die_with(parent_pid: int) -> None:
    """A worker must never outlive the process that started it (it would go on writing into a staging
    folder nobody will commit): the kernel kills it when its parent, the fork server, dies (and the fork
    server when the driver does: teleprev.corpus.orphans, preloaded there), and a watchdog thread ends
    it if the driver is gone all the same (where there is no PR_SET_PDEATHSIG)."""
    import threading

    die_with_parent()

    def watch() -> None:
        while True:
            try:
                os.kill(parent_pid, 0)
            except ProcessLookupError:
                os._exit(1)
            except PermissionError:
                pass
            if os.getppid() == 1:  # the fork server is gone (and so, with it, the driver)
                os._exit(1)
            time.sleep(0.2)

    threading.Thread(target=watch, name="teleprev-parent-watch", daemon=True).start()


def _serve(conn, fn: Callable, context: Any, parent_pid: int | None = None) -> None:
    """A local worker: run the tasks the parent sends until it sends None."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and stops the workers
    if parent_pid is not None:
        _die_with(parent_pid)
    while True:
        try:
            task = conn.recv()
        except EOFError:
            return
        if task is None:
            return
        index, item, label, attempt, faults = task

        def emit(event, index=index):
            conn.send(("event", index, event))

        result = run_task(fn, context, item, label, attempt, faults, emit)
        conn.send((result[0], index, *result[1:]))


@dataclass
class _Slot:
    proc: Any
    conn: Any
    task: tuple[int, int] | None = None  # (index, attempt) it holds


class LocalExecutor:
    """`workers` processes on this machine, forked from a server that has imported `preload`."""

    name = "local"

    def __init__(self, workers: int, preload: list[str] | tuple[str, ...] = ()):
        if workers < 1:
            raise ConfigError(f"workers must be at least 1, got {workers}")
        self.workers = workers
        self.preload = list(preload)
        self.start_s = 0.0  # nothing to start until map()

    def _context(self):
        import multiprocessing as mp

        ctx = mp.get_context("forkserver")
        # takes effect when the server starts (once per process); orphans first: the server dies with us
        ctx.set_forkserver_preload(["teleprev.corpus.orphans", *self.preload])
        return ctx

    def start(self) -> None:
        """Start the fork server now rather than in map(): it imports `preload` (lerobot takes seconds) on
        another core while this process goes on, checking the sessions, say. Returns at once."""
        from multiprocessing import forkserver

        self._context()
        forkserver.ensure_running()

    def map(self, fn: Callable, context: Any, items: list, labels: list[str] | None = None,
            on_event: Emit = _ignore, on_done: Callable[[Outcome], None] = _ignore) -> list[Outcome]:
        """Run fn on every item; the outcomes in item order."""
        from multiprocessing.connection import wait

        labels = [str(i) for i in items] if labels is None else list(labels)
        if not items:
            return []
        faults = fault_plan()
        ctx = self._context()
        pending: deque[tuple[int, int]] = deque((i, 1) for i in range(len(items)))
        outcomes: dict[int, Outcome] = {}
        slots: list[_Slot] = []

        def start() -> _Slot:
            parent, child = ctx.Pipe()
            proc = ctx.Process(
                target=_serve, args=(child, fn, context, os.getpid()), name=f"teleprev-worker-{len(slots)}", daemon=True
            )
            proc.start()
            child.close()
            return _Slot(proc, parent)

        def finish(outcome: Outcome) -> None:
            outcomes[outcome.index] = outcome
            on_done(outcome)

        def died(slot: _Slot) -> None:
            if slot.task is None:
                return
            i, attempt = slot.task
            slot.task = None
            if attempt < MAX_ATTEMPTS:
                pending.appendleft((i, attempt + 1))
            else:
                code = slot.proc.exitcode
                finish(
                    Outcome(
                        i,
                        labels[i],
                        error=f"its worker died on each of {attempt} attempts (last exit code {code})",
                        kind="died",
                        where=labels[i],
                        attempts=attempt,
                    )
                )

        def read(slot: _Slot) -> bool:
            """Handle what the worker sent; False when its pipe is closed (the worker is gone)."""
            while slot.conn.poll():
                try:
                    msg = slot.conn.recv()
                except (EOFError, OSError):
                    return False
                kind, i = msg[0], msg[1]
                if kind == "event":
                    on_event(msg[2])
                    continue
                attempt = slot.task[1] if slot.task else 1
                slot.task = None
                if kind == "done":
                    finish(Outcome(i, labels[i], value=msg[2], attempts=attempt))
                else:
                    finish(Outcome(i, labels[i], error=msg[3], kind=msg[2], where=msg[4], attempts=attempt))
            return True

        try:
            slots = [start() for _ in range(min(self.workers, len(items)))]
            while len(outcomes) < len(items):
                for slot in slots:
                    if slot.task is None and pending:
                        slot.task = pending.popleft()
                        i, attempt = slot.task
                        try:
                            slot.conn.send((i, items[i], labels[i], attempt, faults))
                        except (BrokenPipeError, OSError):
                            pass  # it is dead: its sentinel says so below
                waiting = [s.conn for s in slots] + [s.proc.sentinel for s in slots]
                ready = set(wait(waiting, timeout=1.0))
                for k, slot in enumerate(slots):
                    alive = read(slot) if slot.conn in ready else True
                    if slot.proc.sentinel in ready or not alive or not slot.proc.is_alive():
                        read(slot)  # whatever it sent before it went
                        slot.proc.join(timeout=5)
                        died(slot)
                        slot.conn.close()
                        slots[k] = start()  # a fresh worker for the retry and the rest
            for slot in slots:
                try:
                    slot.conn.send(None)
                except (BrokenPipeError, OSError):
                    pass
            for slot in slots:
                slot.proc.join(timeout=10)
        finally:
            for slot in slots:
                if slot.proc.is_alive():
                    slot.proc.terminate()
            for slot in slots:
                slot.proc.join(timeout=10)
                slot.conn.close()
        return [outcomes[i] for i in range(len(items))]

    def close(self) -> None:
        pass


# -- Ray -------------------------------------------------------------------------------------------


def _ray_task(fn: Callable, context: Any, item: Any, label: str, attempt: int, faults: dict[str, int]) -> tuple:
    return run_task(fn, context, item, label, attempt, faults, _ignore)


class RayExecutor:
    """Tasks on a Ray cluster: `address` None or "local" starts a local instance (with `cpus` CPUs,
    default all), else connects to one ("auto", "HOST:PORT", "ray://HOST:PORT"). An instance that is
    already initialised in this process (ray.init by the caller) is used as it is and left running.

    Each task asks for one CPU; Ray keeps a worker process per CPU and reuses it, so a worker imports
    teleprev (and lerobot, for export) once. Paths travel as absolute paths: every node must see the
    sessions and the output folder at the same place (a shared filesystem)."""

    name = "ray"

    def __init__(self, address: str | None = None, cpus: int | None = None):
        started = time.perf_counter()
        try:
            import ray
        except ImportError:
            raise ConfigError(RAY_MISSING) from None
        self.ray = ray
        self.owned = not ray.is_initialized()
        if self.owned:
            common = dict(include_dashboard=False, logging_level="ERROR", log_to_driver=False)
            try:
                if address in (None, "", "local"):
                    ray.init(address="local", num_cpus=cpus, **common)
                else:
                    ray.init(address=address, **common)
            except ConnectionError as exc:
                raise ConfigError(f"cannot reach the Ray cluster: {exc}", address) from None
        self.workers = max(1, int(ray.cluster_resources().get("CPU", 1)))
        self.start_s = time.perf_counter() - started

    def map(self, fn: Callable, context: Any, items: list, labels: list[str] | None = None,
            on_event: Emit = _ignore, on_done: Callable[[Outcome], None] = _ignore) -> list[Outcome]:
        ray = self.ray
        from ray.exceptions import RayError, RayTaskError

        labels = [str(i) for i in items] if labels is None else list(labels)
        if not items:
            return []
        faults = fault_plan()
        remote = ray.remote(_ray_task).options(num_cpus=1, max_retries=0)  # retries are ours: the same rule as local
        shared = ray.put(context)
        running: dict[Any, tuple[int, int]] = {}

        def submit(i: int, attempt: int) -> None:
            running[remote.remote(fn, shared, items[i], labels[i], attempt, faults)] = (i, attempt)

        outcomes: dict[int, Outcome] = {}

        def finish(outcome: Outcome) -> None:
            outcomes[outcome.index] = outcome
            on_done(outcome)

        try:
            for i in range(len(items)):
                submit(i, 1)
            while running:
                done, _ = ray.wait(list(running), num_returns=1)
                for ref in done:
                    i, attempt = running.pop(ref)
                    try:
                        result = ray.get(ref)
                    except RayTaskError as exc:  # the task itself raised past run_task (e.g. unpicklable)
                        finish(Outcome(i, labels[i], error=str(exc).splitlines()[0], where=labels[i], attempts=attempt))
                        continue
                    except RayError as exc:  # the worker (or its node) died under the task
                        if attempt < MAX_ATTEMPTS:
                            submit(i, attempt + 1)
                        else:
                            finish(Outcome(i, labels[i], error=f"its worker died on each of {attempt} attempts "
                                           f"({type(exc).__name__})", kind="died", where=labels[i], attempts=attempt))
                        continue
                    if result[0] == "done":
                        finish(Outcome(i, labels[i], value=result[1], attempts=attempt))
                    else:
                        finish(
                            Outcome(i, labels[i], error=result[2], kind=result[1], where=result[3], attempts=attempt)
                        )
        finally:
            for ref in running:
                ray.cancel(ref, force=True)
        return [outcomes[i] for i in range(len(items))]

    def start(self) -> None:
        """Nothing: the instance is started or joined by __init__."""

    def close(self) -> None:
        if self.owned and self.ray.is_initialized():
            self.ray.shutdown()


def make_executor(workers: int = 1, ray: str | None = None, preload: list[str] | tuple[str, ...] = ()):
    """The executor a command's options ask for: Ray when `ray` is given ("local" for a new local
    instance with `workers` CPUs when more than 1), else `workers` local processes."""
    if ray is not None:
        local = ray in ("", "local")
        return RayExecutor(ray, cpus=workers if local and workers > 1 else None)
    return LocalExecutor(workers, preload)
