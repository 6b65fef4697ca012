"""`teleprev rollout` refuses a policy it cannot run on the rig in one line, exit 2, before anything opens
(no device, no session file, no torch): a missing or incomplete policy folder, features that do not match
what the export recipe makes of the rig, bad episode times."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from safetensors.numpy import save_file

from tests.cli.test_mistakes import nothing_made, one_line
from tests.helpers.cli import teleprev
from tests.helpers.sessions import RIGS

STATE, IMAGE, ACTION = (22,), (3, 480, 640), (22,)  # the default sim rig's, as lerobot-train saves them


def saved_policy(folder: Path, inputs: dict | None = None, action=ACTION, files=("model.safetensors",)) -> Path:
    """A pretrained_model folder's files as lerobot-train writes them (the checks read its JSON only)."""
    folder.mkdir(parents=True)
    inputs = inputs if inputs is not None else {"observation.state": STATE, "observation.images.cam_front": IMAGE}
    kinds = {"observation.state": "STATE"}
    config = {"type": "act",
              "input_features": {k: {"type": kinds.get(k, "VISUAL"), "shape": list(v)} for k, v in inputs.items()},
              "output_features": {"action": {"type": "ACTION", "shape": list(action)}}}
    (folder / "config.json").write_text(json.dumps(config))
    for name in ("policy_preprocessor.json", "policy_postprocessor.json"):
        (folder / name).write_text("{}")
    if "model.safetensors" in files:
        save_file({"model.layer.weight": np.zeros((64, 64), np.float32)}, str(folder / "model.safetensors"))
    return folder


def truncated(policy: Path) -> None:
    weights = policy / "model.safetensors"
    weights.write_bytes(weights.read_bytes()[:-100])


def header_flipped(policy: Path) -> None:
    weights = policy / "model.safetensors"
    data = bytearray(weights.read_bytes())
    data[12] ^= 0xFF  # inside the JSON header
    weights.write_bytes(bytes(data))


def header_length_flipped(policy: Path) -> None:
    weights = policy / "model.safetensors"
    data = bytearray(weights.read_bytes())
    data[3] ^= 0x01  # the header's length: far past the file's end
    weights.write_bytes(bytes(data))


CASES = {
    "missing": (None, [], "no such policy folder"),
    "no weights": (dict(files=()), [], "model.safetensors missing"),
    "state": (
        dict(inputs={"observation.state": (20,), "observation.images.cam_front": IMAGE}),
        [],
        "the policy's observation.state has shape [20], this rig gives [22]",
    ),
    "image": (
        dict(inputs={"observation.state": STATE, "observation.images.cam_front": (3, 96, 96)}),
        [],
        "the policy's observation.images.cam_front has shape [3, 96, 96], this rig gives [3, 480, 640]",
    ),
    "camera": (
        dict(inputs={"observation.state": STATE, "observation.images.wrist": IMAGE}),
        [],
        "the policy observes observation.images.wrist, which recipe",
    ),
    "action": (dict(action=(7,)), [], "the policy's action is [7]; this rig's is 22 joints"),
    "gripper rig": (
        {},
        ["--config", RIGS / "sim_gripper.toml"],
        "observation.state has shape [22], this rig gives [7]",
    ),
    "truncated weights": (dict(damage=truncated), [], "the policy's weights cannot be read"),
    "header byte": (dict(damage=header_flipped), [], "the policy's weights cannot be read"),
    "header length": (dict(damage=header_length_flipped), [], "the policy's weights cannot be read"),
    "episodes": ({}, ["--episodes", "0"], "--episodes must be 1 or more, got 0"),
    "episode time": ({}, ["--episode-time", "-2"], "--episode-time must be a positive number of seconds, got -2"),
    "engage": (
        {},
        ["--episode-time", "3", "--engage-after", "3"],
        "--engage-after must be 0 or more seconds and less than",
    ),
}


@pytest.mark.parametrize("case", CASES)
def test_refused_in_one_line_before_anything_opens(tmp_path_factory, case):
    made, args, said = CASES[case]
    policy = tmp_path_factory.mktemp("policy") / "pretrained_model"
    if made is not None:
        made = dict(made)
        damage = made.pop("damage", None)
        saved_policy(policy, **made)
        if damage is not None:
            damage(policy)
    cwd = tmp_path_factory.mktemp("cwd")
    run = teleprev("rollout", "--policy", policy, *args, cwd=cwd)
    assert run.returncode == 2 and said in one_line(run), run.stderr
    nothing_made(cwd)


def test_a_matching_policy_passes_the_checks(tmp_path):
    from teleprev.live.rollout.rollout import RolloutOptions, check_rollout

    plan = check_rollout(RolloutOptions(policy=saved_policy(tmp_path / "p"), out=tmp_path / "x.mcap"))
    assert plan.features.names == ("observation.state", "observation.images.cam_front") and plan.fps == 30
    assert plan.action_names[0] == "arm.joint1" and len(plan.action_names) == 22


def test_the_checks_and_help_load_neither_torch_nor_lerobot(tmp_path):
    from tests.export.test_lazy_lerobot import heavy_modules_after, run_cli

    assert heavy_modules_after("import teleprev.live.rollout.rollout") == []
    assert heavy_modules_after(run_cli("rollout", "--help")) == []
    policy = saved_policy(tmp_path / "p")
    code = ("from pathlib import Path\nfrom teleprev.live.rollout.rollout import RolloutOptions, check_rollout\n"
            f"check_rollout(RolloutOptions(policy=Path({str(policy)!r}), out=Path({str(tmp_path / 'x.mcap')!r})))")
    assert heavy_modules_after(code) == []
