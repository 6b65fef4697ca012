"""Realistic hand poses for the pose-reading tests and bench/hand.py: IWER's shipped hand poses, read from
the installed `iwer` package (never copied here), and sweeps of what real hands do that an abduction-first
reading got wrong: fingers flexed to 110 degrees with a few degrees of sideways deviation and some twist,
and the thumb's metacarpal turned about its own bone from -150 to +60 degrees.

Each pose is a right hand's 25 WebXR joints (position, quaternion x y z w, radius), the headset's view;
`hands.hand_pose` turns them into the SMPL-X pose that the WebXR plugin publishes, and `vmc_bones` into the
Unity bone rotations that a VMC sender streams for the same hand.
"""

from __future__ import annotations

import re
import socket
from pathlib import Path

import numpy as np

from teleprev.clock import SessionClock
from teleprev.devices.contract import DeviceContext
from teleprev.human import smplx
from teleprev.messages import JointSample
from teleprev.transforms import axis_angle_to_matrix, matrix_to_quat, quat_to_matrix
from teleprev_devices.vmc import VmcGlove, unity
from teleprev_devices.vmc.plugins import VmcSettings
from teleprev_devices.webxr import hands, wire
from tests.helpers.ports import free_port
from tests.helpers.vmc import bone, bundle
from tests.helpers.wait import wait_until
from tests.helpers.xr_hands import local_rotations, xr_hand

IWER_HAND_POSES = Path(__file__).resolve().parents[1] / "webxr/browser/node_modules/iwer/lib/device/configs/hand"
IWER_POSE_NAMES = ("relaxed", "point", "pinch")
# IWER's mirrorMatrixToRight (lib/device/XRHandInput.js): its poses are a left hand's, the right hand is
# each column-major joint matrix times this, element by element.
_MIRROR_TO_RIGHT = np.array([1, -1, -1, 0, -1, 1, 1, 0, -1, 1, 1, 0, -1, 1, 1, 1], dtype=float)
_JOINT_MATRIX = re.compile(r"'?([a-z-]+)'?\s*:\s*\{\s*offsetMatrix\s*:\s*\[([^\]]*)\]")

FLEXION_SWEEP_DEG = np.arange(0.0, 111.0, 2.0)  # every finger's knuckle flexion, up to 110 degrees
DEVIATION_SWEEP_DEG = (-6.0, -3.0, 0.0, 3.0, 6.0)  # a flexed finger's sideways deviation
FINGER_TWIST_SWEEP_DEG = (-10.0, 0.0, 10.0)  # each finger segment turned about its own bone
THUMB_TWIST_SWEEP_DEG = np.arange(-150.0, 61.0, 5.0)  # the thumb's metacarpal about its own bone


def iwer_pose(name: str) -> np.ndarray:
    """(25, 8) joints of IWER's shipped `name` pose ("relaxed", "point", "pinch") for the right hand, as
    IWER mirrors it; an error naming the file when the iwer package is not installed."""
    path = IWER_HAND_POSES / f"{name}.js"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: IWER's hand poses are missing (the test command installs the iwer "
                                "package under tests/webxr/browser/node_modules)")
    found = {m.group(1): np.array([float(v) for v in m.group(2).split(",") if v.strip()])
             for m in _JOINT_MATRIX.finditer(path.read_text())}
    joints = np.zeros((25, 8))
    for joint, i in hands.JOINT_INDEX.items():
        m = (found[joint] * _MIRROR_TO_RIGHT).reshape(4, 4).T  # column-major
        joints[i, :3], joints[i, 3:7], joints[i, 7] = m[:3, 3], matrix_to_quat(m[:3, :3]), 0.01
    return joints


_THUMB = [
    hands.JOINT_INDEX[j] for j in ("thumb-metacarpal", "thumb-phalanx-proximal", "thumb-phalanx-distal", "thumb-tip")
]
_WRIST, _METACARPAL = hands.JOINT_INDEX["wrist"], hands.JOINT_INDEX["thumb-metacarpal"]


def _bone_axis(joints: np.ndarray) -> np.ndarray:
    """The thumb metacarpal's bone direction (its joint frame's -z) in the reference space."""
    return -quat_to_matrix(joints[_METACARPAL, 3:7])[:, 2]


def thumb_twist(joints: np.ndarray) -> float:
    """The thumb metacarpal's turn about its own bone relative to the wrist (rad): the twist of the
    swing-twist split of its rotation from the wrist, about the bone (WebXR: the joint's -z)."""
    local = quat_to_matrix(joints[_WRIST, 3:7]).T @ quat_to_matrix(joints[_METACARPAL, 3:7])
    x, y, z, w = matrix_to_quat(local)
    return float(np.remainder(2.0 * np.arctan2(-z, w) + np.pi, 2.0 * np.pi) - np.pi)


def with_thumb_twist(joints: np.ndarray, twist: float) -> np.ndarray:
    """The hand with its whole thumb turned about the metacarpal's bone (through the metacarpal's base)
    so that the metacarpal's twist is `twist` rad: the thumb's opposition, its bones' directions relative to
    each other unchanged."""
    axis = _bone_axis(joints)
    turn = axis_angle_to_matrix(axis * (twist - thumb_twist(joints)))
    out = joints.copy()
    base = joints[_METACARPAL, :3]
    for i in _THUMB:
        out[i, :3] = base + turn @ (joints[i, :3] - base)
        out[i, 3:7] = matrix_to_quat(turn @ quat_to_matrix(joints[i, 3:7]))
    return out


def flexed_hand(flexion_deg: float, deviation_deg: float, twist_deg: float) -> np.ndarray:
    """(25, 8) joints of a right hand whose four fingers are flexed by `flexion_deg` at the knuckle (and
    0.9 and 0.6 of it at the next joints), each segment deviating `deviation_deg` sideways out of its
    plane of curling and turned `twist_deg` about its own bone; the thumb resting across the palm."""
    f, d, t = np.radians([flexion_deg, deviation_deg, twist_deg])
    flexion, deviation, twist = np.zeros(15), np.zeros(15), np.zeros(15)
    for finger in ("index", "middle", "ring", "pinky"):
        for k, share in ((1, 1.0), (2, 0.9), (3, 0.6)):
            j = smplx.JOINT_INDEX[f"{finger}{k}"]
            flexion[j], deviation[j], twist[j] = share * f, d, t
    for k, (fk, ak) in enumerate(((0.5, -0.3), (0.4, 0.0), (0.3, 0.0)), start=1):
        j = smplx.JOINT_INDEX[f"thumb{k}"]
        flexion[j], deviation[j] = fk, ak
    return xr_hand(local_rotations(flexion, deviation, twist), np.eye(3), [0.1, 1.1, -0.3])


def sweep() -> dict[str, list[np.ndarray]]:
    """{what: right hands (25, 8)}: IWER's poses, the finger flexion sweep and the thumb twist sweep (on
    each of IWER's poses)."""
    iwer = [iwer_pose(n) for n in IWER_POSE_NAMES]
    flexion = [
        flexed_hand(f, d, t) for f in FLEXION_SWEEP_DEG for d in DEVIATION_SWEEP_DEG for t in FINGER_TWIST_SWEEP_DEG
    ]
    thumb = [with_thumb_twist(p, np.radians(t)) for p in iwer for t in THUMB_TWIST_SWEEP_DEG]
    return {"iwer": iwer, "flexion": flexion, "thumb_twist": thumb}


def vmc_bones(hand_pose: np.ndarray) -> dict[str, np.ndarray]:
    """{Unity bone: local rotation (x y z w)}: the right hand's finger bones as a VMC sender streams the
    SMPL-X pose (45,) (teleprev_devices/vmc/unity.py's D R D, taken back)."""
    rotations = np.asarray(hand_pose, dtype=float).reshape(15, 3)
    return {bone: matrix_to_quat(unity.D @ axis_angle_to_matrix(v) @ unity.D)
            for bone, v in zip(unity.RIGHT_HAND_BONES, rotations)}


def through_webxr(joints: list[np.ndarray]) -> list[JointSample]:
    """Each right hand as the WebXR glove publishes it: packed as the page sends a frame (float32, wire.py),
    unpacked and turned into the SMPL-X hand pose (hands.hand_pose, WebXrGlove.convert's)."""
    out = []
    for k, j in enumerate(joints):
        frame = wire.unpack(wire.pack(k, float(k), float(k), right=j))
        out.append(JointSample(k, smplx.HAND_POSE_NAMES, hands.hand_pose(frame.right)))
    return out


def through_vmc(joints: list[np.ndarray], timeout_s: float = 5.0) -> list[JointSample]:
    """Each right hand as a vmc.glove publishes it: its finger bones sent as a VMC sender sends them (OSC
    bundles over UDP loopback), received and converted by a real VmcGlove, one hand at a time."""
    port = free_port()
    glove = VmcGlove("g", VmcSettings(port=port), DeviceContext(SessionClock()))
    glove.connect()
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    out: list[JointSample] = []
    try:
        for j in joints:
            bones = vmc_bones(hands.hand_pose(j))
            sender.sendto(bundle(*[bone(name, (0.03, 0.0, 0.0), q) for name, q in bones.items()]).dgram,
                          ("127.0.0.1", port))
            got: list = []
            wait_until(lambda: got.extend(glove.read(0.01)) or got, timeout_s, what="the VMC glove's sample")
            out.append(got[-1].payload)
    finally:
        sender.close()
        glove.disconnect()
    return out
