"""The Foxglove layout for teleprev's sessions and live views (foxglove_layout.json beside this file, which
Foxglove imports with Layouts > Import from file): the robot in 3D from /robot_description and /tf with the
camera's frame, the camera, the arm's state against its commands, the hand's retargeted target against the
corrected one, and the mode and episode events.

Built with foxglove-sdk's layout types; `python -m teleprev.live.view.foxglove_layout > foxglove_layout.json`
writes it again after a change here (tests/live/test_foxglove_layout.py checks that the two agree).
"""

from __future__ import annotations

from pathlib import Path

from teleprev import topics as T

FILE = Path(__file__).with_name("foxglove_layout.json")
ARM_JOINTS = tuple(f"joint{i}" for i in range(1, 7))
HAND_JOINTS = ("1", "5", "9", "13")  # one flexion joint of each LEAP Hand finger (the plot stays readable)


def _joint(topic: str, name: str) -> str:
    return f'{topic}.joints[:]{{name=="{name}"}}.position'


def layout(camera: str = "cam_front", arm: str = "arm"):
    import foxglove.layouts as fl

    state, command = T.device_topic("arm", arm, "state"), T.COMMAND_ARM
    robot = fl.ThreeDeePanel(title="robot", config=fl.ThreeDeeConfig(layers={
        "grid": fl.BaseRendererGridLayerSettings(layer_id="foxglove.Grid"),
        "urdf": fl.BaseRendererUrdfLayerSettings(layer_id="foxglove.Urdf", label="robot (/robot_description)",
                                                 source_type="topic", topic=T.ROBOT_DESCRIPTION,
                                                 control_mode="transforms"),
    }))
    image = fl.ImagePanel(title=camera, config=fl.ImageConfig(
        image_mode=fl.ImageModeConfig(image_topic=T.device_topic("camera", camera, "image"))))
    arm_plot = fl.PlotPanel(title="arm: measured (solid) and commanded (thin), rad", config=fl.PlotConfig(paths=[
        *(fl.PlotSeries(value=_joint(state, j), label=f"{j} measured") for j in ARM_JOINTS),
        *(fl.PlotSeries(value=_joint(command, j), label=f"{j} command", line_size=0.5) for j in ARM_JOINTS),
    ]))
    hand_plot = fl.PlotPanel(title="hand: retargeted (thin) and corrected, rad", config=fl.PlotConfig(paths=[
        *(fl.PlotSeries(value=_joint(T.CORRECTED, j), label=f"{j} corrected") for j in HAND_JOINTS),
        *(fl.PlotSeries(value=_joint(T.RETARGETED, j), label=f"{j} retargeted", line_size=0.5) for j in HAND_JOINTS),
    ]))
    events = fl.SplitContainer(direction="column", items=[
        fl.SplitItem(content=fl.RawMessagesPanel(title="mode", config=fl.RawMessagesConfig(topic_path=T.MODE))),
        fl.SplitItem(content=fl.RawMessagesPanel(title="episode", config=fl.RawMessagesConfig(topic_path=T.EPISODE))),
    ])
    top = fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=3, content=robot), fl.SplitItem(proportion=2, content=image)])
    bottom = fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=2, content=arm_plot), fl.SplitItem(proportion=2, content=hand_plot),
        fl.SplitItem(proportion=1, content=events)])
    return fl.Layout(content=fl.SplitContainer(direction="column", items=[
        fl.SplitItem(proportion=3, content=top), fl.SplitItem(proportion=2, content=bottom)]))


if __name__ == "__main__":
    print(layout().to_json())
