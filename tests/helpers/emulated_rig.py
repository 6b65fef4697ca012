"""The default sim rig with the emulated xArm controller and LEAP Hand bus in place of the sim arm and hand:
the simulated operator drives the real plugins and SDKs (tests/live/test_wire_process.py, bench/hardware.py).
The emulators stand for hardware outside this machine: each runs in a real-time process of its own, below
the command path's priority, so that the machine's load delays the commands, not the emulator's replies
and the stamping of their arrival.

    box = EmulatorProcess(lambda: XArmController(host=None), "arm", box_summary)
    bus = EmulatorProcess(DynamixelBus, "hand", bus_summary)
    rig.write_text(sim_operator_rig(box.keys, bus.keys, camera=False))
    ...                                       # record
    arm, hand = box.finish(), bus.finish()    # what the emulators saw

A test that acts on an emulator while the session runs asks it: `box.ask(command_count)` runs the module-level
function `command_count(emulator)` in the emulator's process and returns what it returns.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import re

import numpy as np

from teleprev.rig import default_rig_path


def _section(text: str, name: str, replacement: str) -> str:
    """`text` with the TOML table [name] (up to the next table or comment block) replaced."""
    return re.sub(rf"\[{re.escape(name)}\].*?(?=\n\[|\n#|\Z)", replacement.rstrip("\n"), text, count=1, flags=re.S)


def sim_operator_rig(arm_keys: str, hand_keys: str, camera: bool = True) -> str:
    text = _section(default_rig_path().read_text(), "devices.arm", arm_keys)
    text = _section(text, "devices.hand", hand_keys)
    if not camera:
        text = _section(_section(text, "devices.cam_front", ""), "frames.cam_front", "")
    return text


def box_summary(box) -> dict:
    """The servo targets as the controller received and judged them, its faults, the registers it lacks."""
    return {"arrivals": [(a.received_ns, int(a.cycle), bool(a.taken), np.asarray(a.target, float).tolist())
                         for a in box.arrivals],
            "judged": [(j.speed_ratio, j.accel_ratio, j.jerk_ratio) for j in box.judged],
            "faults": [what for _, what, _ in box.faults], "unknown": dict(box.unknown), "commands": len(box.commands)}


def bus_summary(bus) -> dict:
    return {"goal_writes": bus.goal_writes, "corrupt_requests": bus.corrupt_requests}


# Below the command path's (teleprev/thread_priority.py): here the emulators share the CPUs that real
# hardware would not, and must not take them from the processes they measure.
EMULATOR_PRIORITY = 40


def _serve(make, name: str, summarize, conn) -> None:
    import sys

    sys.setswitchinterval(0.0002)  # the thread that receives a command stamps it at once, as hardware would
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(EMULATOR_PRIORITY))
    except (PermissionError, OSError):
        pass
    emulator = make().start()
    conn.send(emulator.rig_keys(name))
    while (asked := conn.recv()) != "stop":  # until the session is over
        function, args = asked
        try:
            conn.send(("answer", function(emulator, *args)))
        except Exception as e:  # noqa: BLE001 - the asking test shows it
            conn.send(("raised", f"{type(e).__name__}: {e}"))
    summary = summarize(emulator)
    emulator.stop()
    conn.send(summary)


class EmulatorProcess:
    """An emulator in a SCHED_FIFO process of its own: `keys` for the rig, `finish()` its summary."""

    def __init__(self, make, name: str, summarize):
        ours, theirs = mp.get_context("fork").Pipe()
        self.conn = ours
        self.proc = mp.get_context("fork").Process(target=_serve, args=(make, name, summarize, theirs), daemon=True)
        self.proc.start()
        self.keys: str = ours.recv()

    def ask(self, function, *args, timeout_s: float = 30.0):
        """`function(emulator, *args)` run in the emulator's process; `function` is a module-level function."""
        self.conn.send((function, args))
        if not self.conn.poll(timeout_s):
            raise RuntimeError(f"the emulator's process did not answer {function.__name__} in {timeout_s:g} s")
        kind, value = self.conn.recv()
        if kind == "raised":
            raise RuntimeError(f"{function.__name__} raised in the emulator's process: {value}")
        return value

    def finish(self, timeout_s: float = 30.0) -> dict:
        self.conn.send("stop")
        if not self.conn.poll(timeout_s):
            self.proc.kill()
            raise RuntimeError(f"the emulator's process did not answer in {timeout_s:g} s")
        summary = self.conn.recv()
        self.proc.join(10)
        return summary
