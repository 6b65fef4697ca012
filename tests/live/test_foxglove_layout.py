"""The Foxglove layout in the repo (teleprev/live/view/foxglove_layout.json) is what the module builds, and every
topic it shows is one a recording has, with the schema its panel reads."""

from __future__ import annotations

import json

from teleprev.live.view.foxglove_layout import FILE, layout
from teleprev.session.reader import SessionReader


def referenced(node, out: dict) -> dict:
    """panel type -> topics its config names (a plot's series: the topic before the message path)."""
    if isinstance(node, dict):
        if node.get("type") == "panel":
            config = json.dumps(node.get("config", {}))
            found = out.setdefault(node["panelType"], set())
            for key in ("topic", "imageTopic", "topicPath", "value"):
                for part in config.split(f'"{key}": "')[1:]:
                    found.add(part.split('"')[0].split(".")[0])
        for value in node.values():
            referenced(value, out)
    elif isinstance(node, list):
        for value in node:
            referenced(value, out)
    return out


def test_the_file_is_what_the_module_builds():
    assert FILE.read_text().strip() == layout().to_json()


def test_every_topic_it_shows_is_recorded_with_the_schema_its_panel_reads(sim_session):
    panels = referenced(json.loads(FILE.read_text()), {})
    assert set(panels) == {"ThreeDee", "Image", "Plot", "RawMessages"}
    with SessionReader(sim_session) as reader:
        schemas = reader.schemas
    assert panels["ThreeDee"] == {"/robot_description"} and schemas["/robot_description"] == "std_msgs/msg/String"
    assert (
        panels["Image"] == {"/camera/cam_front/image"}
        and schemas["/camera/cam_front/image"] == "foxglove.CompressedImage"
    )
    assert panels["Plot"] == {"/arm/arm/state", "/command/arm", "/pipeline/corrected", "/pipeline/retargeted"}
    assert all(schemas[t] == "foxglove.JointStates" for t in panels["Plot"])
    assert panels["RawMessages"] == {"/events/mode", "/events/episode"} <= set(schemas)
    assert "/tf" in schemas  # what the URDF layer's links move by
