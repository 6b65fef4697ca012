"""Topic names and the JSON schemas of teleprev sessions: the one place that says what a session holds.

Raw device streams are named after the device (its name in the rig):
    /glove/<device>/hand      JointSample   SMPL-X hand pose, 45 axis-angle components ("index1.x", ...)
    /suit/<device>/wrist      PoseSample    right wrist pose in the suit's world frame
    /suit/<device>/body       JointSample   SMPL-X body joints, axis-angle components (optional)
    /camera/<device>/image    ImageSample   JPEG
    /camera/<device>/depth    DepthSample   16-bit depth (RawImage 16UC1 or 16-bit PNG), unit in the channel metadata
    /camera/<device>/calibration CameraInfo  intrinsics of the depth image's frame (foxglove.CameraCalibration)
    /arm/<device>/state       JointSample   measured arm joints
    /hand/<device>/state      JointSample   measured end-effector joints (LEAP "0".."15", "gripper", "vacuum")

What the pipeline computed and sent:
    /pipeline/retargeted      JointSample   end-effector joints from retargeting, before correction
    /pipeline/corrected       JointSample   after the Corrector (always collision-free)
    /pipeline/arm_target      JointSample   arm joints from IK
    /pipeline/report          Event         teleprev.StepReport: corrector action, flags, latency
    /command/arm              JointSample   arm command actually sent (execute mode only), stamped with the
                                            instant the sender sent it; velocities: the command's velocity
    /command/hand             JointSample   end-effector command actually sent (execute mode only)
    /policy/action            JointSample   a policy's raw action (teleprev rollout), arm and end-effector joints
                                            by the dataset's names ("arm.joint1", "hand.0"): the input that
                                            drives the pipeline in place of the glove and suit
    /command/tick             Event         teleprev.CommandTick: per tick of the paced sender, the last
                                            update it had adopted, its lateness and flags
    /command/wire             Event         teleprev.CommandWire: per command an actuator's own process wrote
                                            (live/core/actuator_host.py), stamped when the write began
    /tf                       TransformsSample   robot link frames (for Foxglove's URDF panel); a depth camera
                                                 adds its own frame (its mount in the rig) so that Foxglove's
                                                 3D panel places its point cloud in the robot's scene
    /robot_description        RobotDescription   the rig's URDF (ROS 2 std_msgs/String), once at the start;
                                                 the file also carries it as an attachment <robot>.urdf

A bimanual session (a rig with [sides], teleprev/sides.py) records each side's pipeline and command streams with
the side after the first segment (teleprev/pipeline/bimanual.py: side_topic): /pipeline/left/retargeted,
/pipeline/left/report, /command/left/arm, /command/left/hand, /command/left/tick, /command/left/wire, and
/robot_description/left; its /tf names each side's links "<side>/<link>" under a "world" frame.

Events:
    /events/episode           teleprev.EpisodeEvent
    /events/mode              teleprev.ModeSwitch
    /events/device            teleprev.DeviceEvent
    /events/operator          teleprev.OperatorEvent
    /events/world             teleprev.WorldLayout   a physics rig's scene (objects' starting poses, seed, the
                                                     robot's state), each time the world begins one
    /events/superseded        teleprev.Superseded    a glove sample recorded but not stepped: a newer one was
                                                     queued already (the loop behind); logged just before it
"""

from __future__ import annotations

# Session layout version, written to the "teleprev" metadata record. Sessions of older versions re-run with
# their own classes (teleprev/pipeline/older_formats), which say what changed at each version.
FORMAT_VERSION = 11

TASKS_RECORD = "tasks"  # metadata record: task id -> the task as a natural-language instruction
TF = "/tf"
ROBOT_DESCRIPTION = "/robot_description"
RETARGETED = "/pipeline/retargeted"
CORRECTED = "/pipeline/corrected"
ARM_TARGET = "/pipeline/arm_target"
STEP_REPORT = "/pipeline/report"
COMMAND_ARM = "/command/arm"
COMMAND_HAND = "/command/hand"
COMMAND_TICK = "/command/tick"
COMMAND_WIRE = "/command/wire"
POLICY_ACTION = "/policy/action"
EPISODE = "/events/episode"
MODE = "/events/mode"
DEVICE_EVENT = "/events/device"
OPERATOR = "/events/operator"
WORLD = "/events/world"
SUPERSEDED = "/events/superseded"

KIND_TOPICS = {
    "glove": ("hand", "xr_left", "xr_right"),  # xr_*: an XR page's raw hand joints (webxr.glove)
    "suit": ("wrist", "body", "head"),  # head: the XR headset (webxr.suit)
    "camera": ("image", "depth", "calibration"),
    "arm": ("state",),
    "hand": ("state",),
}


def device_topic(kind: str, device: str, stream: str) -> str:
    """The topic of one stream of a device, e.g. device_topic("glove", "right", "hand")."""
    return f"/{kind}/{device}/{stream}"


def parse_device_topic(topic: str) -> tuple[str, str, str] | None:
    """(kind, device, stream) of a raw device topic, or None for pipeline/event topics."""
    parts = topic.strip("/").split("/")
    if len(parts) == 3 and parts[0] in KIND_TOPICS:
        return parts[0], parts[1], parts[2]
    return None


def _schema(title: str, description: str, properties: dict, required: list[str]) -> dict:
    return {
        "title": title,
        "description": description,
        "type": "object",
        "properties": properties,
        "required": required,
    }


_STR = {"type": "string"}
_INT = {"type": "integer"}
_NUM = {"type": "number"}

EVENT_SCHEMAS: dict[str, dict] = {
    "teleprev.EpisodeEvent": _schema(
        "teleprev.EpisodeEvent",
        "An episode starts, stops or is discarded; outcome is marked by the operator when known (source "
        "'operator', the default) or, on a physics rig, judged from the world's state when the episode stops "
        "(source 'physics', with the reason in words). The operator's mark wins.",
        {
            "event": {"type": "string", "enum": ["start", "stop", "discard", "outcome"]},
            "episode": _INT,
            "task": _STR,
            "outcome": {"type": ["string", "null"], "enum": ["success", "failure", None]},
            "source": {"type": "string", "enum": ["operator", "physics"]},
            "reason": _STR,
        },
        ["event", "episode"],
    ),
    "teleprev.ModeSwitch": _schema(
        "teleprev.ModeSwitch",
        "The pipeline's gate changed mode: preview (robot does not move) or execute. halt: nothing more was "
        "sent at once (an e-stop, or an actuator that failed), instead of braking to rest.",
        {"mode": {"type": "string", "enum": ["preview", "execute"]}, "reason": _STR, "halt": {"type": "boolean"}},
        ["mode"],
    ),
    "teleprev.CommandTick": _schema(
        "teleprev.CommandTick",
        "One tick of the paced command sender: the commands on /command/arm and /command/hand with the same "
        "stamp were sampled from the pipeline's updates up to `seq`; `late_ms`: how late the tick woke.",
        {"seq": _INT, "late_ms": _NUM, "flags": {"type": "array", "items": _STR}, "active": {"type": "boolean"}},
        ["seq", "late_ms"],
    ),
    "teleprev.CommandWire": _schema(
        "teleprev.CommandWire",
        "One command as the actuator's own process wrote it, stamped with the instant the write began: the tick "
        "`seq` it was sampled at (its stamp on /command/arm or /command/hand is `t_ns`), how long the device's "
        "send took (`call_ms`), and whether the device took it (`sent`; else `error` says why).",
        {
            "kind": {"type": "string", "enum": ["arm", "hand"]},
            "seq": _INT,
            "t_ns": _INT,
            "call_ms": _NUM,
            "sent": {"type": "boolean"},
            "error": _STR,
        },
        ["kind", "seq", "sent"],
    ),
    "teleprev.DeviceEvent": _schema(
        "teleprev.DeviceEvent",
        "A device opened (connected), failed (error, disconnected), stopped sending (gap), came back (recovered), "
        "or sent input that was counted and skipped (skipped).",
        {
            "device": _STR,
            "event": {"type": "string", "enum": ["connected", "gap", "recovered", "error", "disconnected", "skipped"]},
            "message": _STR,
            "since_ns": _INT,
        },
        ["device", "event"],
    ),
    "teleprev.WorldLayout": _schema(
        "teleprev.WorldLayout",
        "The physics world began a scene: its task, the seed it was drawn from, the anchor and every object's "
        "starting pose (teleprev/world/layout.py: layout_from_record restores it), and why; the world's time "
        "when it began it (world_ns), the robot's joint positions then, at rest (robot: name -> position), and "
        "whether they were placed (the drives' targets reset to them) or kept from the scene before.",
        {"layout": {"type": "object"}, "reason": _STR, "world_ns": _INT, "robot": {"type": "object"},
         "placed": {"type": "boolean"}},
        ["layout"],
    ),
    "teleprev.Superseded": _schema(
        "teleprev.Superseded",
        "The sample of `topic` logged at `log_time_ns` (just after this) was recorded but stepped nothing: the "
        "session loop, behind, had a newer one of that topic queued already and stepped that one. A re-run "
        "skips the same step.",
        {"topic": _STR, "log_time_ns": _INT},
        ["topic", "log_time_ns"],
    ),
    "teleprev.OperatorEvent": _schema(
        "teleprev.OperatorEvent",
        "Something the operator declared, e.g. 'ready' at the end of practice.",
        {"event": _STR, "detail": _STR},
        ["event"],
    ),
    "teleprev.StepReport": _schema(
        "teleprev.StepReport",
        "One pipeline step: what the Corrector did, which links collided before correction, flags.",
        {
            "step": _INT,
            "mode": _STR,
            "corrector": {"type": "string", "enum": ["untouched", "ccn", "fallback", "held"]},
            "colliding_links": {"type": "array", "items": _STR},
            "deviation_rad": _NUM,
            "ik_converged": {"type": "boolean"},
            "flags": {"type": "array", "items": _STR},
            "latency_us": _NUM,
        },
        ["step", "corrector"],
    ),
}
