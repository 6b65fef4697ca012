"""leap.hand through a test double at the DynamixelBus interface (the real dynamixel-sdk against the emulated
bus: test_leap_emulated.py)."""

from __future__ import annotations

import math
import sys
import threading
import time

import numpy as np
import pytest

from teleprev.clock import SessionClock
from teleprev.devices.contract import DeviceContext
from teleprev.errors import ConfigError, DeviceError
from teleprev.messages import JointSample
from teleprev_devices.leap import (
    GOAL_POSITION,
    LeapHand,
    LeapSettings,
    ReadMiss,
    SdkDynamixelBus,
    angles_from_ticks,
    signed32,
    ticks_from_angles,
)
from tests.helpers.wait import wait_until

NAMES = tuple(str(i) for i in range(16))


class BusDouble:
    """Sixteen motors' registers; records writes. `unplugged` makes every call fail."""

    def __init__(self, ticks=None):
        self.regs: dict[tuple[int, int], int] = {}
        for i in range(16):
            self.regs[(i, 132)] = 2048 if ticks is None else ticks[i]
            self.regs[(i, 70)] = 0  # Hardware Error Status
            self.regs[(i, 9)] = 250  # Return Delay Time at power-on
        self.log: list[tuple] = []
        self.unplugged = False
        self.is_open = False

    def _check(self):
        if self.unplugged:
            raise DeviceError("[TxRxResult] There is no status packet!", "bus double")

    def open(self):
        self._check()
        self.is_open = True
        self.log.append(("open",))

    def write(self, ids, address, size, values):
        self._check()
        self.log.append(("write", address, size, tuple(values)))

    def sync_read(self, ids, address, size):
        self._check()
        self.log.append(("sync_read", address))
        return {i: self.regs[(i, address)] for i in ids}

    def sync_write(self, ids, address, size, values):
        self._check()
        self.log.append(("sync_write", address, size, tuple(values)))

    def close(self):
        self.is_open = False
        self.log.append(("close",))


def hand(bus, **kw):
    return LeapHand("hand", LeapSettings(**kw), DeviceContext(SessionClock()), bus=bus)


def test_ticks_are_sim_angle_plus_pi_at_4096_per_turn():
    assert ticks_from_angles(np.array([0.0]))[0] == 2048  # open hand
    assert ticks_from_angles(np.array([math.pi / 2]))[0] == 3072
    assert ticks_from_angles(np.array([-math.pi / 4]))[0] == 1536
    q = np.linspace(-1.0, 2.0, 16)
    assert np.allclose(angles_from_ticks(ticks_from_angles(q)), q, atol=2 * math.pi / 4096 / 2 + 1e-12)
    assert signed32(0xFFFFFFFF) == -1 and signed32(4095) == 4095


def test_connect_configures_current_based_position_control():
    bus = BusDouble()
    h = hand(bus, current_limit_ma=550)
    h.connect()
    writes = [(e[1], e[3]) for e in bus.log if e[0] == "write"]
    side = lambda g: tuple(round(0.75 * g) if i in (0, 4, 8) else g for i in range(16))  # noqa: E731
    assert writes == [
        (64, (0,) * 16),  # torque off before changing the mode
        (9, (0,) * 16),  # no return delay: 8 ms less per 16-motor read
        (11, (5,) * 16),  # current-based position
        (84, side(600)),  # kP, x0.75 on side-to-side joints
        (82, (0,) * 16),
        (80, side(200)),  # kD
        (102, (550,) * 16),  # current limit
        (64, (1,) * 16),  # torque on last
    ]
    # before torque comes on, the goal is set to where the hand is, so it does not jump
    i_hold = next(i for i, e in enumerate(bus.log) if e[0] == "sync_write")
    i_torque = max(i for i, e in enumerate(bus.log) if e[0] == "write" and e[1] == 64)
    assert i_hold < i_torque and bus.log[i_hold][3] == (2048,) * 16


def test_state_and_commands_in_sim_angles():
    ticks = [2048 + 100 * i for i in range(16)]
    bus = BusDouble(ticks)
    h = hand(bus)
    h.connect()
    sample = h.read(0.1)[0]
    assert sample.topic == "/hand/hand/state" and sample.payload.names == NAMES
    assert np.allclose(sample.payload.positions, np.array([100 * i for i in range(16)]) * 2 * math.pi / 4096)
    h.send(JointSample(0, NAMES, np.zeros(16)))
    assert bus.log[-1] == ("sync_write", GOAL_POSITION[0], 4, (2048,) * 16)
    # joints left out keep their previous target; names map to motor ids, not positions
    h.send(JointSample(0, ("13", "1"), np.array([math.pi / 2, 1.0])))
    goal = bus.log[-1][3]
    assert goal[13] == 3072 and goal[1] == ticks_from_angles(np.array([1.0]))[0] and goal[0] == 2048


def test_commands_outside_the_limits_are_refused_and_never_written():
    bus = BusDouble()
    h = hand(bus)
    h.connect()
    n = len(bus.log)
    with pytest.raises(DeviceError, match=r"12=2.5000 not in \[-0.3490, 2.0940\]"):
        h.send(JointSample(0, ("12",), np.array([2.5])))
    with pytest.raises(DeviceError, match="non-finite"):
        h.send(JointSample(0, ("0",), np.array([np.inf])))
    with pytest.raises(DeviceError, match="unknown joints"):
        h.send(JointSample(0, ("16",), np.array([0.0])))
    assert len(bus.log) == n and h.counters() == {"refused_commands": 3, "read_misses": 0}


def test_reads_are_capped_near_90_hz():
    h = hand(BusDouble())
    h.connect()
    t0, n = time.monotonic(), 0
    while time.monotonic() - t0 < 0.3:
        n += len(h.read(0.01))
    assert 24 <= n <= 29
    with pytest.raises(ValueError, match=r"rate_hz must be in \(0, 90\]"):
        LeapSettings(rate_hz=120.0)


def test_a_bus_fault_is_a_device_error():
    bus = BusDouble()
    h = hand(bus)
    h.connect()
    bus.unplugged = True
    with pytest.raises(DeviceError, match="no status packet"):
        h.read(0.1)
    with pytest.raises(DeviceError):
        h.send(JointSample(0, ("0",), np.array([0.1])))
    h.disconnect()
    assert not bus.is_open
    with pytest.raises(DeviceError, match="not connected"):
        h.send(JointSample(0, ("0",), np.array([0.1])))


def test_missing_sdk_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "dynamixel_sdk", None)
    with pytest.raises(DeviceError, match=r"uv sync --extra leap"):
        SdkDynamixelBus("/dev/ttyUSB0").open()


def test_rig_settings_are_checked(tmp_path):
    from teleprev.rig import load_rig

    rig = tmp_path / "rig.toml"
    rig.write_text('[devices.hand]\nplugin = "leap.hand"\nkp = "600"\n')
    with pytest.raises(ConfigError, match=r"\[devices.hand\].kp: expected an integer, got '600'"):
        load_rig(rig)


class MissingBus(BusDouble):
    """The first `misses` position reads each wait `wait_s` and get no reply (a motor's packet lost)."""

    def __init__(self, misses: int, wait_s: float):
        super().__init__()
        self.misses, self.wait_s = misses, wait_s

    def sync_read(self, ids, address, size):
        if address == 132 and self.misses > 0 and self.is_open and any(e[0] == "sync_write" for e in self.log):
            self.misses -= 1
            self.log.append(("sync_read", address, "missed"))
            time.sleep(self.wait_s)
            raise ReadMiss("motor 5 did not answer the sync read at address 132", "bus double")
        return super().sync_read(ids, address, size)


def test_a_command_is_written_between_a_reads_retries():
    """A read that misses is tried again, and a command waiting for the bus is written before the next try
    (the hand's writes do not wait out the read's retries)."""
    bus = MissingBus(misses=0, wait_s=0.03)
    h = hand(bus)
    h.connect()
    bus.misses = 4
    reader = threading.Thread(target=h.read, args=(1.0,))
    reader.start()
    wait_until(lambda: ("sync_read", 132, "missed") in bus.log, 1.0, what="the first read to miss")
    h.send(JointSample(0, NAMES, np.full(16, 0.1)))
    reader.join()
    missed = [i for i, e in enumerate(bus.log) if e == ("sync_read", 132, "missed")]
    written = max(i for i, e in enumerate(bus.log) if e[0] == "sync_write")
    assert len(missed) == 4 and written < missed[1], bus.log[-8:]
    assert h.counters()["read_misses"] == 4
