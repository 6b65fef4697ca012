"""A VMC sender for tests and benchmarks: real OSC messages and bundles (python-osc) over real UDP.

    sender = VmcSender(port).start(rate_hz=60)   # a glove + suit frame every 1/60 s, stamped with /VMC/Ext/T
    ...; sender.stop(); sender.sent              # frames sent
"""

from __future__ import annotations

import socket
import threading
import time

import numpy as np
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

from teleprev.transforms import quat_from_axis_angle

FINGERS = ("Index", "Middle", "Ring", "Little", "Thumb")


def msg(address: str, *args, types: str | None = None):
    b = OscMessageBuilder(address=address)
    for i, a in enumerate(args):
        b.add_arg(a, types[i] if types else None)
    return b.build()


def bone(name: str, pos=(0.0, 0.0, 0.0), quat=(0.0, 0.0, 0.0, 1.0), address="/VMC/Ext/Bone/Pos", double=False):
    """A bone's message; float32 values as senders send them, or float64 (`double`) for values beyond float32."""
    return msg(
        address, name, *[float(v) for v in pos], *[float(v) for v in quat], types="s" + ("d" if double else "f") * 7
    )


def bundle(*messages):
    b = OscBundleBuilder(IMMEDIATELY)
    for m in messages:
        b.add_content(m)
    return b.build()


def unity_quat(axis, angle):
    """A Unity rotation of `angle` about the Unity-frame `axis` (x y z w)."""
    axis = np.asarray(axis, dtype=float)
    return quat_from_axis_angle(axis / np.linalg.norm(axis) * angle)


def arm_messages(root_pos=(0, 0, 0), root_quat=(0, 0, 0, 1), elbow_quat=(0, 0, 0, 1), t=None, hand_quat=(0, 0, 0, 1)):
    msgs = [
        bone("root", root_pos, root_quat, address="/VMC/Ext/Root/Pos"),
        bone("Hips", (0, 0.9, 0)),
        bone("Spine", (0, 0.1, 0)),
        bone("Chest", (0, 0.15, 0)),
        bone("RightShoulder", (0.02, 0.2, 0)),
        bone("RightUpperArm", (0.1, 0, 0)),
        bone("RightLowerArm", (0.3, 0, 0), elbow_quat),
        bone("RightHand", (0.25, 0, 0), hand_quat),
    ]
    if t is not None:
        msgs.append(msg("/VMC/Ext/T", t, types="d"))
    return msgs


def mirrored(name: str, pos, quat) -> tuple[str, tuple, tuple]:
    """A Right* bone as its Left* twin on a skeleton mirrored through its sagittal plane (Unity x -> -x)."""
    x, y, z, w = quat
    return name.replace("Right", "Left"), (-pos[0], pos[1], pos[2]), (x, -y, -z, w)


def both_sides(right: list[tuple[str, tuple, tuple]]) -> list:
    """Bone messages of the given right-side bones and their mirrored left twins (a symmetric operator)."""
    return [bone(*b) for b in right] + [bone(*mirrored(*b)) for b in right if b[0].startswith("Right")]


def arm_frame(**kw):
    return bundle(*arm_messages(**kw))


def finger_messages(flexion) -> list:
    """Every right finger bone curled by `flexion` rad (a negative turn about Unity z): one angle for all,
    or one per finger (FINGERS' order)."""
    per_finger = np.broadcast_to(np.asarray(flexion, dtype=float), (len(FINGERS),))
    return [bone(f"Right{f}{p}", (0.03, 0, 0), unity_quat([0, 0, 1], -a)) for f, a in zip(FINGERS, per_finger)
            for p in ("Proximal", "Intermediate", "Distal")]


def rig_text(port: int, glove_timeout_s: float = 0.0, allow: tuple[str, ...] = ()) -> str:
    """A rig with a VMC glove and suit on `port` and the simulated arm and hand."""
    allowed = f"allow = {list(allow)!r}\n".replace("'", '"') if allow else ""
    return (
        '[rig]\nname = "vmc"\n\n'
        f'[devices.glove]\nplugin = "vmc.glove"\nport = {port}\ntimeout_s = {glove_timeout_s}\n{allowed}\n'
        f'[devices.suit]\nplugin = "vmc.suit"\nport = {port}\n{allowed}\n'
        '[devices.arm]\nplugin = "sim.arm"\n\n[devices.hand]\nplugin = "sim.hand"\n'
    )


class VmcSender:
    """Sends a whole frame (arm chain, fingers, /VMC/Ext/T) every 1/rate_hz s from its own thread, the
    fingers flexing slowly; `inject(datagram)` slips an extra datagram in before the next frame."""

    def __init__(self, port: int, host: str = "127.0.0.1", source: str = "127.0.0.1", both_sides: bool = False):
        self.address = (host, port)
        self.both_sides = both_sides  # the left arm and fingers too, mirroring the right (a symmetric operator)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((source, 0))
        self.sent = 0
        self._extra: list[bytes] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def frame(self, k: int, rate_hz: float) -> bytes:
        t = k / rate_hz
        flex = 0.6 + 0.4 * np.sin(2 * np.pi * 0.5 * t)
        messages = [*arm_messages(t=100.0 + t), *finger_messages(flex)]
        if self.both_sides:
            messages += [bone(*mirrored(*m.params[:1], m.params[1:4], m.params[4:8]))
                         for m in messages if str(m.params[0]).startswith("Right")]
        return bundle(*messages).dgram

    def send(self, datagram: bytes) -> None:
        self.sock.sendto(datagram, self.address)

    def inject(self, datagram: bytes) -> None:
        with self._lock:
            self._extra.append(datagram)

    def start(self, rate_hz: float = 60.0, seconds: float | None = None) -> VmcSender:
        self._thread = threading.Thread(target=self._run, args=(rate_hz, seconds), daemon=True)
        self._thread.start()
        return self

    skip_late = False  # a frame due while the one before was late is dropped, not sent in a burst (a device's clock)

    def _run(self, rate_hz: float, seconds: float | None) -> None:
        start, k = time.monotonic(), 0
        while not self._stop.is_set() and (seconds is None or k < seconds * rate_hz):
            with self._lock:
                extra, self._extra = self._extra, []
            for d in extra:
                self.send(d)
            if self.skip_late:
                k = max(k, int((time.monotonic() - start) * rate_hz))
            self.send(self.frame(k, rate_hz))
            self.sent += 1
            k += 1
            self._stop.wait(max(0.0, start + k / rate_hz - time.monotonic()))

    def join(self, timeout: float = 10.0) -> None:
        if self._thread is not None:
            self._thread.join(timeout)

    def stop(self) -> None:
        self._stop.set()
        self.join()
        self.sock.close()


# ---- fuzzing: what a noisy sender, a broken one and a stranger on the port send ------------------------
_BAD_NUMBERS = (float("nan"), float("inf"), -float("inf"), 1e300, -1e300, 1e39, 0.0)
_BONES = ("RightIndexProximal", "RightHand", "Hips", "RightLittleDistal", "NoSuchBone", "", "rightindexproximal",
          "RightIndexProximal\x00x", "\u00e9\u00e9")


def _wrong_value(rng):
    kind = rng.integers(6)
    return (("s", "0.5"), ("i", int(rng.integers(-2**31, 2**31))), ("T", True), ("b", b"\x00\x01"),
            ("N", None), ("d", float(rng.choice(_BAD_NUMBERS))))[kind]


def fuzz_datagram(rng, good: bytes) -> bytes:
    """One random or mutated datagram: byte flips, truncations, oversized ones, wrong types, NaN/inf/1e300,
    wrong bone names, bad sender times, non-unit and zero quaternions, random bytes."""
    kind = rng.integers(12)
    if kind == 0:  # flipped bytes
        data = bytearray(good)
        for i in rng.integers(0, len(data), size=int(rng.integers(1, 16))):
            data[i] = int(rng.integers(256))
        return bytes(data)
    if kind == 1:  # truncated
        return good[: int(rng.integers(0, len(good)))]
    if kind == 2:  # oversized: the frame and junk up to the largest UDP datagram
        return good + rng.bytes(int(rng.integers(1000, 65507 - len(good))))
    if kind == 3:  # random bytes, some starting like a bundle or a message
        head = (b"#bundle\x00", b"/VMC/Ext/Bone/Pos\x00\x00\x00", b"")[int(rng.integers(3))]
        return head + rng.bytes(int(rng.integers(0, 400)))
    if kind == 4:  # a bad sender time
        return bundle(*finger_messages(0.5), msg("/VMC/Ext/T", float(rng.choice(_BAD_NUMBERS)), types="d")).dgram
    if kind == 5:  # a bone with a bad number (double precision, so 1e300 survives)
        values = rng.normal(size=7)
        values[int(rng.integers(7))] = float(rng.choice(_BAD_NUMBERS))
        return bundle(bone("RightIndexProximal", values[:3], values[3:], double=True)).dgram
    if kind == 6:  # wrong bone names
        return bundle(bone(str(rng.choice(_BONES)), (0.03, 0, 0))).dgram
    if kind == 7:  # wrong argument types
        t, v = _wrong_value(rng)
        args = ["RightIndexProximal", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
        types = list("sfffffff")
        k = int(rng.integers(8))
        args[k], types[k] = v, t
        return bundle(msg("/VMC/Ext/Bone/Pos", *args, types="".join(types))).dgram
    if kind == 8:  # too few arguments, or none
        n = int(rng.integers(0, 7))
        return bundle(msg(str(rng.choice(["/VMC/Ext/Bone/Pos", "/VMC/Ext/Root/Pos", "/VMC/Ext/T"])),
                          *(["RightHand"] + [0.0] * 7)[:n])).dgram
    if kind == 9:  # non-unit or zero quaternions
        q = rng.normal(size=4) * float(rng.choice([0.0, 1e-9, 0.5, 3.0, 1e30]))
        return bundle(bone("RightMiddleProximal", (0.03, 0, 0), q, double=True)).dgram
    if kind == 10:  # a whole arm with one huge or non-finite position
        p = [float(rng.choice(_BAD_NUMBERS)), 0.0, 0.0]
        root = bone("root", p, address="/VMC/Ext/Root/Pos", double=True)
        return bundle(root, *arm_messages()[1:], msg("/VMC/Ext/T", 1.0, types="d")).dgram
    return bundle(msg("/VMC/Ext/Bone/Pos", "RightHand", *rng.normal(size=7).tolist(), types="s" + "f" * 7),
                  msg("/VMC/Ext/T", "noon", types="s")).dgram  # a bad time beside a good bone


def _min_jerk(s: np.ndarray) -> np.ndarray:
    """The minimum-jerk profile from 0 to 1 over s in [0, 1] (how people reach)."""
    s = np.clip(s, 0.0, 1.0)
    return s**3 * (10 - 15 * s + 6 * s**2)


class HumanLikeSender(VmcSender):
    """A glove and suit moving as a person does: the hand closing and opening in grasps of varying depth,
    pace and finger timing (minimum-jerk strokes, the fingers not quite together), a physiological tremor
    (about 10 Hz, a few milliradians), and the wrist reaching between points some 10 cm apart with a
    little rotation, each reach its own minimum-jerk stroke. Deterministic for a seed; frames keep to the
    wall clock (a late one is skipped, as a device's own clock would)."""

    skip_late = True

    def __init__(self, port: int, seed: int = 0, **kw):
        super().__init__(port, **kw)
        rng = np.random.default_rng(seed)
        self._grasps = self._strokes(rng, 120.0, 0.6, 1.6, lambda r: r.uniform(0.2, 1.3))
        self._reaches = self._strokes(rng, 120.0, 0.7, 1.8, lambda r: r.uniform(-0.1, 0.1, 3))
        self._twists = self._strokes(rng, 120.0, 0.8, 2.0, lambda r: r.uniform(-0.35, 0.35))
        self._finger_delay = rng.uniform(0.0, 0.12, len(FINGERS))
        self._finger_gain = rng.uniform(0.8, 1.1, len(FINGERS))
        self._tremor_phase = rng.uniform(0, 2 * np.pi, len(FINGERS))

    @staticmethod
    def _strokes(
        rng, seconds: float, shortest: float, longest: float, draw
    ) -> list[tuple[float, float, object, object]]:
        """(start, end, from, to) strokes back to back, each held a moment before the next."""
        out, t, value = [], 0.0, draw(rng) * 0
        while t < seconds:
            length = rng.uniform(shortest, longest)
            target = draw(rng)
            out.append((t, t + length, value, target))
            t += length + rng.uniform(0.05, 0.6)
            value = target
        return out

    @staticmethod
    def _at(strokes, t: float):
        for start, end, a, b in strokes:
            if t < start:
                return a
            if t <= end:
                return a + (b - a) * _min_jerk(np.array((t - start) / (end - start)))
        return strokes[-1][3]

    def frame(self, k: int, rate_hz: float) -> bytes:
        t = k / rate_hz
        flex = np.array([self._at(self._grasps, t - d) for d in self._finger_delay]) * self._finger_gain
        flex = flex + 0.004 * np.sin(2 * np.pi * 10.0 * t + self._tremor_phase)
        reach = np.asarray(self._at(self._reaches, t), dtype=float)
        twist = float(self._at(self._twists, t))
        return bundle(*arm_messages(root_pos=tuple(reach), hand_quat=tuple(unity_quat([1, 0, 0], twist)), t=100.0 + t),
                      *finger_messages(flex)).dgram


class WristTwister(VmcSender):
    """An operator turning the wrist about the forearm at `rate` rad/s, to `reach` rad one way, holding,
    then to `reach` the other way, and back again, the hand half closed: past where the arm's last joint
    ends, one way or the other, so it drives that joint into its limit."""

    skip_late = True

    def __init__(self, port: int, rate: float = 1.5, reach: float = 2.6, hold: float = 1.5, **kw):
        super().__init__(port, **kw)
        self.rate, self.reach, self.hold = rate, reach, hold

    def twist(self, t: float) -> float:
        leg = self.reach / self.rate
        plan = [(1.0, 0.0), (leg, self.reach), (self.hold, self.reach), (2 * leg, -self.reach),
                (self.hold, -self.reach), (leg, 0.0)]
        start, value = 0.0, 0.0
        for length, to in plan:
            if t < start + length:
                return value + (to - value) * (t - start) / length
            start, value = start + length, to
        return value

    def frame(self, k: int, rate_hz: float) -> bytes:
        t = (k / rate_hz) % 16.0
        twist = self.twist(t)
        return bundle(*arm_messages(hand_quat=tuple(unity_quat([1, 0, 0], twist)), t=100.0 + t),
                      *finger_messages(0.5)).dgram
