"""Export recipes: the shipped ones load, roles resolve against a session's topics for any rig, and a
bad recipe or a session that lacks a stream gets a message naming what and where."""

import json
from types import SimpleNamespace

import pytest

from teleprev.errors import ConfigError, SessionError
from teleprev.export.recipe import IMAGE, JOINTS, POSE, load_recipe, recipes_dir, resolve

SIM_TOPICS = {
    "/arm/arm/state": JOINTS, "/hand/hand/state": JOINTS, "/glove/glove/hand": JOINTS, "/suit/suit/wrist": POSE,
    "/camera/cam_top/image": IMAGE, "/camera/cam_front/image": IMAGE, "/command/arm": JOINTS,
    "/command/hand": JOINTS, "/pipeline/retargeted": JOINTS, "/pipeline/corrected": JOINTS,
    "/events/episode": "teleprev.EpisodeEvent",
}


def topics(d):
    return {t: SimpleNamespace(schema=s) for t, s in d.items()}


def recipe_file(tmp_path, text):
    path = tmp_path / "r.toml"
    path.write_text(text)
    return path


def test_shipped_recipes_load_and_resolve_on_the_sim_layout():
    names = sorted(p.stem for p in recipes_dir().glob("*.toml"))
    assert {"default", "with_glove"} <= set(names)
    feats = resolve(load_recipe(), topics(SIM_TOPICS), {}, "s.mcap")
    by_name = {f.name: f for f in feats}
    assert list(by_name) == [
        "observation.state",
        "action",
        "observation.images.cam_front",
        "observation.images.cam_top",
    ]
    assert [s.topic for s in by_name["observation.state"].sources] == ["/arm/arm/state", "/hand/hand/state"]
    assert [s.prefix for s in by_name["observation.state"].sources] == ["arm", "hand"]
    assert [s.topic for s in by_name["action"].sources] == ["/command/arm", "/command/hand"]
    assert by_name["action"].is_action and not by_name["observation.state"].is_action
    glove = {f.name: f for f in resolve(load_recipe("with_glove"), topics(SIM_TOPICS), {}, "s.mcap")}
    assert glove["observation.wrist"].sources[0].schema == POSE
    assert glove["corrected"].is_action and not glove["observation.glove"].is_action


def test_roles_fit_any_rig_and_ask_for_a_name_when_ambiguous(tmp_path):
    rig = {"/arm/left/state": JOINTS, "/arm/right/state": JOINTS, "/hand/gripper/state": JOINTS,
           "/command/arm": JOINTS, "/command/hand": JOINTS}
    with pytest.raises(SessionError, match=r"2 arm devices \(left, right\); name one, e.g. 'arm_state:left'"):
        resolve(load_recipe(), topics(rig), {}, "s.mcap")
    # the pipeline's inputs (session metadata) say which arm it drove
    meta = {"pipeline": {"inputs": json.dumps({"arm": "/arm/right/state"})}}
    feats = resolve(load_recipe(), topics(rig), meta, "s.mcap")
    assert [s.topic for s in feats[0].sources] == ["/arm/right/state", "/hand/gripper/state"]
    assert len(feats) == 2  # no camera: no video feature
    two = recipe_file(
        tmp_path,
        '[[feature]]\nname = "observation.state"\nstreams = ["arm_state:left", "arm_state:right", '
        '"/hand/gripper/state"]\n',
    )
    feats = resolve(load_recipe(two), topics(rig), {}, "s.mcap")
    assert [s.prefix for s in feats[0].sources] == ["left", "right", "gripper"]


def test_a_session_without_a_requested_stream_is_named(tmp_path):
    preview_only = {t: s for t, s in SIM_TOPICS.items() if not t.startswith("/command/")}
    with pytest.raises(
        SessionError,
        match=r"s.mcap: feature 'action': stream 'arm_command' \(/command/arm\) is not in "
        r"this session: the robot was never engaged: the whole session ran in PREVIEW",
    ):
        resolve(load_recipe(), topics(preview_only), {}, "s.mcap")
    no_glove = {t: s for t, s in SIM_TOPICS.items() if not t.startswith("/glove/")}
    with pytest.raises(SessionError, match="'observation.glove': stream 'glove': this session has no glove device"):
        resolve(load_recipe("with_glove"), topics(no_glove), {}, "s.mcap")
    one = recipe_file(tmp_path, '[[feature]]\nname = "observation.state"\nstreams = ["camera:cam_side"]\n')
    with pytest.raises(SessionError, match=r"no camera device 'cam_side'.*found: cam_front, cam_top"):
        resolve(load_recipe(one), topics(SIM_TOPICS), {}, "s.mcap")
    wrong = recipe_file(tmp_path, '[[feature]]\nname = "observation.state"\nstreams = ["/events/episode"]\n')
    with pytest.raises(
        SessionError, match="/events/episode holds teleprev.EpisodeEvent messages, expected foxglove.JointStates"
    ):
        resolve(load_recipe(wrong), topics(SIM_TOPICS), {}, "s.mcap")


@pytest.mark.parametrize(
    "text, message",
    [
        ('[[feature]]\nname = "action"\nstreams = ["arm_cmd"]\n', r"unknown stream 'arm_cmd' \(roles: arm_state"),
        ('[[feature]]\nname = "timestamp"\nstreams = ["arm_state"]\n', "not a usable feature name"),
        (
            '[[feature]]\nname = "a"\nstreams = ["arm_state"]\n[[feature]]\nname = "a"\nstreams = ["glove"]\n',
            "feature defined twice",
        ),
        ('[export]\nfps = -3\n[[feature]]\nname = "a"\nstreams = ["arm_state"]\n', r"\[export\]|export.*fps must be"),
        (
            '[export]\non_gap = "stretch"\n[[feature]]\nname = "a"\nstreams = ["arm_state"]\n',
            r"export.on_gap: expected one of 'split', 'drop', 'fail'",
        ),
        (
            '[video]\ncodec = "mjpeg"\n[[feature]]\nname = "a"\nstreams = ["arm_state"]\n',
            "video.codec: expected one of 'h264', 'hevc', 'av1'",
        ),
        ('[[feature]]\nname = "a"\nstreams = ["arm_command:arm"]\n', "a pipeline stream, not a device's"),
        ('[[feature]]\nname = "a"\nstream = ["arm_state"]\n', "unknown key 'stream'"),
    ],
)
def test_bad_recipes_name_the_file_and_the_key(tmp_path, text, message):
    with pytest.raises(ConfigError, match=message) as err:
        load_recipe(recipe_file(tmp_path, text))
    assert "r.toml" in str(err.value)


def test_mixed_or_unnamed_camera_features_are_refused(tmp_path):
    mixed = recipe_file(tmp_path, '[[feature]]\nname = "observation.state"\nstreams = ["arm_state", "camera:*"]\n')
    with pytest.raises(ConfigError, match="mixes camera and joint streams"):
        resolve(load_recipe(mixed), topics(SIM_TOPICS), {}, "s.mcap")
    unnamed = recipe_file(tmp_path, '[[feature]]\nname = "observation.state"\nstreams = ["arm_state"]\n'
                                    '[[feature]]\nname = "observation.image"\nstreams = ["camera:*"]\n')
    with pytest.raises(ConfigError, match=r"put \{camera\} in its name"):
        resolve(load_recipe(unnamed), topics(SIM_TOPICS), {}, "s.mcap")


def test_an_unknown_recipe_lists_the_shipped_ones():
    with pytest.raises(
        ConfigError, match=r"no such recipe file \(recipes in .*datasets/recipes: default, sent_commands, with_glove"
    ):
        load_recipe("nope")
