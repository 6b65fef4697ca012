"""docs/writing-a-plugin.md runs as written: its glove plugin streams through DeviceRunner,
its entry point names that plugin, and its own test passes."""

from __future__ import annotations

import re
import sys
import time
import tomllib
import types
from pathlib import Path

import numpy as np

from teleprev.devices import DeviceContext, DeviceRunner, SessionClock, smplx

PAGE = Path(__file__).resolve().parents[2] / "docs" / "writing-a-plugin.md"


def page_blocks() -> list[tuple[str, str]]:
    """(language, code) of the page's fenced blocks, in order."""
    return re.findall(r"```(\w+)\n(.*?)```", PAGE.read_text(), flags=re.S)


def load_plugin_module(monkeypatch) -> types.ModuleType:
    """The page's plugin block, executed as the module `my_glove` it says it is."""
    lang, code = page_blocks()[0]
    assert lang == "python" and code.startswith("# my_glove.py")
    assert len(code.strip().splitlines()) <= 40  # an example to read, not a library
    module = types.ModuleType("my_glove")
    monkeypatch.setitem(sys.modules, "my_glove", module)
    exec(compile(code, f"{PAGE}:my_glove.py", "exec"), module.__dict__)
    return module


def test_the_documented_glove_streams_hand_poses_through_the_runner(monkeypatch):
    my_glove = load_plugin_module(monkeypatch)
    clock, got = SessionClock(), []
    glove = my_glove.WaveGlove("right", my_glove.WaveSettings(rate_hz=50.0), DeviceContext(clock))
    runner = DeviceRunner(glove, lambda sample, receive_ns: got.append(sample), clock).start()
    time.sleep(0.5)
    runner.stop()
    samples = [s for s in got if s.topic == "/glove/right/hand"]
    assert 20 <= len(samples) <= 30
    stamps = np.array([s.payload.stamp_ns for s in samples])
    assert np.all(np.diff(stamps) == 20_000_000)  # stamped at acquisition, on the session clock
    assert samples[-1].payload.names == smplx.HAND_POSE_NAMES and samples[-1].payload.positions.shape == (45,)
    assert runner.stats().errors == 0 and runner.stats().sink_errors == 0


def test_the_documented_entry_point_rig_and_test_fit_the_plugin(monkeypatch):
    my_glove = load_plugin_module(monkeypatch)
    blocks = page_blocks()
    tomls = [tomllib.loads(code) for lang, code in blocks if lang == "toml"]
    (name, target), = tomls[0]["project"]["entry-points"]["teleprev.devices"].items()
    module, cls = target.split(":")
    assert module == "my_glove" and getattr(my_glove, cls).kind == name.split(".")[1]
    rig = tomls[1]["devices"]["glove"]
    assert rig.pop("plugin") == name
    my_glove.WaveSettings(**rig)  # the rig's keys are the settings' keys

    lang, test_code = blocks[-1]
    assert lang == "python" and "DeviceRunner" in test_code
    namespace: dict = {}
    exec(compile(test_code, f"{PAGE}:test", "exec"), namespace)
    tests = [f for n, f in namespace.items() if n.startswith("test_")]
    assert tests
    for test in tests:
        test()
