"""Interop figures: importing foreign recordings into LeRobot, and what a session carries for Foxglove.

    python bench/interop.py [--json] [--quick]

Figures:
  import_realtime_x     seconds of recording imported per second of wall time: a 60 s (--quick: 6 s) ROS 2 MCAP
  written by
                        rosbags (one 640x480 JPEG camera at 30 fps, 100 Hz joint states from two publishers
                        on /joint_states, a 50 Hz pose and /tf, start/stop events) through `teleprev import`
                        with datasets/imports/ros2_arm.toml (30 fps, h264), the median of 3 imports; lerobot's
                        one-time import is outside it (import_realtime_x_with_startup counts it)
  foreign_formats_ok    how many of ros2-mcap, rosbag2-sqlite (raw bgr8 images), foxglove-mcap (written with
                        the mcap library and Foxglove's schemas; datasets/imports/foxglove_arm.toml) import and load
                        back with LeRobotDataset
                        with the frames, joint names and values expected
  tf_rate_hz            /tf messages per second in a 3 s sim recording (arm_state_rate_hz beside it)
  urdf_embedded         the recording carries the rig's URDF as an attachment and on /robot_description,
                        byte for byte (read with the mcap library and rosbags' CDR decoder)

JSON keys:
    import_realtime_x               float
    import_realtime_x_with_startup  float
    imported_s                      float
    foreign_formats_ok              int
    tf_rate_hz                      float
    arm_state_rate_hz               float
    urdf_embedded                   bool
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402  (sets one-thread environment before numpy loads)


def import_speed(folder: Path, seconds: float, repeat: int) -> dict:
    import numpy as np

    from teleprev.export.foreign.config import load_import_recipe
    from teleprev.export.foreign.run import import_files
    from teleprev.export.foreign.samples import ForeignSpec, ros2_mcap_file, write_ros2

    t = time.perf_counter()
    bag = ros2_mcap_file(write_ros2(folder / "speed", ForeignSpec(episodes=((0.0, seconds),), width=640, height=480)))
    print(f"wrote a {seconds:.0f} s ROS 2 MCAP ({bag.stat().st_size / 1e6:.1f} MB) in {time.perf_counter() - t:.0f} s",
          file=sys.stderr)
    t = time.perf_counter()
    import lerobot.datasets.lerobot_dataset  # noqa: F401  (once per process: timed apart)

    startup = time.perf_counter() - t
    working = []
    for k in range(repeat):  # the median of a few imports: the machine is shared
        report = import_files([bag], load_import_recipe("ros2_arm"), "bench/interop", folder / f"speed_out{k}")
        working.append(report.wall_s - report.startup_s)
    wall = float(np.median(working))
    return {"bag": bag, "root": folder / "speed_out0", "recorded_s": report.duration_s, "frames": report.frames,
            "import_realtime_x": report.duration_s / wall,
            "import_realtime_x_with_startup": report.duration_s / (wall + startup)}


def check_dataset(root: Path, repo: str, frames_min: int, names: list[str]) -> str:
    """"" when the dataset loads with LeRobotDataset and holds what it should (observation.state named
    `names`, in that order), else why not."""
    import numpy as np
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from teleprev.export.synthetic import arm_q

    ds = LeRobotDataset(repo, root=root, video_backend="pyav")
    if len(ds) < frames_min:
        return f"{len(ds)} frames, expected at least {frames_min}"
    found = ds.meta.features["observation.state"]["names"]
    if found != names:
        return f"joint names {found}, expected {names}"
    item = ds[len(ds) // 2]
    if tuple(item["observation.images.front"].shape)[0] != 3:
        return "no RGB image"
    state = np.asarray(item["observation.state"])
    # the joints at mid-episode are arm_q at some frame time: within one 30 fps frame of some time in range
    t = np.linspace(0, 5, 5001)
    if np.abs(arm_q(t) - state[:6]).max(axis=1).min() > 0.02:
        return f"state {state[:6]} is not on the recorded trajectory"
    return ""


def formats(folder: Path, speed: dict) -> dict:
    from teleprev.export.foreign.config import load_import_recipe
    from teleprev.export.foreign.run import import_files
    from teleprev.export.foreign.samples import ARM, ForeignSpec, write_foxglove_mcap, write_ros2

    # ros2_arm.toml's [import.joints]: the arm, then the gripper
    ros_names = [f"joint_states.{j}" for j in (*ARM, "gripper")]
    results = {
        "ros2-mcap": check_dataset(speed["root"], "bench/interop", 30 * int(speed["recorded_s"]) - 30, ros_names)
    }
    spec = ForeignSpec(episodes=((0.0, 3.0),), raw_images=True)
    sqlite = write_ros2(folder / "sqlite", spec, storage="sqlite3")
    import_files([sqlite], load_import_recipe("ros2_arm"), "bench/sqlite", folder / "sqlite_out")
    results["rosbag2-sqlite"] = check_dataset(folder / "sqlite_out", "bench/sqlite", 80, ros_names)
    fox = write_foxglove_mcap(folder / "fox.mcap", ForeignSpec(episodes=((0.0, 3.0),)))
    import_files([fox], load_import_recipe("foxglove_arm"), "bench/fox", folder / "fox_out")
    # foxglove_arm.toml takes its joints from the xArm6 URDF: the recorded gripper, which it lacks, is left out
    results["foxglove-mcap"] = check_dataset(folder / "fox_out", "bench/fox", 80, [f"joints.{j}" for j in ARM])
    return results


def session_figures(folder: Path, seconds: float) -> dict:
    import numpy as np
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore

    from teleprev.live.record.session import LiveSession, RecordOptions
    from teleprev.rig import default_rig_path
    from teleprev.robot.model import load_robot
    from teleprev.session.reader import SessionReader

    path = folder / "sim.mcap"
    rec = LiveSession(RecordOptions(out=path, rig=default_rig_path(), task="pick_place"))
    rec.start()
    try:
        rec.loop.start_episode("pick_place")
        time.sleep(seconds)
    finally:
        rec.stop()
    with SessionReader(path) as r:
        def rate(topic):
            s = np.array([m.payload.stamp_ns for m in r.messages([topic])], dtype=np.int64)
            return (len(s) - 1) / ((s[-1] - s[0]) / 1e9)

        tf_rate, arm_rate = rate("/tf"), rate("/arm/arm/state")
    urdf = load_robot(rec.rig.rig.robot).urdf_path
    with open(path, "rb") as f:
        reader = make_reader(f)
        attached = [a.data for a in reader.iter_attachments() if a.name == urdf.name]
        texts = [get_typestore(Stores.ROS2_HUMBLE).deserialize_cdr(m.data, "std_msgs/msg/String").data
                 for _, _, m in reader.iter_messages(topics=["/robot_description"])]
    embedded = attached == [urdf.read_bytes()] and texts == [urdf.read_text()]
    return {"tf_rate_hz": tf_rate, "arm_state_rate_hz": arm_rate, "urdf_embedded": embedded}


def main() -> None:
    args = common.parser(__doc__.splitlines()[0]).parse_args()
    with tempfile.TemporaryDirectory(prefix="teleprev-interop-") as tmp:
        folder = Path(tmp)
        speed = import_speed(folder, 6.0 if args.quick else 60.0, 1 if args.quick else 3)
        checks = formats(folder, speed)
        session = session_figures(folder, 3.0)
    for name, why in checks.items():
        if why:
            print(f"{name}: {why}", file=sys.stderr)
    figures = {
        "import_realtime_x": round(speed["import_realtime_x"], 2),
        "import_realtime_x_with_startup": round(speed["import_realtime_x_with_startup"], 2),
        "imported_s": round(speed["recorded_s"], 2),
        "foreign_formats_ok": sum(1 for why in checks.values() if not why),
        "tf_rate_hz": round(session["tf_rate_hz"], 1),
        "arm_state_rate_hz": round(session["arm_state_rate_hz"], 1),
        "urdf_embedded": session["urdf_embedded"],
    }
    targets = {"import_realtime_x": ">= 10", "foreign_formats_ok": "3", "tf_rate_hz": ">= arm_state_rate_hz",
               "urdf_embedded": "true"}
    common.report("teleprev interop (machine shared: figures are noisy)", figures, targets, args.json)


if __name__ == "__main__":
    main()
