"""Re-running the pipeline on a session's recorded raw streams.

The session's raw device streams and mode switches go through a PipelineDriver in log-time order, as
they went through the live session loop; the driver is built from the rig and calibration the session
recorded in its metadata (or from a rig file given instead) and from the models given (default: the
shipped ones). Every step's outputs are kept next to what the session recorded for the same step.
"""

from __future__ import annotations

import gc
import itertools
import json
import time
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from teleprev import numeric_platform, topics
from teleprev.assembly import build_driver, build_pipeline, rig_calibration
from teleprev.errors import SessionError
from teleprev.evaluation.command_tracks import CommandTrack, RecordedTick, replay_ticks, track
from teleprev.evaluation.controller_resets import ActuatorHistory
from teleprev.messages import Event, JointSample
from teleprev.pipeline.driver import InputTopics, PipelineDriver
from teleprev.pipeline.planner import CommandPlanner
from teleprev.pipeline.step import Pipeline, StepResult
from teleprev.retarget.calibration import load_calibration_text
from teleprev.rig import load_recorded_rig, load_rig
from teleprev.robot.effectors import EndEffector
from teleprev.session.codec import JOINT_STATES
from teleprev.session.reader import Episode, JointTable, SessionReader

PREPARE_BLOCK = 4096  # messages read ahead per batch of glove-sample preparation (bounds the memory)
COMMAND_TOPICS = (topics.COMMAND_ARM, topics.COMMAND_HAND)


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
    rerun: dict[str, np.ndarray]  # topic -> (steps, joints), for each stream the steps record
    recorded: dict[str, np.ndarray]
    episodes: list[Episode]
    metadata: dict[str, dict[str, str]]
    models_match: bool | None  # the recorded models' hashes equal those used now (None: unknown)
    rig_source: str
    duration_s: float
    input_messages: int
    wall_s: float = 0.0
    notes: list[str] = field(default_factory=list)
    commands: dict[str, CommandTrack] = field(default_factory=dict)  # COMMAND_ARM / COMMAND_HAND, on their stamps
    actuators: dict[str, ActuatorHistory] = field(default_factory=dict)  # per command topic: measured states, resets


def recorded_format(meta: dict) -> int:
    """The session format a session was recorded in (the "teleprev" metadata record): eval re-runs it with
    that format's arithmetic (teleprev.assembly.build_pipeline), so it reproduces bit for bit."""
    try:
        return int(meta.get("teleprev", {}).get("format_version", topics.FORMAT_VERSION))
    except ValueError:
        return topics.FORMAT_VERSION


def _pipeline_for(reader: SessionReader, path: Path, models, rig_path):
    meta = reader.metadata
    session_format = recorded_format(meta)
    if rig_path:
        rig = load_rig(rig_path)
        return build_pipeline(rig, models, rig_calibration(rig), session_format), f"rig file {rig_path}"
    if not meta.get("rig", {}).get("toml"):
        raise SessionError("the session does not carry its rig (metadata 'rig'); pass --config RIG", str(path))
    calibration_toml = meta.get("calibration", {}).get("toml", "")
    # a recorded rig is anchored at its session's folder (teleprev.rig.load_recorded_rig): part of the key
    key = (meta["rig"]["toml"], str(path.resolve().parent), calibration_toml, str(models) if models else None,
           session_format)
    if key not in _BUILT:
        rig = load_recorded_rig(meta, path)
        calibration = load_calibration_text(calibration_toml, f"{path}: recorded calibration")
        if len(_BUILT) >= 8:
            _BUILT.pop(next(iter(_BUILT)))
        _BUILT[key] = build_pipeline(rig, models, calibration, session_format)
    return _BUILT[key], "recorded in the session"


# Pipelines built from recorded rigs, by (rig, session folder, calibration, models, format): the sessions
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


class _Steps:
    """What the re-run produced, a list entry per step, gathered as the steps go."""

    def __init__(self, driver: PipelineDriver) -> None:
        self.t_ns: list[int] = []
        self.mode: list[str] = []
        self.corrector: list[str] = []
        self.latency_ns: list[int] = []
        self.flags: list[list[str]] = []
        self.topics = driver.recorded_topics
        self.recorded_values = driver.recorded_values
        self.values: list[tuple[np.ndarray | None, ...]] = []  # per step: recorded_values (in `topics`' order)

    def add(self, t_ns: int, result: StepResult, latency_ns: int) -> None:
        self.t_ns.append(t_ns)
        self.latency_ns.append(latency_ns)
        report = result.report
        self.mode.append(report["mode"])
        self.corrector.append(report["corrector"])
        self.flags.append(report["flags"])
        self.values.append(self.recorded_values(result))  # what PipelineDriver.feed records for this step

    def rows(self) -> dict[str, tuple[np.ndarray | None, ...]]:
        """Per stream the steps record, its value at each step (None: nothing recorded)."""
        columns = zip(*self.values) if self.values else ((),) * len(self.topics)
        return dict(zip(self.topics, columns))


def _table(values: Sequence[np.ndarray | None], width: int) -> np.ndarray:
    """Rows of a (len(values), width) float64 table; NaN rows where a value is None."""
    out = np.full((len(values), width), np.nan)
    present = [i for i, v in enumerate(values) if v is not None]
    if not present:
        return out
    try:
        block = np.array([values[i] for i in present])
    except ValueError:  # ragged rows
        block = None
    if block is not None and block.dtype != object and block.shape == (len(present), width):
        out[present] = block
        return out
    for i in present:  # odd rows: each assigned as it is (broadcasting, errors and all)
        out[i] = values[i]
    return out


def rerun_session(path: str | Path, models: str | Path | None = None, rig_path: str | Path | None = None) -> Rerun:
    path = Path(path)
    started = time.perf_counter()
    with SessionReader(path) as reader, _long_lived_unscanned():
        return _rerun(reader, path, models, rig_path, started)


@contextmanager
def _long_lived_unscanned():
    """The objects alive before a re-run (modules, compiled kernels, built pipelines) left out of the
    garbage collector's scans while it runs: a full collection over them took 55-60 ms of a 30 s session's
    0.6 s re-run. What the re-run makes is collected as usual."""
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def _rerun(reader: SessionReader, path: Path, models, rig_path, started: float) -> Rerun:
    meta = reader.metadata
    pipeline, rig_source = _pipeline_for(reader, path, models, rig_path)
    try:
        inputs = InputTopics(**json.loads(meta["pipeline"]["inputs"]))
    except (KeyError, TypeError, ValueError):
        raise SessionError(
            "the session does not say which streams fed its pipeline (metadata 'pipeline')", str(path)
        ) from None
    missing = [t for t in (inputs.hand, inputs.wrist, inputs.arm, inputs.effector) if t not in reader.schemas]
    if missing:
        raise SessionError(f"the session lacks the pipeline's input streams {missing}", str(path))
    driver = build_driver(pipeline, inputs, recorded_format(meta))
    arm_names, eff_names = pipeline.arm_names, pipeline.effector_names
    stepped_topics = driver.recorded_topics
    outputs = stepped_topics + tuple(k for k in COMMAND_TOPICS if k not in stepped_topics)
    widths = dict(zip(stepped_topics, map(len, driver.recorded_names))) | {topics.COMMAND_ARM: len(arm_names),
                                                                           topics.COMMAND_HAND: len(eff_names)}

    steps = _Steps(driver)
    recorded_by_stamp: dict[str, dict[int, np.ndarray]] = {k: {} for k in outputs}
    # The recorded outputs are read as tables (stamps and values, no messages) in the same pass as the
    # inputs; an output topic of another schema comes through as messages and is skipped, as before.
    tables = {k: JointTable() for k in outputs if reader.schemas.get(k) == JOINT_STATES}
    if inputs.action and inputs.action not in reader.schemas:
        raise SessionError(
            f"the session lacks the policy's actions ({inputs.action}) that drove its pipeline", str(path)
        )
    # a policy's rollout: its recorded actions are the input that steps the pipeline (PipelineDriver)
    streamed = [inputs.hand, inputs.wrist, inputs.arm, inputs.effector, *([inputs.action] if inputs.action else []),
                topics.MODE, topics.SUPERSEDED, topics.COMMAND_TICK,
                topics.DEVICE_EVENT, *(k for k in outputs if k not in tables)]
    # the actuators' measured states and resets: where a controller starts a stream (metrics' derivatives)
    histories = {topics.COMMAND_ARM: ActuatorHistory(), topics.COMMAND_HAND: ActuatorHistory()}
    measured = {inputs.arm: (histories[topics.COMMAND_ARM], arm_names),
                inputs.effector: (histories[topics.COMMAND_HAND], eff_names)}
    states: dict[str, list[JointSample]] = {topic: [] for topic in measured}  # into the histories at the end
    devices = {inputs.arm.split("/")[2]: histories[topics.COMMAND_ARM],
               inputs.effector.split("/")[2]: histories[topics.COMMAND_HAND]}
    updates, ticks = [], []  # the planner's updates the re-run makes, and the recorded ticks
    n_inputs = 0
    # One BLAS thread: the batched CPN is a few hundred rows, where threads cost more than they give (on a
    # busy machine or with -j workers, many times more); single configurations never use them anyway.
    with threadpool_limits(1, user_api="blas"):
        messages = reader.messages(topics=[t for t in streamed if t in reader.schemas], tables=tables)
        for msg, hand_input in _prepared(driver, messages):
            if msg.topic in recorded_by_stamp:
                if isinstance(msg.payload, JointSample):
                    recorded_by_stamp[msg.topic][msg.payload.stamp_ns] = msg.payload.positions
                continue
            if msg.topic == topics.COMMAND_TICK:
                if isinstance(msg.payload, Event):
                    ticks.append(RecordedTick(msg.payload.stamp_ns, int(msg.payload.data.get("seq", 0))))
                continue
            if msg.topic == topics.DEVICE_EVENT:
                data = msg.payload.data if isinstance(msg.payload, Event) else {}
                if data.get("event") == "connected" and data.get("device") in devices:
                    devices[data["device"]].connects_ns.append(msg.log_time_ns)
                continue
            if msg.topic in states and isinstance(msg.payload, JointSample):
                states[msg.topic].append(msg.payload)
            n_inputs += 1
            t0 = time.perf_counter_ns()
            result = driver.advance(msg, hand_input)
            updates += driver.take_updates()
            if result is not None:
                steps.add(msg.log_time_ns, result, time.perf_counter_ns() - t0)
    for topic, samples in states.items():
        history, names = measured[topic]
        history.add_states(*pipeline.measured_rows(samples, names))
    for k, table in tables.items():
        recorded_by_stamp[k] = dict(zip(table.stamp_ns, table.positions))
    t = np.array(steps.t_ns, dtype=np.int64)
    rows = steps.rows()
    rerun = {k: _table(rows[k], widths[k]) for k in stepped_topics}
    t_keys = t.tolist()
    recorded = {k: _table([recorded_by_stamp[k].get(s) for s in t_keys], widths[k]) for k in stepped_topics}
    notes = []
    stepped = set(t_keys)
    extra = {k: len(set(recorded_by_stamp[k]) - stepped) for k in stepped_topics}
    if any(extra.values()):
        notes.append(f"recorded outputs at times the re-run never stepped: { {k: v for k, v in extra.items() if v} }")
    # The commands: those the steps made themselves (pipelines that record them), and those the planner
    # samples at the recorded ticks of the paced sender from the re-run's updates.
    sides = {k: {s: row for s, row in zip(t_keys, rows[k]) if row is not None} if k in rows else {}
             for k in COMMAND_TOPICS}
    if ticks:
        for k, sampled in zip(COMMAND_TOPICS, replay_ticks(CommandPlanner.for_pipeline(pipeline), updates, ticks)):
            sides[k].update(sampled)
    commands = {k: track(rerun_side, recorded_by_stamp[k], widths[k]) for k, rerun_side in sides.items()}
    recorded_platform = meta.get("session", {}).get("numeric_platform")
    if recorded_platform and recorded_platform != numeric_platform.describe():
        notes.append(f"recorded on numeric platform {recorded_platform!r}, re-run on {numeric_platform.describe()!r}: "
                     "the last bits may differ")
    return Rerun(
        path,
        t,
        np.array(steps.mode),
        np.array(steps.corrector),
        np.array(steps.latency_ns, dtype=np.int64),
        steps.flags,
        arm_names,
        eff_names,
        pipeline.effector.spec,
        rerun,
        recorded,
        reader.episodes(),
        meta,
        _models_match(meta, pipeline),
        rig_source,
        reader.duration_s,
        n_inputs,
        time.perf_counter() - started,
        notes,
        commands,
        histories,
    )
