"""Bad robot descriptions fail with a message naming the file and the element."""

import pytest

from teleprev.errors import UrdfError
from teleprev.robot.model import load_robot

GOOD = """<robot name="r">
  <link name="a"/><link name="b"/>
  <joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" velocity="1" effort="1"/></joint>
</robot>"""


def _write(tmp_path, text, name="robot.urdf"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_missing_file_names_the_path(tmp_path):
    with pytest.raises(UrdfError, match="no_such_robot"):
        load_robot(tmp_path / "no_such_robot.urdf")


def test_malformed_xml_names_the_file(tmp_path):
    path = _write(tmp_path, GOOD.replace("</robot>", ""))
    with pytest.raises(UrdfError) as err:
        load_robot(path)
    assert str(path) in str(err.value) and "XML" in str(err.value)


@pytest.mark.parametrize(
    "edit, element, words",
    [
        (('upper="1"', 'upper="x"'), '<joint name="j"> <limit>', "not numeric"),
        (('<limit lower="-1" upper="1" velocity="1" effort="1"/>', ""), '<joint name="j">', "needs <limit"),
        (('<child link="b"/>', '<child link="c"/>'), '<joint name="j">', "'c' is not defined"),
        (('type="revolute"', 'type="spherical"'), '<joint name="j">', "unsupported joint type"),
        (
            (
                '<link name="b"/>',
                '<link name="b"><collision><geometry><mesh filename="x.stl"/></geometry></collision></link>',
            ),
            '<link name="b"> <collision> <mesh>',
            "meshes are not supported",
        ),
        (('upper="1"', 'upper="-2"'), '<joint name="j"> <limit>', "above upper"),
    ],
)
def test_broken_elements_are_named(tmp_path, edit, element, words):
    path = _write(tmp_path, GOOD.replace(*edit))
    with pytest.raises(UrdfError) as err:
        load_robot(path)
    message = str(err.value)
    assert str(path) in message and element in message and words in message


def test_unknown_joint_name_is_named(tmp_path):
    model = load_robot(_write(tmp_path, GOOD))
    with pytest.raises(UrdfError, match="unknown joint name 'k'"):
        model.vector({"k": 0.1})
    with pytest.raises(UrdfError, match=str(model.urdf_path)):
        model.indices(["j", "k"])
