"""Ctrl-C at any moment of a command's start-up stops it: one line, exit 130 (record: the signal's own
status), no traceback, nothing engaged, and a session file that was opened is finalized.

The interrupt is sent by the child itself at a chosen point (an import, the pipeline's build, the wait for
the devices), so the moment is exact however busy the machine is. A KeyboardInterrupt raised where Python
cannot propagate it (a `__del__`, as numba's loading of its runtime has) is lost: the command must still stop.
"""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest

from teleprev import topics
from tests.helpers.faults import ROOT, _env, has_traceback, mcap_opens

# A finder that interrupts the process while teleprev.cli.replay is being imported (app imports it).
INTERRUPT_AN_IMPORT = """
import os, signal, sys
class Interrupt:
    def find_spec(self, name, path=None, target=None):
        if name == "teleprev.cli.replay":
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000): pass  # the handler runs here, inside the import
        return None
sys.meta_path.insert(0, Interrupt())
"""

# SIGINT delivered inside a __del__: Python prints "Exception ignored" and drops the KeyboardInterrupt.
LOSE_AN_INTERRUPT = """
import os, signal
class Lost:
    def __del__(self):
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(1000): pass
def interrupted_in(module, name):
    import importlib
    owner, attr = name.rsplit(".", 1) if "." in name else (None, name)
    mod = importlib.import_module(module)
    holder = getattr(mod, owner) if owner else mod
    original = getattr(holder, attr)
    def wrapped(*args, **kwargs):
        Lost()  # made and dropped at once: its __del__ runs here
        return original(*args, **kwargs)
    setattr(holder, attr, wrapped)
"""


def run_child(code: str, args: list[str], timeout: float = 90.0) -> subprocess.CompletedProcess:
    program = code + "\nfrom teleprev.cli.app import main; main()\n"
    return subprocess.run([sys.executable, "-c", program, *map(str, args)], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout, env=_env(None))


def test_ctrl_c_while_imports_run_is_one_line_and_130():
    ran = run_child(INTERRUPT_AN_IMPORT, ["info", "--help"])
    assert ran.returncode == 130, (ran.returncode, ran.stderr)
    assert not has_traceback(ran.stderr), ran.stderr
    assert ran.stderr.strip() == "interrupted"


@pytest.mark.parametrize("module, where", [
    ("teleprev.live.record.session", "build_pipeline"),  # the kernels load while the session is made
    ("teleprev.live.record.session", "LiveSession.wait_connected"),  # the devices start
])
def test_record_interrupted_in_start_up_stops_and_never_engages(tmp_path, module, where):
    out = tmp_path / "s.mcap"
    code = LOSE_AN_INTERRUPT + f"\ninterrupted_in({module!r}, {where!r})\n"
    ran = run_child(code, ["record", "--duration", "4", "--engage-after", "0", "--no-preview", "--out", out])
    assert ran.returncode == 128 + signal.SIGINT, (ran.returncode, ran.stdout[-2000:], ran.stderr)
    # the only traceback is Python's note of the interrupt it lost ("Exception ignored in: ... __del__")
    assert ran.stderr.count("Traceback") == ran.stderr.count("Exception ignored in"), ran.stderr
    assert out.exists() and mcap_opens(out), "the session file is not finalized"
    from teleprev.session.reader import SessionReader

    with SessionReader(out) as reader:
        has_modes = topics.MODE in reader.topics
        modes = [m.payload.data["mode"] for m in reader.messages([topics.MODE])] if has_modes else []
    assert "execute" not in modes, modes


def test_a_ctrl_c_after_a_lost_one_still_interrupts(monkeypatch):
    import os

    from teleprev.cli import signals as stop

    monkeypatch.setattr(stop, "LOST_AFTER_S", 0.05)
    with stop.StopSignals() as signals:
        try:
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):
                pass
        except KeyboardInterrupt:
            pass  # what a callback that swallows it does
        assert signals.pending
        with pytest.raises(KeyboardInterrupt):
            signals.check()
        import time

        time.sleep(0.06)
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):
                pass
        with signals.finishing():
            os.kill(os.getpid(), signal.SIGTERM)  # noted only
            for _ in range(1000):
                pass
    assert signals.received == signal.SIGINT and signals.later == 2


# SIGTERM or SIGHUP sent by the child itself, raised where it is sent (not lost), when `name` is called.
SIGNAL_AT_A_CALL = """
import importlib, os, signal
def signalled_in(module, name, sig):
    owner, attr = name.rsplit(".", 1) if "." in name else (None, name)
    mod = importlib.import_module(module)
    holder = getattr(mod, owner) if owner else mod
    original = getattr(holder, attr)
    def wrapped(*args, **kwargs):
        os.kill(os.getpid(), sig)
        for _ in range(1000): pass  # the handler runs here
        return original(*args, **kwargs)
    setattr(holder, attr, wrapped)
"""


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["sigterm", "sighup"])
def test_a_stop_signal_while_imports_run_is_one_line(sig):
    ran = run_child(INTERRUPT_AN_IMPORT.replace("signal.SIGINT", f"signal.{sig.name}"), ["info", "--help"])
    assert ran.returncode == 128 + sig, (ran.returncode, ran.stderr)
    assert ran.stderr.strip() == f"stopped by {sig.name}"


FIXTURE = ROOT / "tests" / "fixtures" / "sim_v2.mcap"


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=["sigint", "sigterm", "sighup"])
@pytest.mark.parametrize("args, module, where", [
    (["eval", FIXTURE, "--out", "{tmp}/report.json"], "teleprev.evaluation.corpus", "evaluate_corpus"),
    (["audit", FIXTURE, "--json", "{tmp}/audit.json"], "teleprev.evaluation.audit", "audit_path"),
    (["info", FIXTURE], "teleprev.session.summary", "summarize"),
], ids=["eval", "audit", "info"])
def test_a_stop_signal_during_a_command_is_one_line_and_writes_nothing(tmp_path, sig, args, module, where):
    """A command without clean-up of its own: SIGTERM and SIGHUP stop it as Ctrl-C does (one line, exit
    128 + the signal), not a death without a word, and Ctrl-C says "interrupted" (typer's exit 130 said
    nothing); what it would have written is not half there."""
    code = SIGNAL_AT_A_CALL + f"\nsignalled_in({module!r}, {where!r}, signal.{sig.name})\n"
    ran = run_child(code, [str(a).format(tmp=tmp_path) for a in args])
    assert ran.returncode == 128 + sig, (ran.returncode, ran.stdout[-2000:], ran.stderr)
    assert not has_traceback(ran.stdout + ran.stderr), ran.stderr
    assert ran.stderr.strip() == ("interrupted" if sig == signal.SIGINT else f"stopped by {sig.name}"), ran.stderr
    assert list(tmp_path.iterdir()) == []
