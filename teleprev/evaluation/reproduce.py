"""Re-running the pipeline on a session's recorded raw streams.

The session's raw device streams and mode switches go through a PipelineDriver in log-time order, as
they went through the live session loop; the driver is built from the rig and calibration the session
recorded in its metadata (or from a rig file given instead) and from the models given (default: the
shipped ones). Every step's outputs are kept next to what the session recorded for the same step.
"""

from __future__ import annotations

import itertools
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from teleprev import numeric_platform
from teleprev.errors import SessionError
from teleprev.messages import Event, JointSample
from teleprev.live.build import build_pipeline, rig_calibration
from teleprev.pipeline.driver import InputTopics, PipelineDriver
from teleprev.pipeline.step import Pipeline
from teleprev.retarget.calibration import load_calibration_text
from teleprev.rig import load_recorded_rig, load_rig
from teleprev.robot.effectors import EndEffector
from teleprev import topics
from teleprev.session.reader import Episode, SessionReader

PREPARE_BLOCK = 4096  # messages read ahead per batch of glove-sample preparation (bounds the memory)
RECORDED_OUTPUTS = (topics.RETARGETED, topics.CORRECTED, topics.ARM_TARGET, topics.COMMAND_ARM, topics.COMMAND_HAND)


@dataclass
class Rerun:
    """Per pipeline step (one row per glove sample), re-run and recorded side by side; NaN where a step
    produced nothing on that stream (e.g. no command in preview)."""

    session: Path
    t_ns: np.ndarray
    mode: np.ndarray  # "preview" | "execute"
    corrector: np.ndarray  # "untouched" | "ccn" | "fallback" | "held"
    latency_ns: np.ndarray
    flags: list[list[str]]
    arm_names: tuple[str, ...]
    effector_names: tuple[str, ...]
    effector: EndEffector  # the end effector re-run (its row of the table)
    rerun: dict[str, np.ndarray]  # topic -> (steps, joints)
    recorded: dict[str, np.ndarray]
    episodes: list[Episode]
    metadata: dict[str, dict[str, str]]
    models_match: bool | None  # the recorded models' hashes equal those used now (None: unknown)
    rig_source: str
    duration_s: float
    input_messages: int
    wall_s: float = 0.0
    notes: list[str] = field(default_factory=list)


def _format_version(meta: dict) -> int:
    try:
        return int(meta.get("teleprev", {}).get("format_version", topics.FORMAT_VERSION))
    except ValueError:
        return topics.FORMAT_VERSION


def recorded_with_motion(meta: dict) -> bool:
    """Whether the session's commands went through the motion limits (format 2 on); older sessions are
    re-run as they were recorded, with the speed caps alone."""
    return _format_version(meta) >= topics.MOTION_FORMAT_VERSION


def recorded_compiled(meta: dict) -> bool:
    """Whether the session was computed by the compiled hot path (format 3 on); older sessions are re-run
    with the numpy arithmetic that recorded them, so they still reproduce bit for bit."""
    return _format_version(meta) >= topics.COMPILED_FORMAT_VERSION


def _pipeline_for(reader: SessionReader, path: Path, models, rig_path):
    meta = reader.metadata
    motion, compiled = recorded_with_motion(meta), recorded_compiled(meta)
    if rig_path:
        rig = load_rig(rig_path)
        return build_pipeline(rig, models, rig_calibration(rig), motion=motion, compiled=compiled), f"rig file {rig_path}"
    if not meta.get("rig", {}).get("toml"):
        raise SessionError("the session does not carry its rig (metadata 'rig'); pass --config RIG", str(path))
    calibration_toml = meta.get("calibration", {}).get("toml", "")
    # a recorded rig is anchored at its session's folder (teleprev.rig.load_recorded_rig): part of the key
    key = (meta["rig"]["toml"], str(path.resolve().parent), calibration_toml, str(models) if models else None, motion, compiled)
    if key not in _BUILT:
        rig = load_recorded_rig(meta, path)
        calibration = load_calibration_text(calibration_toml, f"{path}: recorded calibration")
        if len(_BUILT) >= 8:
            _BUILT.pop(next(iter(_BUILT)))
        _BUILT[key] = build_pipeline(rig, models, calibration, motion=motion, compiled=compiled)
    return _BUILT[key], "recorded in the session"


# Pipelines built from recorded rigs, by (rig, session folder, calibration, models, motion, compiled): the sessions
# of a corpus mostly share one rig, and building one (rig plugins, URDFs, models, checkers) costs about
# 0.1 s. A Pipeline keeps no state between steps (PipelineState does), so sessions can share one.
_BUILT: dict[tuple, Pipeline] = {}


def _models_match(meta: dict, pipeline: Pipeline) -> bool | None:
    now = pipeline.model_hashes()
    if now is None:
        return True  # the pipeline runs no models
    recorded = meta.get("models")
    return now == recorded if recorded else None


def _prepared(driver: PipelineDriver, messages, block: int = PREPARE_BLOCK):
    """(message, its prepared glove input or None): the glove samples' state-independent work done a
    block of messages at a time, ahead of the sequential pass (bit for bit what the step would compute)."""
    messages = iter(messages)
    while chunk := list(itertools.islice(messages, block)):
        yield from zip(chunk, driver.prepare(chunk))


def rerun_session(path: str | Path, models: str | Path | None = None, rig_path: str | Path | None = None) -> Rerun:
    path = Path(path)
    started = time.perf_counter()
    reader = SessionReader(path)
    meta = reader.metadata
    pipeline, rig_source = _pipeline_for(reader, path, models, rig_path)
    try:
        inputs = InputTopics(**json.loads(meta["pipeline"]["inputs"]))
    except (KeyError, TypeError, ValueError):
        raise SessionError("the session does not say which streams fed its pipeline (metadata 'pipeline')", str(path)) from None
    missing = [t for t in (inputs.hand, inputs.wrist, inputs.arm, inputs.effector) if t not in reader.topics]
    if missing:
        raise SessionError(f"the session lacks the pipeline's input streams {missing}", str(path))
    driver = PipelineDriver(pipeline, inputs)
    arm_names, eff_names = pipeline.arm_names, pipeline.effector_names
    widths = {topics.RETARGETED: len(eff_names), topics.CORRECTED: len(eff_names), topics.ARM_TARGET: len(arm_names),
              topics.COMMAND_ARM: len(arm_names), topics.COMMAND_HAND: len(eff_names)}

    t_list, mode, action, latency, flags = [], [], [], [], []
    rows: dict[str, list] = {k: [] for k in RECORDED_OUTPUTS}
    recorded_by_stamp: dict[str, dict[int, np.ndarray]] = {k: {} for k in RECORDED_OUTPUTS}
    n_inputs = 0
    wanted = [inputs.hand, inputs.wrist, inputs.arm, inputs.effector, topics.MODE, *RECORDED_OUTPUTS]
    # One BLAS thread: the batched CPN is a few hundred rows, where threads cost more than they give (on a
    # busy machine or with -j workers, many times more); single configurations never use them anyway.
    with threadpool_limits(1, user_api="blas"):
        for msg, hand_input in _prepared(driver, reader.messages(topics=[t for t in wanted if t in reader.topics])):
            if msg.topic in recorded_by_stamp:
                if isinstance(msg.payload, JointSample):
                    recorded_by_stamp[msg.topic][msg.payload.stamp_ns] = msg.payload.positions
                continue
            n_inputs += 1
            t0 = time.perf_counter_ns()
            out = driver.feed(msg, hand_input)
            if out.result is None:
                continue
            latency.append(time.perf_counter_ns() - t0)
            t_list.append(msg.log_time_ns)
            report = out.result.report
            mode.append(report["mode"])
            action.append(report["corrector"])
            flags.append(report["flags"])
            produced = {topic: payload.positions for topic, payload in out.logged if isinstance(payload, JointSample)}
            for topic in RECORDED_OUTPUTS:
                rows[topic].append(produced.get(topic))
    t = np.array(t_list, dtype=np.int64)

    def table(values: list, width: int) -> np.ndarray:
        out = np.full((len(values), width), np.nan)
        for i, v in enumerate(values):
            if v is not None:
                out[i] = v
        return out

    rerun = {k: table(rows[k], widths[k]) for k in RECORDED_OUTPUTS}
    recorded = {k: table([recorded_by_stamp[k].get(int(s)) for s in t], widths[k]) for k in RECORDED_OUTPUTS}
    notes = []
    extra = {k: len(set(recorded_by_stamp[k]) - set(t.tolist())) for k in RECORDED_OUTPUTS}
    if any(extra.values()):
        notes.append(f"recorded outputs at times the re-run never stepped: { {k: v for k, v in extra.items() if v} }")
    recorded_platform = meta.get("session", {}).get("numeric_platform")
    if recorded_platform and recorded_platform != numeric_platform.describe():
        notes.append(f"recorded on numeric platform {recorded_platform!r}, re-run on {numeric_platform.describe()!r}: "
                     "the last bits may differ")
    return Rerun(
        path, t, np.array(mode), np.array(action), np.array(latency, dtype=np.int64), flags, arm_names, eff_names,
        pipeline.effector.spec, rerun, recorded, reader.episodes(), meta, _models_match(meta, pipeline), rig_source,
        reader.duration_s, n_inputs,
        time.perf_counter() - started, notes,
    )
