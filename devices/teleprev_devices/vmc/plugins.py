"""vmc.suit and vmc.glove: a VMC-protocol sender (Rebocap, UDCAP-class gloves, VMC-speaking apps) as a
suit and/or a glove. See devices/vmc/unity.py for the conversions and devices/vmc/receiver.py for
the socket; both plugins on one host and port share one receiver (one sender, two devices).

    [devices.suit]             [devices.glove]
    plugin = "vmc.suit"        plugin = "vmc.glove"
    port = 39539               port = 39539
    side = "right"             side = "right"      # "left": the Left* bones (a bimanual rig's left side)

VMC carries the whole skeleton, both hands included, so one sender serves both sides of a bimanual rig: a
device per side, on the same port, each with its `side`.

They listen on 127.0.0.1 unless `host` says otherwise; `allow` limits the senders accepted (others are
counted as disallowed_senders and dropped), and plugins sharing a port must list the same ones.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from teleprev.devices import (
    DeviceContext,
    JointSample,
    PoseSample,
    Sample,
    StreamSpec,
    smplx,
    transforms,
)
from teleprev_devices.fanout import FanoutDevice, ListenSettings
from teleprev_devices.vmc import unity
from teleprev_devices.vmc.receiver import Frame, VmcReceiver, acquire, release

BODY_POSE_NAMES: tuple[str, ...] = tuple(f"{j}.{c}" for j in smplx.BODY_JOINTS for c in "xyz")
_IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])
_ARM_CHAIN = {side: frozenset(chain) | {""} for side, chain in unity.ARM_CHAIN.items()}  # they move the wrist
_FINGERS = {side: frozenset(bones) for side, bones in unity.HAND_BONES.items()}


@dataclass
class VmcSettings(ListenSettings):
    port: int = 39539  # VMC's usual receiving port
    allow: tuple[
        str, ...
    ] = ()  # senders accepted (addresses or networks, e.g. "192.168.1.7", "10.0.0.0/24"); empty: any
    side: str = "right"  # whose bones: "right" (Right*) or "left" (Left*: the left hand, the left wrist)

    def __post_init__(self):
        super().__post_init__()
        if self.side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {self.side!r}")
        for a in self.allow:
            try:
                ipaddress.IPv4Network(a, strict=False)
            except ValueError:
                raise ValueError(
                    f"allow: {a!r} is not an IPv4 address or network (e.g. 192.168.1.7 or 10.0.0.0/24)"
                ) from None


@dataclass
class VmcSuitSettings(VmcSettings):
    body: bool = False  # also publish the SMPL-X body joints on /suit/<name>/body


V = TypeVar("V", bound=VmcSettings)


class _VmcDevice(FanoutDevice[V]):
    def open_receiver(self) -> VmcReceiver:
        s = self.settings
        return acquire(self.context.receivers, s.host, s.port, self.context.clock, s.allow)

    def close_receiver(self, receiver: VmcReceiver) -> None:
        release(self.context.receivers, receiver)

    def endpoint(self) -> str:
        return f"UDP {self.settings.host}:{self.settings.port}"

    def silence(self, seconds: float) -> str:
        s = self.settings
        return (f"no VMC frames on UDP {s.host}:{s.port} for {seconds:g} s "
                "(is the sender running and sending to this address?)")


class VmcSuit(_VmcDevice[VmcSuitSettings], kind="suit"):
    """The right (or `side`'s) wrist (PoseSample, frame "suit") on /suit/<name>/wrist; with body = true also the
    SMPL-X body joints' local rotations (JointSample, "<joint>.x|y|z") on /suit/<name>/body."""

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
        side = self.settings.side
        if not frame.updated.isdisjoint(_ARM_CHAIN[side]) and unity.ARM_REQUIRED[side] <= bones.keys():
            out.append(Sample(self.wrist_topic, wrist_pose(bones, frame.stamp_ns, side)))
        if self.settings.body and "Hips" in bones:
            out.append(Sample(self.body_topic, JointSample(frame.stamp_ns, BODY_POSE_NAMES, body_pose(bones))))
        return out


class VmcGlove(_VmcDevice[VmcSettings], kind="glove"):
    """The right (or `side`'s) hand's finger bones as the SMPL-X hand pose (45 values) on /glove/<name>/hand: the
    left hand's own SMPL-X pose for side = "left" (a bimanual pipeline mirrors it, as it does sim.glove's)."""

    def streams(self) -> list[StreamSpec]:
        return [StreamSpec(self.topic("hand"), "joints", self.settings.rate_hz)]

    def convert(self, frame: Frame) -> list[Sample]:
        side = self.settings.side
        if frame.updated.isdisjoint(_FINGERS[side]):
            return []
        pose = hand_pose(frame.bones, side)
        return [Sample(self.topic("hand"), JointSample(frame.stamp_ns, smplx.HAND_POSE_NAMES, pose))]


def _rotations(bones: dict, names: tuple[str, ...]) -> np.ndarray:
    """Local quaternions of the named bones; a bone never received stays in rest (identity)."""
    return np.array([bones[n].rotation if n in bones else _IDENTITY for n in names])


def hand_pose(bones: dict, side: str = "right") -> np.ndarray:
    """(45,) SMPL-X pose of the `side` hand from Unity's finger bones of that side."""
    return unity.local_rotations_to_smplx(_rotations(bones, unity.HAND_BONES[side])).reshape(45)


def body_pose(bones: dict) -> np.ndarray:
    """(66,) SMPL-X body joints' axis-angle; pelvis = the global orientation (root * Hips)."""
    quats = _rotations(bones, unity.BODY_BONES)
    root = bones.get("")
    if root is not None:
        quats[0] = transforms.quat_multiply(root.rotation, quats[0])
    return unity.local_rotations_to_smplx(quats).reshape(-1)


def wrist_pose(bones: dict, stamp_ns: int, side: str = "right") -> PoseSample:
    root = bones.get("")
    t_root = unity.transform(root.position, root.rotation) if root is not None else np.eye(4)
    locals_ = [unity.transform(bones[b].position, bones[b].rotation) for b in unity.ARM_CHAIN[side] if b in bones]
    position, quat = unity.wrist_in_suit(unity.chain(t_root, locals_), side)
    return PoseSample(stamp_ns, "suit", position, quat)
