"""What a live session writes in its MCAP metadata records: the rig, calibration, session facts, tasks,
model hashes, the episode plan, the policy, the physics world and the survey's sidecar."""

from __future__ import annotations

import json
from pathlib import Path

from teleprev import __version__, numeric_platform, topics
from teleprev.live.record.schedule import PLAN_RECORD
from teleprev.robot.model import load_robot


def rig_record(rig) -> dict[str, str]:
    """The session's "rig" metadata record: the rig file's text (`load_recorded_rig` reads it back) and
    what it names."""
    toml = rig.text if rig.text is not None else rig.path.read_text() if rig.path else ""
    return {"path": str(rig.path), "toml": toml, "name": rig.rig.name,
            "robot": rig.rig.robot, "end_effector": rig.rig.end_effector,
            "robot_urdf_sha256": load_robot(rig.rig.robot).urdf_sha256}


def session_metadata(session) -> dict[str, dict[str, str]]:
    """The metadata records of a LiveSession's file."""
    rig, o = session.rig, session.options
    cal_path = rig.resolve(rig.rig.calibration) if rig.rig.calibration else None
    meta = {
        "rig": rig_record(rig),
        "calibration": {"path": str(cal_path or ""), "toml": cal_path.read_text() if cal_path else ""},
        "session": {
            "operator": o.operator or rig.rig.operator,
            "task": session.task,
            "participant": o.participant or rig.rig.participant,
            "condition": o.condition or rig.rig.condition,
            "end_effector": rig.rig.end_effector,
            "practice": "true" if o.practice else "false",
            "software_version": __version__,
            "numeric_platform": numeric_platform.describe(),
        },
    }
    tasks = dict(rig.tasks)
    if o.task_text:
        tasks[session.task] = o.task_text
    if tasks:  # task id -> instruction: an export gives LeRobot the instruction, the episodes keep the id
        meta[topics.TASKS_RECORD] = tasks
    hashes = session.pipeline.model_hashes()
    if hashes is not None:
        meta["models"] = hashes
    meta["pipeline"] = {"inputs": json.dumps(session.driver.topics.__dict__)}
    if o.episode_plan is not None:
        meta[PLAN_RECORD] = o.episode_plan.to_record(session.preview_lead_s)
    if o.policy is not None:
        meta["policy"] = dict(o.policy)
    if session.physics is not None:  # its scenes are events on /events/world
        meta["world"] = {"world": rig.sim.world, "rate_hz": f"{rig.sim.rate_hz:g}",
                         "end_effector": rig.rig.end_effector}
    # The post-condition questionnaire is answered after the file is closed: it goes in a sidecar
    # next to the session, which the session names here so that nothing recorded is rewritten.
    meta["study"] = {"survey_sidecar": Path(o.out).with_suffix(".survey.json").name}
    return meta
