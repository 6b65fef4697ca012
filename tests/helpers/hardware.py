"""Driving the real actuator plugins (xarm.arm, leap.hand) against the emulators, for tests and bench/hardware.py.

    log = EventLog()
    runner = DeviceRunner(device, log.sink, clock, reconnect_s=0.1).start()   # or paced_runner(...): as the product
    stream = CommandStream(device, clock, amplitude=0.05).start()    # smooth stamped commands at 100 Hz
    log.wait(lambda: log.count("error") >= 1)
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from contextlib import nullcontext

import numpy as np

from teleprev import topics
from teleprev.devices import DeviceRunner
from teleprev.devices.servo_limits import STREAM_GAP_NS
from teleprev.emulators.wire_schedule import PlannedSend
from teleprev.errors import DeviceError
from teleprev.messages import JointSample
from teleprev.thread_priority import ACTUATOR_PRIORITY
from tests.helpers.wait import WaitTimeout, wait_until


def pace_this_thread() -> None:
    """The calling thread at the actuators' processes' priority (SCHED_FIFO ACTUATOR_PRIORITY, where permitted),
    as the product's command path runs (teleprev/live/core/actuator_host.py)."""
    try:
        os.sched_setscheduler(threading.get_native_id(), os.SCHED_FIFO, os.sched_param(ACTUATOR_PRIORITY))
    except (OSError, AttributeError):
        pass


def paced_runner(device, sink, clock, **runner) -> DeviceRunner:
    """A DeviceRunner for `device`, started from a thread at the actuators' priority (pace_this_thread): its
    thread inherits that priority, and so do the threads the plugin's SDK starts once it connects (the xArm
    SDK's reply and report readers), as in the product's actuator process. Driven from ordinary threads of
    a process on a loaded machine, the SDK's reply reader got no CPU in time and the SDK's 0.1 s reply wait
    ran out ("no reply within 0.1 s": bench/hardware.py's xarm_sdk_session_ok, at a load of 25-30) while
    the box had long answered."""
    started: list[DeviceRunner] = []

    def start() -> None:
        pace_this_thread()
        started.append(DeviceRunner(device, sink, clock, **runner).start())

    thread = threading.Thread(target=start, name="paced-runner-start")
    thread.start()
    thread.join()
    return started[0]


class EventLog:
    """A runner's sink: device events and the last state sample, with the times they arrived."""

    def __init__(self):
        self.events: list[dict] = []
        self.states: int = 0
        self.last_state: JointSample | None = None
        self._lock = threading.Lock()

    def sink(self, sample, receive_ns: int) -> None:
        with self._lock:
            if sample.topic == topics.DEVICE_EVENT:
                self.events.append({**sample.payload.data, "t": time.monotonic()})
            else:
                self.states += 1
                self.last_state = sample.payload

    def of(self, event: str) -> list[dict]:
        with self._lock:
            return [e for e in self.events if e["event"] == event]

    def count(self, event: str) -> int:
        return len(self.of(event))

    def wait(self, done: Callable[[], bool], timeout_s: float = 5.0) -> bool:
        """Whether done() held within timeout_s (False rather than a failure: bench/hardware.py reports it)."""
        try:
            return bool(wait_until(done, timeout_s))
        except WaitTimeout:
            return False


def _swing(origin: np.ndarray, start: np.ndarray, joints: slice, amplitude: float) -> np.ndarray:
    """Each joint's swing from `start`: `amplitude` up from where the stream first started, back down to it
    from anywhere above. A stream that starts again (after a stall or a fault) where its last swing left it,
    always swinging up, crept by up to 2 x amplitude a time until its commands were refused at a joint limit
    (bench/hardware.py, load 25: 1276 of 3571 xArm commands, "joint3=0.1920 not in [-3.1102, 0.1920]"); it
    stays within [origin, origin + 2 x amplitude]."""
    above = start[joints] - origin[joints]
    return np.where(above > 1e-9, -above / 2.0, amplitude)


class CommandStream:
    """Sends `device` a command every 1/rate_hz s from its own thread, stamped when it is sent: the joints
    start where the device is and move by amplitude * (1 - cos(w t)) (at rest at t = 0, so the stream
    keeps far inside the servo rule's acceleration and jerk limits). Counts sent and failed commands;
    `planned` keeps, for each command sent, the instant it was due to leave (its schedule, on the monotonic
    clock) and what it was, which an emulator's arrival times are measured against."""

    def __init__(self, device, clock, rate_hz: float = 100.0, amplitude: float = 0.05, period_s: float = 4.0,
                 joints: slice = slice(None)):
        self.device, self.clock = device, clock
        self.period_s = 1.0 / rate_hz
        self.amplitude, self.omega = amplitude, 2 * np.pi / period_s
        self.joints = joints
        self.sent = 0
        self.failed = 0
        self.last_error = ""
        self.send_s: list[float] = []
        self.planned: list[PlannedSend] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="command-stream", daemon=True)

    def start(self) -> CommandStream:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5.0)

    def _resume_point(self) -> np.ndarray | None:
        """Where the stream (re)starts: the device's target, once it is connected with no fault; None before.
        Read under the device's lock, so that a reconnect in progress (which holds it, and sets the target
        to where the arm now stands) is waited for: a target read before it would be where the arm was
        before the fault, a jump from where it is now that the servo rule refuses."""
        with getattr(self.device, "_lock", None) or nullcontext():
            if getattr(self.device, "_fault", None) is not None or not getattr(self.device, "_connected", True):
                return None
            target = getattr(self.device, "_target", None)
            return None if target is None else np.array(target, dtype=float)

    def _run(self) -> None:
        # Each position is a function of its own stamp: a thread preempted between reading the clock and
        # sending would otherwise send a position that does not match its stamp, which the servo rule (it
        # differentiates stamps) reads as a jerk. A stall longer than the rule's stream gap starts a new
        # stream from rest, as the rule (and the controller) take it.
        # Paced as the product's command path is: an ordinary thread of a busy process stalls for tens of ms,
        # and the emulated box rightly takes the target after a stall as a jump
        # (teleprev/emulators/xarm_servo.py), which says nothing of the plugin.
        pace_this_thread()
        names = self.device.joint_names
        start, t0, last, last_ns = None, 0, None, None
        origin, swing = None, self.amplitude  # where the stream first started; each joint's swing from `start`
        next_t = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            if now < next_t:
                time.sleep(next_t - now)
                continue
            due, next_t = next_t, next_t + self.period_s
            if next_t < now:  # fell behind (a stall): start again from now instead of bursting
                next_t = now + self.period_s
            if start is None:
                start, t0 = self._resume_point(), None
                if start is None:
                    continue
                origin = start.copy() if origin is None else origin
                swing = _swing(origin, start, self.joints, self.amplitude)
            stamp = self.clock.now_ns()
            if t0 is None:
                t0 = stamp
            elif last_ns is not None and stamp - last_ns > STREAM_GAP_NS:
                start, t0 = last, stamp  # the rule sees a new stream, at rest on the last command
                swing = _swing(origin, start, self.joints, self.amplitude)
            q = start.copy()
            q[self.joints] += swing * (1 - np.cos(self.omega * (stamp - t0) / 1e9))
            t = time.perf_counter()
            try:
                self.device.send(JointSample(stamp, names, q))
                self.sent += 1
                self.send_s.append(time.perf_counter() - t)
                self.planned.append(PlannedSend(round(due * 1e9), q))
                last, last_ns = q, stamp
            except DeviceError as exc:
                self.failed += 1
                self.last_error = str(exc)
                start, last, last_ns = None, None, None  # after a fault the device starts again from where it is
                time.sleep(0.02)
