"""What every bench script shares: one-thread setup, timing, and the table / JSON report.

Each script prints a table of its figures and, with --json, one JSON object last whose keys are the
figure names its issue gives. Medians and ratios come from one run, since these machines are noisy.

Every bench/*.py but this one is a bench, and every bench has a quick mode (--quick: seconds, not
minutes; fewer samples, shorter sessions, a token load) that the suite runs as `python bench/NAME.py
--quick --json` (tests/bench/test_quick.py, which finds the benches on disk). Each declares the figures it
always prints in its module docstring, in a section of its own, last:

    JSON keys:
        fk_single_us_p50        float
        collision_free_configs  int
        urdf_embedded           bool

The section starts at a line that reads exactly "JSON keys:"; each line after it, up to a blank line or
the docstring's end, is a key and its type (float, int, bool or str; a float key may hold a whole number,
an int key may not hold a bool). The suite fails the bench unless its quick run exits 0 and its last JSON
object holds every declared key with a value of that type, null for none of them and no NaN or infinity
anywhere. Figures a run prints only with some option (or that are per-item, named by the item) stay out
of the section; the prose above it says what each figure means.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import time

# One thread for numpy's BLAS and torch: the figures are per core.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")


KEY_TYPES = {"float": (int, float), "int": (int,), "bool": (bool,), "str": (str,)}


def declared_keys(docstring: str) -> dict[str, str]:
    """The keys of a bench docstring's "JSON keys:" section and their types' names (see the module
    docstring); a line that is not `key type` with a known type is a ValueError naming it."""
    lines = docstring.splitlines()
    starts = [k for k, line in enumerate(lines) if line.strip() == "JSON keys:"]
    if len(starts) != 1:
        raise ValueError(f'{len(starts)} "JSON keys:" sections, expected one')
    keys: dict[str, str] = {}
    for line in lines[starts[0] + 1:]:
        if not line.strip():
            break
        parts = line.split()
        if len(parts) != 2 or parts[1] not in KEY_TYPES:
            raise ValueError(f"JSON keys: {line.strip()!r} is not `key type` with a type of {sorted(KEY_TYPES)}")
        keys[parts[0]] = parts[1]
    if not keys:
        raise ValueError('the "JSON keys:" section names no key')
    return keys


def parser(description: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--json", action="store_true", help="print one JSON object with the figures last")
    p.add_argument("--quick", action="store_true", help="fewer samples, for a smoke run")
    return p


def _spin() -> None:
    # An ordinary process, whoever forks it: a fork keeps the forking thread's scheduling, and a spinner that
    # kept SCHED_FIFO 50 from a paced thread would hold a core against the command sender itself.
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    os.setpriority(os.PRIO_PROCESS, 0, 0)
    while True:
        pass


class Load:
    """`processes` busy processes (a spinning loop each) while inside the with block: the figures "with N
    busy processes beside it" that the issues ask for, made inside the bench. Each is an ordinary process
    (SCHED_OTHER, nice 0), as the load beside a session is, even when forked from a real-time thread."""

    def __init__(self, processes: int):
        import multiprocessing as mp

        self.procs = [mp.get_context("fork").Process(target=_spin, daemon=True) for _ in range(processes)]

    def __enter__(self) -> Load:
        for p in self.procs:
            p.start()
        return self

    def __exit__(self, *exc) -> None:
        self.resume()  # a stopped process does not act on SIGTERM until it runs again
        for p in self.procs:
            p.terminate()
        for p in self.procs:
            p.join()

    def pause(self) -> None:
        """Stop the busy processes (SIGSTOP) until resume(): for the parts of a loaded run that are not what
        it measures (a command's start-up, the checks after it)."""
        self._signal(signal.SIGSTOP)

    def resume(self) -> None:
        self._signal(signal.SIGCONT)

    @contextlib.contextmanager
    def paused(self):
        self.pause()
        try:
            yield
        finally:
            self.resume()

    def _signal(self, sig: int) -> None:
        for p in self.procs:
            if p.pid is not None and p.exitcode is None:
                os.kill(p.pid, sig)


def steal_ms() -> float | None:
    """The hypervisor's steal time so far, all CPUs (/proc/stat): CPU time the host gave to other machines
    while this one wanted it. No priority inside the machine wins it back, so the benches print it beside
    their timing figures. None where the kernel does not count it."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
        return int(fields[8]) * 1000.0 / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def time_calls(fn, args_list, repeat: int = 1) -> list[float]:
    """Seconds per call of fn(*args) for each args in args_list (best of `repeat` per item)."""
    out = []
    for args in args_list:
        best = float("inf")
        for _ in range(repeat):
            t = time.perf_counter()
            fn(*args)
            best = min(best, time.perf_counter() - t)
        out.append(best)
    return out


def percentile(values, q: float) -> float:
    import numpy as np

    return float(np.percentile(np.asarray(values), q))


def report(title: str, figures: dict, targets: dict | None = None, as_json: bool = False) -> None:
    """Print the figures as a table (with the issue's target where there is one), then JSON if asked."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    targets = targets or {}
    table = Table(title=title, title_justify="left")
    table.add_column("figure")
    table.add_column("value", justify="right")
    table.add_column("target")
    for key, value in figures.items():
        shown = f"{value:.4g}" if isinstance(value, float) else str(value)
        table.add_row(escape(key), escape(shown), escape(targets.get(key, "")))
    Console(stderr=as_json).print(table)
    if as_json:
        # a figure a run could not measure is null, not NaN (which strict JSON readers refuse)
        print(json.dumps({k: None if isinstance(v, float) and v != v else v for k, v in figures.items()}))
