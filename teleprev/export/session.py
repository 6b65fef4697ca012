"""One session into a LeRobot dataset: its features resolved, each episode planned on the frame
timeline (timeline.py) and written frame by frame, its camera frames decoded one at a time.

`SessionSource` opens and checks a session (nothing is written); `export_session` writes its episodes.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from teleprev.errors import ConfigError, SessionError
from teleprev.export.recipe import DEPTH, IMAGE, Recipe, ResolvedFeature, resolve
from teleprev.export.report import EpisodeReport, SessionReport
from teleprev.export.streams import probe_joint_names, read_episode
from teleprev.export.timeline import EpisodePlan, plan_episode
from teleprev.messages import DepthSample, ImageSample
from teleprev.robot.effectors import EFFECTORS
from teleprev.topics import TASKS_RECORD

_NS = 1_000_000_000
DEFAULT_FPS = 30  # without a camera
MARGIN_NS = _NS  # read this much before and after an episode: the state just before it, late frames
# LeRobot's per-frame episode marks (as in its own datasets): done on an episode's last frame, success on
# that frame of an episode the operator marked successful
MARK_FEATURES = {"next.done": {"dtype": "bool", "shape": (1,), "names": None},
                 "next.success": {"dtype": "bool", "shape": (1,), "names": None}}


@dataclass
class Progress:
    """What an export reports while it runs (the CLI draws bars from it)."""

    kind: str  # "session" | "episode" | "frames" | "episode_done" | "session_done" | "phase" | "note" (a line to print)
    session: str
    total: int = 0  # episodes of a session, frames of an episode
    count: int = 0  # frames written since the last report
    episode: int = -1
    report: object = None


Reporter = Callable[[Progress], None]


def no_progress(_: Progress) -> None:
    pass


@dataclass
class SessionSource:
    """A session opened for export, with the recipe resolved against it."""

    path: Path
    recipe: Recipe
    fps: int = 0  # asked for (0: the recipe's, else the reference camera's rate)
    open_reader: Callable | None = None  # path -> a reader with SessionReader's surface (None: a SessionReader)
    reader: object = field(init=False)
    features: list[ResolvedFeature] = field(init=False)
    names: dict[str, tuple[str, ...]] = field(init=False)  # joint names per joint topic
    image_shapes: dict[str, tuple[int, int, int]] = field(init=False)  # (h, w, 3) per camera, (h, w, 1) per depth
    reference: str | None = field(init=False)  # the reference camera's topic
    camera_rate_hz: float = field(init=False)

    def __post_init__(self):
        from teleprev.session.reader import SessionReader

        self.path = Path(self.path)
        self.reader = (self.open_reader or SessionReader)(self.path)
        try:
            self._resolve()
        except BaseException:
            self.reader.close()
            raise

    def _resolve(self) -> None:
        where = str(self.path)
        reader = self.reader
        self.features = resolve(self.recipe, reader.topics, reader.metadata, where)
        self.names, self.image_shapes = {}, {}
        for f in self.features:
            for s in f.sources:
                if s.schema in (IMAGE, DEPTH):
                    self.image_shapes[s.topic] = _first_image_shape(reader, s.topic)
                elif s.topic not in self.names:
                    self.names[s.topic] = probe_joint_names(reader, s.topic, s.schema)
        # the frame times follow a colour camera; a depth stream leads only where there is none
        cameras = [f.sources[0] for f in self.features if f.is_image] + [f.sources[0] for f in self.features
                                                                          if f.is_depth]
        wanted = self.recipe.export.reference_camera
        if wanted:
            match = [s for s in cameras if s.prefix == wanted]
            if not match:
                raise ConfigError(f"reference_camera {wanted!r} is not among the exported cameras "
                                  f"({', '.join(s.prefix for s in cameras) or 'none'})", self.recipe.path)
            self.reference = match[0].topic
        else:
            self.reference = cameras[0].topic if cameras else None
        self.camera_rate_hz = _rate(reader, self.reference) if self.reference else 0.0
        if self.reference and self.camera_rate_hz == 0.0:
            raise SessionError(f"camera {self.reference} has fewer than two frames", where)

    @property
    def robot_type(self) -> str:
        return self.reader.metadata.get("rig", {}).get("robot", "") or "unknown"

    def dataset_fps(self) -> int:
        fps = self.fps or self.recipe.export.fps
        if not fps:
            return max(1, round(self.camera_rate_hz)) if self.reference else DEFAULT_FPS
        if self.reference and fps > self.camera_rate_hz * 1.02:
            raise ConfigError(f"{fps} frames per second is more than camera {self.reference} delivers "
                              f"({self.camera_rate_hz:.1f} Hz): frames would repeat; choose --fps "
                              f"{math.floor(self.camera_rate_hz * 1.02)} or less", str(self.path))
        return fps

    def lerobot_features(self) -> dict:
        """The LeRobot feature spec: float32 vectors whose names list the joints, RGB videos, and depth maps
        (one channel, flagged is_depth_map: lerobot's depth encoder writes them)."""
        out = {}
        for f in self.features:
            if f.is_video:
                h, w, c = self.image_shapes[f.sources[0].topic]
                out[f.name] = {"dtype": "video", "shape": (h, w, c), "names": ["height", "width", "channels"]}
                if f.is_depth:
                    out[f.name]["info"] = {"is_depth_map": True}
            else:
                names = [f"{s.prefix}.{j}" for s in f.sources for j in self.names[s.topic]]
                out[f.name] = {"dtype": "float32", "shape": (len(names),), "names": names}
        out.update(MARK_FEATURES)
        return out

    def task_of(self, episode) -> str:
        """The episode's task as LeRobot gets it: the instruction in words when the session's "tasks"
        metadata (the rig's [tasks], record --task-text) has one for its id, else the id."""
        task = episode.task or self.reader.metadata.get("session", {}).get("task", "") or "teleoperation"
        return self.reader.metadata.get(TASKS_RECORD, {}).get(task, task)

    def close(self) -> None:
        self.reader.close()


def _first_image_shape(reader, topic: str) -> tuple[int, int, int]:
    for msg in reader.messages([topic]):
        return _decode(msg.payload, topic, msg.log_time_ns, str(reader.path)).shape
    raise SessionError(f"camera {topic} has no frames", str(reader.path))


def _rate(reader, topic: str) -> float:
    """A camera's frame rate from the median interval of its first 120 frames."""
    stamps = [m.payload.stamp_ns for m in itertools.islice(reader.messages([topic]), 120)]
    if len(stamps) < 2:
        return 0.0
    d = np.diff(np.sort(np.array(stamps, dtype=np.int64)))
    d = d[d > 0]
    return _NS / float(np.median(d)) if len(d) else 0.0


def rgb_image(data) -> np.ndarray | None:
    """A camera sample's picture as the datasets hold it (H x W x 3, RGB), or None where it does not decode:
    the same for an export and for a policy that observes the live camera (teleprev/live/rollout/policy.py)."""
    if isinstance(data, np.ndarray):  # a raw image a foreign reader already laid out as RGB
        return np.ascontiguousarray(data)
    import cv2

    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR_RGB)


def depth_image(sample: DepthSample) -> np.ndarray:
    """A depth sample as the datasets hold it: (H, W, 1) float32 metres, 0 where the camera saw nothing
    (lerobot's quantiser clips it to its depth_min)."""
    return sample.metres()[:, :, None]


def _decode(payload, topic: str, log_ns: int, where: str) -> np.ndarray:
    """A camera message's image as the dataset gets it (RGB, or depth in metres)."""
    if isinstance(payload, DepthSample):
        return depth_image(payload)
    if not isinstance(payload, ImageSample):
        raise SessionError(f"{topic} at log time {log_ns}: expected an image, got {type(payload).__name__}", where)
    img = rgb_image(payload.data)
    if img is None:
        raise SessionError(f"the image on {topic} at log time {log_ns} does not decode", where)
    return img


@dataclass(frozen=True)
class ExportSettings:
    fps: int
    include_discarded: bool = False
    selected: dict[str, frozenset[int]] | None = None  # session -> the episodes to export (None: every one)


def export_session(
    source: SessionSource, dataset, settings: ExportSettings, report: Reporter = no_progress
) -> SessionReport:
    """Write the session's episodes into `dataset` (a LeRobotDataset in write mode)."""
    name = str(source.path)
    episodes = source.reader.episodes()
    if settings.selected is not None:
        wanted = settings.selected.get(name, frozenset())
        episodes = [ep for ep in episodes if ep.index in wanted]
    report(Progress("session", name, total=len(episodes)))
    result = SessionReport(name, len(episodes))
    end_ns = source.reader.end_ns or 0
    for ep in episodes:
        rep = _export_episode(source, dataset, settings, ep, end_ns, report)
        result.episodes.append(rep)
        report(Progress("episode_done", name, episode=ep.index, report=rep))
    if not episodes:
        result.notes.append("no episodes recorded (nothing between episode start and stop events; a file teleprev did "
                            "not record is cut into episodes by `teleprev import`)")
    report(Progress("session_done", name, report=result))
    return result


def _export_episode(
    source: SessionSource, dataset, settings: ExportSettings, ep, end_ns: int, report: Reporter
) -> EpisodeReport:
    name = str(source.path)
    task = source.task_of(ep)
    rep = EpisodeReport(name, ep.index, task)
    if ep.discarded and not settings.include_discarded:
        rep.dropped = "discarded by the operator"
        return rep
    stop = ep.stop_ns if ep.stop_ns is not None else end_ns
    if ep.stop_ns is None:
        rep.notes.append("never stopped (the session ended first): exported up to the session's end")
    fps = settings.fps
    export = source.recipe.export
    max_gap = int(export.max_gap_ms * 1e6)
    joint_topics = dict(source.names)
    camera_topics = list(source.image_shapes)
    window = (ep.start_ns - MARGIN_NS, stop + MARGIN_NS)
    joints, cams = read_episode(source.reader, joint_topics, camera_topics, *window)
    # lookups per (topic, timing); named by the recipe's stream entry in messages
    streams, labels = {}, {}
    for f in source.features:
        for s in f.sources:
            if s.topic == source.reference:
                continue
            timing = _timing(f, s)
            key = _key(s.topic, timing)
            stamps = cams[s.topic].stamps if s.schema in (IMAGE, DEPTH) else joints[s.topic].stamps
            streams[key] = (stamps, timing)
            labels[key] = s.entry
    ref_key = None
    if source.reference:
        ref_key = _key(source.reference, False)
        labels[ref_key] = source.reference.split("/")[2]
    min_frames = max(1, math.ceil(export.min_episode_s * fps))
    plan = plan_episode(ref_key, cams[source.reference].stamps if source.reference else None, streams,
                        ep.start_ns, stop, fps, max_gap, min_frames)
    stamps = {k: v[0] for k, v in streams.items()}
    if ref_key:
        stamps[ref_key] = cams[source.reference].stamps
    _describe(plan, stamps, labels, ep.start_ns, fps, rep)
    inner = [g for g in plan.gaps if not g.at_edge]
    if inner and export.on_gap != "split":
        text = "; ".join(rep.gaps)
        if export.on_gap == "fail":
            raise SessionError(
                f'episode {ep.index}: {text} (on_gap = "fail"; "split" would cut the episode there)', name
            )
        rep.dropped = f"gap: {text}"
        return rep
    if not len(plan.frames.time_ns):
        rep.dropped = f"camera {labels.get(ref_key, '')} has no frames in this episode"
        return rep
    if not plan.pieces:
        why = "too short after trimming" if plan.short else "no frame where every stream has a sample"
        rep.dropped = f"{why} ({'; '.join(rep.notes + rep.gaps)})"
        return rep
    _write_pieces(source, dataset, plan, joints, cams, window, task, ref_key, report, rep, ep.outcome == "success")
    return rep


def _timing(f: ResolvedFeature, s) -> bool | str:
    """How a feature's stream is looked up (see plan_episode): False (an observation), "trajectory" (an
    action: the commanded trajectory at the frame's time), True (the first command sent in the frame) or
    "next"."""
    if s.schema in (IMAGE, DEPTH) or not f.is_action:
        return False
    return "next" if f.next_frame else True if f.sent else "trajectory"


def _key(topic: str, timing: bool | str) -> str:
    return f"{topic}|{timing if isinstance(timing, str) else 'sent' if timing else 'observation'}"


def _interpolation(source: SessionSource, topic: str, stream) -> str:
    """How a command stream moves between its commands: the arm's jerk-limited profile (cubic Hermite on
    the recorded positions and velocities), a switch's step (hold), else straight segments (the hand's
    commands: each one a segment from the last, as the swept check saw it)."""
    if _is_command(topic, "arm") and stream.velocities is not None:
        return "hermite"
    effector = EFFECTORS.get(source.reader.metadata.get("rig", {}).get("end_effector", ""))
    if _is_command(topic, "hand") and effector is not None and effector.is_switch:
        return "hold"
    return "linear"


def _is_command(topic: str, kind: str) -> bool:
    """The commands to the arm (or hand): /command/arm, or a bimanual side's /command/<side>/arm."""
    return topic == f"/command/{kind}" or (topic.startswith("/command/") and topic.endswith(f"/{kind}"))


def _sampled(stream, look, frames: np.ndarray, kind: str) -> np.ndarray:
    """The values of a trajectory lookup at the frames: between two commands as `kind` says, else the
    command itself (held)."""
    i = look.index[frames]
    j = look.next[frames]
    values = stream.values[i].copy()
    between = np.flatnonzero(j >= 0)
    if not len(between) or kind == "hold":
        return values
    a, b, s = i[between], j[between], look.frac[frames][between][:, None]
    p0, p1 = stream.values[a], stream.values[b]
    if kind == "hermite":
        h = ((stream.stamps[b] - stream.stamps[a]) / 1e9)[:, None]
        v0, v1 = stream.velocities[a], stream.velocities[b]
        s2, s3 = s * s, s * s * s
        values[between] = ((2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * h * v0 + (3 * s2 - 2 * s3) * p1
                           + (s3 - s2) * h * v1)
    else:
        values[between] = p0 + s * (p1 - p0)
    return values


def _describe(plan: EpisodePlan, stamps: dict[str, np.ndarray], labels: dict[str, str], start_ns: int, fps: int,
              rep: EpisodeReport) -> None:
    """Notes for the trimmed ends and the gaps: which stream was silent, from when to when."""
    t = plan.frames.time_ns

    def silence(key: str, first: int) -> str:
        s = stamps[key]
        i = int(np.searchsorted(s, t[first], side="right")) - 1
        a = "the start" if i < 0 else f"{(s[i] - start_ns) / _NS:.2f} s"
        b = "the end" if i + 1 >= len(s) else f"{(s[i + 1] - start_ns) / _NS:.2f} s"
        return f"{labels.get(key, key)} silent from {a} to {b}"

    for g in plan.gaps:
        text = ", ".join(silence(k, g.first) for k in g.streams)
        if g.at_edge:
            rep.trimmed_s += (g.stop - g.first) / fps
            rep.notes.append(
                f"trimmed {(g.stop - g.first) / fps:.2f} s at the {'start' if g.first == 0 else 'end'}: {text}"
            )
        else:
            rep.gaps.append(text)
    for first, stop in plan.short:
        rep.notes.append(
            f"left out {stop - first} frames at {(t[first] - start_ns) / _NS:.2f} s (shorter than min_episode_s)"
        )


def _write_pieces(source: SessionSource, dataset, plan: EpisodePlan, joints, cams, window: tuple[int, int], task: str,
                  ref_key, report: Reporter, rep: EpisodeReport, success: bool) -> None:
    name = str(source.path)
    frames_all = np.concatenate([np.arange(a, b) for a, b in plan.pieces])
    report(Progress("episode", name, total=len(frames_all), episode=rep.index))
    # joint features: (frames, values) float32 matrices
    matrices = {}
    align = []
    for f in source.features:
        if f.is_video:
            continue
        cols = []
        for s in f.sources:
            key = _key(s.topic, _timing(f, s))
            look = plan.lookups[key]
            if look.next is not None:
                cols.append(
                    _sampled(joints[s.topic], look, frames_all, _interpolation(source, s.topic, joints[s.topic]))
                )
            else:
                cols.append(joints[s.topic].values[look.index[frames_all]])
            align.append(look.err_ns[frames_all])
        matrices[f.name] = np.concatenate(cols, axis=1).astype(np.float32)
    images = _ImageStream(source, plan, cams, frames_all, ref_key, window)
    rep.align_err_ms = float(np.max(align)) / 1e6 if align else 0.0
    rep.image_err_ms = images.err_ms
    rep.held_frames = int((~plan.frames.fresh[frames_all]).sum())
    row = 0
    piece_of = np.concatenate([np.full(b - a, i) for i, (a, b) in enumerate(plan.pieces)])
    pending = 0
    try:
        for k, imgs in images:
            frame = {fname: m[row] for fname, m in matrices.items()}
            frame.update(imgs)
            frame["task"] = task
            last = row + 1 == len(frames_all) or piece_of[row + 1] != piece_of[row]
            frame["next.done"] = np.array([last])
            frame["next.success"] = np.array([last and success and row + 1 == len(frames_all)])
            dataset.add_frame(frame)
            row += 1
            pending += 1
            if pending == 30:
                report(Progress("frames", name, count=pending, episode=rep.index))
                pending = 0
            if row == len(frames_all) or piece_of[row] != piece_of[row - 1]:
                dataset.save_episode()
                a, b = plan.pieces[piece_of[row - 1]]
                rep.pieces += 1
                rep.frames += b - a
                rep.duration_s += (b - a) / dataset.fps
    except BaseException:
        _clear(dataset)
        raise
    if pending:
        report(Progress("frames", name, count=pending, episode=rep.index))
    if row != len(frames_all):
        raise SessionError(f"episode {rep.index}: only {row} of {len(frames_all)} camera frames could be read", name)


def _clear(dataset) -> None:
    try:
        if dataset.has_pending_frames():
            dataset.clear_episode_buffer()
    except Exception:  # the export is failing already; the staging folder goes away with it
        pass


class _ImageStream:
    """Yields (frame, {feature: RGB image}) for the planned frames in order, reading the cameras'
    messages once, in log-time order, and decoding each needed image once. `window` must be the one the
    episode's streams were read with: message ordinals count from its start."""

    def __init__(self, source: SessionSource, plan: EpisodePlan, cams, frames_all: np.ndarray, ref_key,
                 window: tuple[int, int]):
        self.source = source
        self.frames = frames_all
        self.features = {}  # topic -> feature name
        self.need: dict[str, np.ndarray] = {}  # topic -> message ordinal per frame
        errs = []
        for f in source.features:
            if not f.is_video:
                continue
            topic = f.sources[0].topic
            key = ref_key if topic == source.reference else _key(topic, False)
            look = plan.lookups[key]
            self.features[topic] = f.name
            self.need[topic] = cams[topic].ordinal[look.index[frames_all]]
            errs.append(look.err_ns[frames_all])
        self.err_ms = float(np.max(errs)) / 1e6 if errs else 0.0
        self.window = window

    def __iter__(self):
        if not self.need:
            for k in self.frames:
                yield int(k), {}
            return
        where = str(self.source.path)
        uses = {t: _counts(o) for t, o in self.need.items()}
        data: dict[str, dict[int, np.ndarray | bytes]] = {t: {} for t in self.need}
        seen = {t: -1 for t in self.need}
        nxt = 0
        n = len(self.frames)
        reader = self.source.reader
        for msg in reader.messages(list(self.need), *self.window):
            topic = msg.topic
            seen[topic] += 1
            ordinal = seen[topic]
            if ordinal in uses[topic]:
                data[topic][ordinal] = (msg.payload, msg.log_time_ns)
            while nxt < n and all(self.need[t][nxt] in data[t] for t in self.need):
                images = {}
                for t, store in data.items():
                    o = int(self.need[t][nxt])
                    item = store[o]
                    if isinstance(item, tuple):
                        item = store[o] = self._image(t, *item, where)
                    images[self.features[t]] = item
                    uses[t][o] -= 1
                    if uses[t][o] == 0:
                        del store[o]
                        del uses[t][o]
                yield int(self.frames[nxt]), images
                nxt += 1
            if nxt == n:
                return

    def _image(self, topic: str, payload, log_ns: int, where: str) -> np.ndarray:
        img = _decode(payload, topic, log_ns, where)
        if img.shape != self.source.image_shapes[topic]:
            raise SessionError(f"the image on {topic} at log time {log_ns} is {img.shape[1]}x{img.shape[0]}, the "
                               f"camera's first frame was {self.source.image_shapes[topic][1]}x"
                               f"{self.source.image_shapes[topic][0]}", where)
        return img


def _counts(ordinals: np.ndarray) -> dict[int, int]:
    values, counts = np.unique(ordinals, return_counts=True)
    return dict(zip(values.tolist(), counts.tolist()))
