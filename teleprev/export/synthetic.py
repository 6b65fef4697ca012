"""Sessions with exactly known content, written with the session writer: for tests, benchmarks and
for trying the exporter without a rig.

Every stream runs at its own rate on its own slightly drifting clock with jitter and transport delay,
as the sim devices do; joint values are smooth functions of their stamp (`arm_q`, `hand_q`, ...), and
each camera frame carries its frame number as a row of black and white blocks (`read_frame_code`), so
a test can tell which recorded frame a decoded video frame came from. Messages are written in log-time
order, one second at a time, so that a ten-minute session is written in bounded memory.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from teleprev import topics as T
from teleprev.messages import Event, ImageSample, JointSample, Logged, PoseSample
from teleprev.robot.effectors import end_effector

ARM_JOINTS = tuple(f"joint{i}" for i in range(1, 7))
GLOVE_JOINTS = tuple(
    f"{j}.{a}"
    for j in (
        "index1",
        "index2",
        "index3",
        "middle1",
        "middle2",
        "middle3",
        "pinky1",
        "pinky2",
        "pinky3",
        "ring1",
        "ring2",
        "ring3",
        "thumb1",
        "thumb2",
        "thumb3",
    )
    for a in "xyz"
)
CODE_BITS = 20
_NS = 1_000_000_000


@dataclass(frozen=True)
class StreamTiming:
    rate_hz: float
    latency_ms: float = 1.0
    jitter_ms: float = 0.3
    drift_ppm: float = 0.0
    phase_ms: float = 0.0


@dataclass(frozen=True)
class EpisodeSpec:
    task: str
    duration_s: float
    discarded: bool = False
    outcome: str | None = None
    commands_after_s: float = 0.0  # execute mode from this many seconds into the episode
    camera_gaps: tuple[tuple[float, float], ...] = ()  # (from, to) seconds into the episode without frames


@dataclass(frozen=True)
class SyntheticSession:
    episodes: tuple[EpisodeSpec, ...]
    end_effector: str = "leap_hand"
    cameras: tuple[str, ...] = ("cam_front",)
    width: int = 320
    height: int = 240
    camera: StreamTiming = StreamTiming(30.0, latency_ms=20.0, jitter_ms=1.0, drift_ppm=-18.0)
    arm: StreamTiming = StreamTiming(100.0, latency_ms=1.0, jitter_ms=0.2, drift_ppm=8.0)
    hand: StreamTiming = StreamTiming(90.0, latency_ms=1.5, jitter_ms=0.3, drift_ppm=-6.0)
    glove: StreamTiming = StreamTiming(120.0, latency_ms=2.0, jitter_ms=0.3, drift_ppm=15.0)
    suit: StreamTiming = StreamTiming(60.0, latency_ms=5.0, jitter_ms=0.5, drift_ppm=-12.0)
    pause_s: float = 1.0  # between episodes (devices keep streaming)
    jpeg_quality: int = 85
    noise: float = 2.0
    frame_bank: int = 0  # 0: render every frame; n: render n frames and cycle them (long benchmark sessions)
    seed: int = 0
    extra_topics: bool = True  # also glove, wrist, retargeted and corrected
    metadata: dict = field(default_factory=dict)


def arm_q(t_s: np.ndarray | float) -> np.ndarray:
    t = np.asarray(t_s, dtype=float)[..., None]
    return 0.3 * np.sin(2 * np.pi * 0.2 * t + np.arange(6)) + np.array([0.0, -0.27, -0.11, 0.0, -0.85, -1.571])


def effector_q(name: str, t_s: np.ndarray | float) -> np.ndarray:
    """A smooth motion of the end effector's joints: hand joints waving, a jaw opening and closing, a switch."""
    t = np.asarray(t_s, dtype=float)[..., None]
    spec = end_effector(name)
    if spec.is_switch:
        return (np.sin(2 * np.pi * 0.25 * t) > 0).astype(float)
    if len(spec.joints) == 1:  # a jaw, opening in metres
        return 0.0425 + 0.04 * np.sin(2 * np.pi * 0.3 * t)
    return 0.6 + 0.5 * np.sin(2 * np.pi * 0.5 * t + np.arange(len(spec.joints)) / 3)


def glove_q(t_s: np.ndarray | float) -> np.ndarray:
    t = np.asarray(t_s, dtype=float)[..., None]
    return 0.4 * np.sin(2 * np.pi * 0.4 * t + np.arange(45) / 7)


COMMAND_LEAD_S = 0.05  # the robot follows its command 50 ms behind


def _stamps(
    timing: StreamTiming, t0: int, t1: int, rng: np.random.Generator, epoch: int
) -> tuple[np.ndarray, np.ndarray]:
    """(stamp_ns, log_ns) of a stream's samples due in [t0, t1): the ticks of its drifting clock from
    `epoch`, jittered; logged after its transport delay."""
    period = _NS / timing.rate_hz * (1 + timing.drift_ppm * 1e-6)
    start = epoch + timing.phase_ms * 1e6
    k = np.arange(max(0, int(np.ceil((t0 - start) / period))), max(0, int(np.ceil((t1 - start) / period))))
    stamps = (start + k * period + rng.normal(0, timing.jitter_ms * 1e6, len(k))).astype(np.int64)
    delay = (timing.latency_ms + np.abs(rng.normal(0, timing.jitter_ms, len(stamps)))) * 1e6
    return stamps, stamps + delay.astype(np.int64)


def frame_code_box(width: int, height: int) -> tuple[int, int]:
    """(block size, top row) of the frame-number code."""
    block = max(4, width // (CODE_BITS + 4))
    return block, height - 2 * block


_BACKDROPS: dict[tuple[int, int, int], np.ndarray] = {}


def _backdrop(w: int, h: int, camera: int) -> np.ndarray:
    """A shaded wall and a table in perspective (drawn once per size and camera)."""
    import cv2

    key = (w, h, camera)
    if key not in _BACKDROPS:
        y = np.linspace(0.0, 1.0, h)[:, None, None]
        wall = (np.array([205, 196, 186]) - 35 * y + 8 * camera).clip(0, 255)
        img = np.broadcast_to(wall, (h, w, 3)).astype(np.uint8).copy()
        table = np.array([[0.02 * w, 0.8 * h], [0.3 * w, 0.4 * h], [0.87 * w, 0.5 * h], [0.85 * w, 0.95 * h]], np.int32)
        cv2.fillConvexPoly(img, table, (75, 105, 140))
        cv2.polylines(img, [table], True, (50, 70, 95), max(1, w // 200))
        _BACKDROPS[key] = img
    return _BACKDROPS[key]


def render_frame(spec: SyntheticSession, number: int, t_s: float, camera: int, noise: np.ndarray | None) -> np.ndarray:
    """A BGR frame: wall, table, a three-link arm with a hand and an object moving with the
    synthetic joints, a time label, the frame number as blocks (read_frame_code), sensor noise."""
    import cv2

    w, h = spec.width, spec.height
    img = _backdrop(w, h, camera).copy()
    q = arm_q(t_s)
    base = np.array([0.55 * w, 0.55 * h])
    points = [base]
    angle = -np.pi / 2
    for i, length in enumerate((0.28, 0.22, 0.12)):
        angle += 0.8 * q[i + 1] + (0.9 if i == 0 else 0.4)
        points.append(points[-1] + length * h * np.array([np.cos(angle + 0.5 * q[0]), np.sin(angle)]))
    for i, (a, b) in enumerate(zip(points[:-1], points[1:])):
        cv2.line(img, tuple(int(v) for v in a), tuple(int(v) for v in b), (222, 222, 218), max(3, w // (30 + 10 * i)))
        cv2.circle(img, tuple(int(v) for v in a), max(3, w // 45), (160, 160, 158), -1)
    tip = tuple(int(v) for v in points[-1])
    fingers = effector_q(spec.end_effector, t_s).ravel()
    for k in range(4):
        bend = float(fingers[(4 * k + 1) % len(fingers)])
        end = (int(tip[0] + (k - 1.5) * w / 90), int(tip[1] + h / 20 * (1.2 - 0.5 * bend)))
        cv2.line(img, tip, end, (48, 48, 52), max(2, w // 110))
    cv2.rectangle(img, (tip[0] - w // 60, tip[1] - h // 50), (tip[0] + w // 60, tip[1] + h // 50), (40, 40, 44), -1)
    cv2.circle(img, (int(w * (0.35 + 0.08 * np.sin(0.7 * t_s))), int(h * 0.68)), max(3, w // 28), (40, 40, 200), -1)
    cv2.putText(img, f"cam{camera} t={t_s:7.2f}s", (4, max(12, h // 16)), cv2.FONT_HERSHEY_SIMPLEX, max(0.3, w / 1000),
                (0, 0, 0), 1, cv2.LINE_AA)
    if noise is not None:
        img = cv2.add(img, noise)
    block, top = frame_code_box(w, h)
    for bit in range(CODE_BITS):
        x = (bit + 2) * block
        img[top:top + block, x:x + block] = 255 if (number >> bit) & 1 else 0
    return img


def read_frame_code(rgb: np.ndarray) -> int:
    """The frame number render_frame drew into a (decoded) frame."""
    h, w = rgb.shape[:2]
    block, top = frame_code_box(w, h)
    m = block // 4
    number = 0
    for bit in range(CODE_BITS):
        x = (bit + 2) * block
        patch = rgb[top + m:top + block - m, x + m:x + block - m]
        if patch.mean() > 127:
            number |= 1 << bit
    return number


def write_session(path: str | Path, spec: SyntheticSession) -> Path:
    """Write the session; returns its path."""
    import cv2

    from teleprev.session.writer import McapSessionWriter

    rng = np.random.default_rng(spec.seed)
    ee = spec.end_effector
    ee_names = end_effector(ee).joints
    robot = end_effector(ee).robot
    inputs = {"hand": T.device_topic("glove", "glove", "hand"), "wrist": T.device_topic("suit", "suit", "wrist"),
              "arm": T.device_topic("arm", "arm", "state"), "effector": T.device_topic("hand", "hand", "state")}
    metadata = {
        "rig": {"name": "synthetic", "robot": robot, "end_effector": ee, "toml": ""},
        "session": {
            "task": spec.episodes[0].task if spec.episodes else "",
            "operator": "synthetic",
            "end_effector": ee,
        },
        "pipeline": {"inputs": json.dumps(inputs)},
        **spec.metadata,
    }
    # a bank of noise images (drawing fresh noise for every frame would dominate the run time)
    noise = [np.clip(rng.normal(0, spec.noise, (spec.height, spec.width, 3)), 0, 255).astype(np.uint8)
             for _ in range(4)] if spec.noise else [None]
    bank: list[bytes] = []
    if spec.frame_bank:
        for i in range(spec.frame_bank):
            img = render_frame(spec, i, i / spec.camera.rate_hz, 0, noise[i % len(noise)])
            bank.append(cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, spec.jpeg_quality])[1].tobytes())

    epoch = 1_000 * _NS  # the session clock at the first sample
    windows = []  # (start, stop, spec) of each episode
    t = epoch + int(0.5 * _NS)
    for ep in spec.episodes:
        windows.append((t, t + int(ep.duration_s * _NS), ep))
        t += int((ep.duration_s + spec.pause_s) * _NS)
    end = t - int(spec.pause_s * _NS) + int(0.5 * _NS)
    frame_number = {cam: 0 for cam in spec.cameras}
    last_log = 0
    with McapSessionWriter(path, metadata, fsync=False) as writer:
        for t0 in range(epoch, end, _NS):
            t1 = min(t0 + _NS, end)
            out: list[Logged] = []

            def add(topic, stamps, logs, make):
                for s, lg in zip(stamps.tolist(), logs.tolist()):
                    out.append(Logged(topic, lg, make(s)))

            s, lg = _stamps(spec.arm, t0, t1, rng, epoch)
            add(T.device_topic("arm", "arm", "state"), s, lg,
                lambda s: JointSample(s, ARM_JOINTS, arm_q((s - epoch) / _NS - COMMAND_LEAD_S)))
            s, lg = _stamps(spec.hand, t0, t1, rng, epoch)
            add(T.device_topic("hand", "hand", "state"), s, lg,
                lambda s: JointSample(s, ee_names, effector_q(ee, (s - epoch) / _NS - COMMAND_LEAD_S)))
            g, glg = _stamps(spec.glove, t0, t1, rng, epoch)
            if spec.extra_topics:
                add(
                    T.device_topic("glove", "glove", "hand"),
                    g,
                    glg,
                    lambda s: JointSample(s, GLOVE_JOINTS, glove_q((s - epoch) / _NS)),
                )
                w, wlg = _stamps(spec.suit, t0, t1, rng, epoch)
                add(
                    T.device_topic("suit", "suit", "wrist"),
                    w,
                    wlg,
                    lambda s: PoseSample(
                        s,
                        "suit",
                        np.array([0.3, 0.0, 0.2]) + 0.01 * np.sin((s - epoch) / _NS),
                        np.array([0.0, 0.0, 0.0, 1.0]),
                    ),
                )
            # pipeline outputs: one step per glove sample, stamped with the glove sample's log time
            for start, stop, ep in windows:
                inside = (glg >= start) & (glg < stop)
                steps = glg[inside]
                if spec.extra_topics:
                    add(
                        T.RETARGETED,
                        steps,
                        steps + 1000,
                        lambda s: JointSample(s, ee_names, effector_q(ee, (s - epoch) / _NS) + 0.01),
                    )
                    add(
                        T.CORRECTED,
                        steps,
                        steps + 2000,
                        lambda s: JointSample(s, ee_names, effector_q(ee, (s - epoch) / _NS)),
                    )
                execute = steps[steps >= start + int(ep.commands_after_s * _NS)]
                add(
                    T.COMMAND_ARM,
                    execute,
                    execute + 3000,
                    lambda s: JointSample(s, ARM_JOINTS, arm_q((s - epoch) / _NS)),
                )
                add(
                    T.COMMAND_HAND,
                    execute,
                    execute + 4000,
                    lambda s: JointSample(s, ee_names, effector_q(ee, (s - epoch) / _NS)),
                )
            for ci, cam in enumerate(spec.cameras):
                timing = StreamTiming(spec.camera.rate_hz, spec.camera.latency_ms, spec.camera.jitter_ms,
                                      spec.camera.drift_ppm, phase_ms=7.0 * ci)
                s, lg = _stamps(timing, t0, t1, rng, epoch)
                for stamp, log in zip(s.tolist(), lg.tolist()):
                    if any(
                        start + a * _NS <= stamp < start + b * _NS
                        for start, _, ep in windows
                        for a, b in ep.camera_gaps
                    ):
                        continue
                    n = frame_number[cam]
                    frame_number[cam] += 1
                    if bank:
                        data = bank[n % len(bank)]
                    else:
                        img = render_frame(spec, n, (stamp - epoch) / _NS, ci, noise[n % len(noise)])
                        data = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, spec.jpeg_quality])[1].tobytes()
                    out.append(
                        Logged(T.device_topic("camera", cam, "image"), log, ImageSample(stamp, cam, data, "jpeg"))
                    )
            for i, (start, stop, ep) in enumerate(windows):
                events = [(start, {"event": "start", "episode": i, "task": ep.task}),
                          (stop, {"event": "stop", "episode": i, "task": ep.task})]
                if ep.discarded:
                    events.append((stop + 1, {"event": "discard", "episode": i, "task": ep.task}))
                if ep.outcome:
                    events.append(
                        (stop + 2, {"event": "outcome", "episode": i, "task": ep.task, "outcome": ep.outcome})
                    )
                for at, data in events:
                    if t0 <= at < t1:
                        out.append(Logged(T.EPISODE, at, Event(at, "teleprev.EpisodeEvent", data)))
            out.sort(key=lambda m: m.log_time_ns)
            for msg in out:
                # log times strictly increase, as the session loop assigns them
                lt = max(msg.log_time_ns, last_log + 1)
                last_log = lt
                writer.write(Logged(msg.topic, lt, msg.payload))
    return Path(path)
