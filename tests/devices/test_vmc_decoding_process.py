"""The VMC decoding process (devices/vmc/decoding_process.py): real UDP on loopback into a real process, whose
frames must reach the receiver exactly as the decoder made them, and whose end is seen and recovered from."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from teleprev import topics
from teleprev.clock import SessionClock
from teleprev.devices import DeviceContext, DeviceRunner
from teleprev_devices.vmc import VmcGlove
from teleprev_devices.vmc.decode import VmcDecoder
from teleprev_devices.vmc.plugins import VmcSettings
from teleprev_devices.vmc.receiver import VmcReceiver
from tests.helpers.ports import free_port
from tests.helpers.vmc import arm_messages, bone, bundle, finger_messages, msg
from tests.helpers.wait import wait_until


def _alive(pid: int) -> bool:
    """Running (not gone, not a zombie left to reap)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def test_frames_cross_the_pipe_bit_for_bit_and_stamped_as_the_decoder_stamps_them():
    rng = np.random.default_rng(3)
    clock = SessionClock()
    port = free_port()
    receiver = VmcReceiver("127.0.0.1", port, clock)
    sub = receiver.fanout.subscribe()
    datagrams = []
    for k in range(20):  # odd doubles (not float32's), rotations a hair off unit that the decoder normalises
        q = rng.normal(size=4)
        q = q / np.linalg.norm(q) * (1 + 1e-3 * rng.uniform(-1, 1))
        datagrams.append(bundle(*arm_messages(root_pos=tuple(rng.normal(size=3))),
                                *finger_messages(rng.uniform(0, 1.5, 5)),
                                bone("RightIndexProximal", tuple(rng.normal(size=3)), tuple(q), double=True),
                                msg("/VMC/Ext/T", 100.0 + k / 120, types="d")).dgram)
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    got = []
    try:
        for d in datagrams:
            sender.sendto(d, ("127.0.0.1", port))
            time.sleep(0.002)
        wait_until(lambda: got.extend(receiver.fanout.wait(sub, 0.05)) or len(got) == 20, 5.0, what="20 frames")
    finally:
        sender.close()
        receiver.close()
    here = VmcDecoder()  # the same datagrams decoded in this process, received when the process received them
    for d, frame in zip(datagrams, got):
        mine = here.datagram(d, [], ("127.0.0.1", 1), frame.receive_ns)
        assert mine.stamp_ns == frame.stamp_ns and mine.updated == frame.updated
        assert mine.bones.keys() == frame.bones.keys()
        for name, pose in mine.bones.items():
            assert pose.position.tobytes() == frame.bones[name].position.tobytes(), name
            assert pose.rotation.tobytes() == frame.bones[name].rotation.tobytes(), name
    receive = np.array([f.receive_ns for f in got])
    assert np.all(np.diff(receive) > 0) and abs(receive[-1] - clock.now_ns()) < 5e9  # on the session clock


def test_a_decoding_process_that_dies_is_one_error_and_the_runner_opens_a_new_one():
    clock = SessionClock()
    port = free_port()
    glove = VmcGlove("g", VmcSettings(port=port), DeviceContext(clock))
    got: list = []
    runner = DeviceRunner(glove, lambda s, t: got.append(s), clock, reconnect_s=0.1).start()
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def send(n: int) -> None:
        for _ in range(n):
            sender.sendto(bundle(*finger_messages(np.full(5, 0.5))).dgram, ("127.0.0.1", port))
            time.sleep(0.005)

    def hands() -> int:
        return sum(s.topic == "/glove/g/hand" for s in list(got))

    try:
        wait_until(lambda: runner.connected, 10.0, what="the glove opened")
        send(5)
        wait_until(lambda: hands() == 5, 5.0, what="5 hand samples")
        first = glove._receiver._process
        os.kill(first.pid, signal.SIGKILL)
        wait_until(lambda: glove._receiver is not None and glove._receiver._process is not first
                   and runner.connected, 10.0, what="a new decoding process")
        send(5)
        wait_until(lambda: hands() == 10, 5.0, what="5 more hand samples from the new process")
    finally:
        runner.stop()
        sender.close()
    errors = [s.payload.data["message"] for s in got
              if s.topic == topics.DEVICE_EVENT and s.payload.data["event"] == "error"]
    assert errors == [f"read failed: VMC receiver 127.0.0.1:{port}: the VMC decoding process ended (exit status -9)"]


def test_the_process_outlives_the_thread_that_opened_it_and_ends_with_the_session():
    """Opened from a device's runner thread that then ends (PR_SET_PDEATHSIG would kill it then), it keeps
    decoding; a session process that dies without closing it leaves no decoding process behind."""
    clock = SessionClock()
    port = free_port()
    opened: list[VmcReceiver] = []
    thread = threading.Thread(target=lambda: opened.append(VmcReceiver("127.0.0.1", port, clock)))
    thread.start()
    thread.join()
    receiver = opened[0]
    sub = receiver.fanout.subscribe()
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        time.sleep(0.3)
        sender.sendto(bundle(*finger_messages(np.full(5, 0.5))).dgram, ("127.0.0.1", port))
        assert len(receiver.fanout.wait(sub, 5.0)) == 1 and receiver._process.poll() is None
    finally:
        sender.close()
        receiver.close()

    code = ("import os, sys; from teleprev.clock import SessionClock; "
            "from teleprev_devices.vmc.receiver import VmcReceiver; "
            f"r = VmcReceiver('127.0.0.1', {free_port()}, SessionClock()); "
            "print(r._process.pid, flush=True); os._exit(0)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                         env={**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)})
    pid = int(out.stdout.split()[0])
    wait_until(lambda: not _alive(pid), 5.0, what="the orphaned decoding process ended")
