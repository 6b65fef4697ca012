"""vmc.suit and vmc.glove: a VMC-protocol sender (Rebocap, UDCAP-class gloves, VMC-speaking apps) as a
suit and/or a glove. See devices/vmc/unity.py for the conversions and devices/vmc/receiver.py for
the socket; both plugins on one host and port share one receiver (one sender, two devices).

    [devices.suit]             [devices.glove]
    plugin = "vmc.suit"        plugin = "vmc.glove"
    port = 39539               port = 39539

They listen on 127.0.0.1 unless `host` says otherwise; `allow` limits the senders accepted (others are
counted as disallowed_senders and dropped), and plugins sharing a port must list the same ones.
"""

from __future__ import annotations

import ipaddress
from abc import abstractmethod
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from teleprev.devices import (
    Device, DeviceContext, DeviceError, JointSample, PoseSample, Sample, StreamSpec, smplx, transforms,
)
from teleprev_devices.vmc import unity
from teleprev_devices.vmc.receiver import Frame, VmcReceiver, acquire, release

BODY_POSE_NAMES: tuple[str, ...] = tuple(f"{j}.{c}" for j in smplx.BODY_JOINTS for c in "xyz")
_IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])
_ARM_CHAIN = frozenset(unity.RIGHT_ARM_CHAIN) | {""}  # a frame updating any of these moves the wrist
_FINGERS = frozenset(unity.RIGHT_HAND_BONES)


@dataclass
class VmcSettings:
    host: str = "127.0.0.1"  # the address to listen on; "0.0.0.0" accepts senders on other machines
    port: int = 39539  # VMC's usual receiving port
    rate_hz: float = 60.0  # the sender's frame rate (for the rate display and gap detection)
    timeout_s: float = 0.0  # > 0: no frame for this long is a fault (the runner reopens the socket); 0: only a gap
    allow: tuple[str, ...] = ()  # senders accepted (addresses or networks, e.g. "192.168.1.7", "10.0.0.0/24"); empty: any

    def __post_init__(self):
        try:
            ipaddress.IPv4Address(self.host)
        except ValueError:
            raise ValueError(f"host must be an IPv4 address to listen on (e.g. 127.0.0.1), got {self.host!r}") from None
        for a in self.allow:
            try:
                ipaddress.IPv4Network(a, strict=False)
            except ValueError:
                raise ValueError(f"allow: {a!r} is not an IPv4 address or network (e.g. 192.168.1.7 or 10.0.0.0/24)") from None
        if not 0 <= self.port <= 65535:
            raise ValueError(f"port must be 0..65535, got {self.port}")
        if not 0 < self.rate_hz <= 1000:
            raise ValueError(f"rate_hz must be in (0, 1000], got {self.rate_hz}")
        if self.timeout_s < 0:
            raise ValueError(f"timeout_s must be >= 0, got {self.timeout_s}")


@dataclass
class VmcSuitSettings(VmcSettings):
    body: bool = False  # also publish the SMPL-X body joints on /suit/<name>/body


V = TypeVar("V", bound=VmcSettings)


class _VmcDevice(Device[V]):
    def __init__(self, name: str, settings: V, context: DeviceContext):
        super().__init__(name, settings, context)
        self._receiver: VmcReceiver | None = None
        self._sub = None
        self._last_frame_ns = 0

    def connect(self) -> None:
        s = self.settings
        self._receiver = acquire(self.context.shared, s.host, s.port, self.context.clock, s.allow)
        self._sub = self._receiver.fanout.subscribe()
        self._last_frame_ns = self.context.clock.now_ns()

    def disconnect(self) -> None:
        receiver, self._receiver = self._receiver, None
        if receiver is not None:
            receiver.fanout.unsubscribe(self._sub)
            release(self.context.shared, receiver)

    def endpoint(self) -> str:
        return f"UDP {self.settings.host}:{self.settings.port}"

    def counters(self) -> dict[str, int]:
        receiver, sub = self._receiver, self._sub
        if receiver is None or sub is None:
            return {}
        return {**receiver.counters.errors(), "lost_queue_overflow": sub.overflow}

    def read(self, timeout_s: float) -> list[Sample]:
        receiver = self._receiver
        if receiver is None:
            raise DeviceError("not connected", f"device {self.name!r}")
        frames = receiver.fanout.wait(self._sub, timeout_s)
        out: list[Sample] = []
        for frame in frames:
            out.extend(self.convert(frame))
        self._check_timeout(bool(frames))
        return out

    def _check_timeout(self, got: bool) -> None:
        limit = self.settings.timeout_s
        if limit <= 0:
            return
        now = self.context.clock.now_ns()
        if got:
            self._last_frame_ns = now
        elif now - self._last_frame_ns > limit * 1e9:
            s = self.settings
            raise DeviceError(f"no VMC frames on UDP {s.host}:{s.port} for {limit:g} s "
                              "(is the sender running and sending to this address?)", f"device {self.name!r}")

    @abstractmethod
    def convert(self, frame: Frame) -> list[Sample]:
        """The samples one frame of the sender gives this device."""


class VmcSuit(_VmcDevice[VmcSuitSettings], kind="suit"):
    """The right wrist (PoseSample, frame "suit") on /suit/<name>/wrist; with body = true also the SMPL-X
    body joints' local rotations (JointSample, "<joint>.x|y|z") on /suit/<name>/body."""

    def __init__(self, name: str, settings: VmcSuitSettings, context: DeviceContext):
        super().__init__(name, settings, context)
        self.wrist_topic = self.topic("wrist")
        self.body_topic = self.topic("body")

    def streams(self) -> list[StreamSpec]:
        out = [StreamSpec(self.wrist_topic, "pose", self.settings.rate_hz)]
        if self.settings.body:
            out.append(StreamSpec(self.body_topic, "joints", self.settings.rate_hz))
        return out

    def convert(self, frame: Frame) -> list[Sample]:
        out = []
        bones = frame.bones
        if not frame.updated.isdisjoint(_ARM_CHAIN) and unity.RIGHT_ARM_REQUIRED <= bones.keys():
            out.append(Sample(self.wrist_topic, wrist_pose(bones, frame.stamp_ns)))
        if self.settings.body and "Hips" in bones:
            out.append(Sample(self.body_topic, JointSample(frame.stamp_ns, BODY_POSE_NAMES, body_pose(bones))))
        return out


class VmcGlove(_VmcDevice[VmcSettings], kind="glove"):
    """The right hand's finger bones as the SMPL-X hand pose (45 values) on /glove/<name>/hand."""

    def streams(self) -> list[StreamSpec]:
        return [StreamSpec(self.topic("hand"), "joints", self.settings.rate_hz)]

    def convert(self, frame: Frame) -> list[Sample]:
        if frame.updated.isdisjoint(_FINGERS):
            return []
        return [Sample(self.topic("hand"), JointSample(frame.stamp_ns, smplx.HAND_POSE_NAMES, hand_pose(frame.bones)))]


def _rotations(bones: dict, names: tuple[str, ...]) -> np.ndarray:
    """Local quaternions of the named bones; a bone never received stays in rest (identity)."""
    return np.array([bones[n].rotation if n in bones else _IDENTITY for n in names])


def hand_pose(bones: dict) -> np.ndarray:
    """(45,) SMPL-X right-hand pose from Unity's right finger bones."""
    return unity.local_rotations_to_smplx(_rotations(bones, unity.RIGHT_HAND_BONES)).reshape(45)


def body_pose(bones: dict) -> np.ndarray:
    """(66,) SMPL-X body joints' axis-angle; pelvis = the global orientation (root * Hips)."""
    quats = _rotations(bones, unity.BODY_BONES)
    root = bones.get("")
    if root is not None:
        quats[0] = transforms.quat_multiply(root.rotation, quats[0])
    return unity.local_rotations_to_smplx(quats).reshape(-1)


def wrist_pose(bones: dict, stamp_ns: int) -> PoseSample:
    root = bones.get("")
    t_root = unity.transform(root.position, root.rotation) if root is not None else np.eye(4)
    locals_ = [unity.transform(bones[b].position, bones[b].rotation) for b in unity.RIGHT_ARM_CHAIN if b in bones]
    position, quat = unity.wrist_in_suit(unity.chain(t_root, locals_))
    return PoseSample(stamp_ns, "suit", position, quat)
