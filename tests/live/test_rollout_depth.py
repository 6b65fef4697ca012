"""A policy trained with depth gets it in a rollout as lerobot-train gave it from the dataset: the feature
observation.images.<camera>_depth, (H, W, 1) float32 in the training's depth unit (lerobot's default, mm),
which lerobot's own prepare_observation_for_inference and the policy's saved preprocessor turn into what a
LeRobotDataset batch of the same depth becomes; a policy trained without depth gets none.

The session: a physics rig whose camera renders depth, recorded by `teleprev record`, exported by `teleprev
export` (the default recipe: colour and depth). The policy folders are written by lerobot's own classes from
that dataset (config, weights, processors with the dataset's stats, train_config.json as lerobot-train writes
it), not trained: lerobot 0.6.1's ACT, Diffusion and VQ-BeT put every visual feature through a 3-channel
torchvision ResNet, so lerobot-train cannot train one on a one-channel depth map ("expected input[..., 1, H, W]
to have 3 channels"). The policy that runs is a recorder of what it is handed, behind those real processors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from teleprev import topics
from teleprev.live.rollout.lerobot_policy import PolicyCard
from teleprev.live.rollout.rollout import Rollout, RolloutOptions, check_rollout
from teleprev.session.reader import SessionReader
from tests.helpers.cli import teleprev
from tests.helpers.depth_session import depth_physics_rig

W, H = 160, 120
DEPTH = "observation.images.cam_front_depth"
COLOUR = "observation.images.cam_front"


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    d = tmp_path_factory.mktemp("depth_rollout")
    rig = depth_physics_rig(d, W, H)
    ran = teleprev("record", rig, "--out", d / "demo.mcap", "--episodes", "1", "--episode-time", "3.0",
                   "--engage-after", "0.3", "--no-preview")
    assert ran.returncode == 0, ran.stderr + ran.stdout
    ran = teleprev("export", d / "demo.mcap", "--repo-id", "lab/depth_demo", "--root", d / "ds")
    assert ran.returncode == 0, ran.stderr + ran.stdout
    return d, rig, d / "ds"


def policy_folder(root: Path, out: Path, inputs: tuple[str, ...], depth_unit: str | None) -> Path:
    """A saved ACT policy over the dataset's `inputs` (lerobot's config, weights and processors, the dataset's
    stats), with the train_config.json lerobot-train writes (its dataset's root and depth_output_unit)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.act.modeling_act import ACTPolicy
    from lerobot.policies.factory import make_pre_post_processors
    from lerobot.utils.feature_utils import dataset_to_policy_features

    meta = LeRobotDatasetMetadata("lab/depth_demo", root=root)
    features = dataset_to_policy_features(meta.features)
    config = ACTConfig(input_features={k: features[k] for k in inputs}, output_features={"action": features["action"]},
                       device="cpu", pretrained_backbone_weights=None, dim_model=32, n_heads=2, dim_feedforward=64,
                       n_encoder_layers=1, n_decoder_layers=1, latent_dim=8, chunk_size=10, n_action_steps=10)
    meta.rescale_depth_stats(depth_unit or "mm")  # what lerobot-train's LeRobotDataset does with its stats
    pre, post = make_pre_post_processors(config, dataset_stats=meta.stats)
    ACTPolicy(config).save_pretrained(out)
    pre.save_pretrained(out)
    post.save_pretrained(out)
    dataset = {"repo_id": "lab/depth_demo", "root": str(root)}
    if depth_unit is not None:
        dataset["depth_output_unit"] = depth_unit
    (out / "train_config.json").write_text(json.dumps({"dataset": dataset}))
    return out


class Recorder:
    """Holds the robot where it is (plans the observed state) and keeps what it is handed, raw and as the
    policy's preprocessor makes it."""

    def __init__(self, folder: Path):
        from lerobot.configs.policies import PreTrainedConfig
        from lerobot.policies.factory import make_pre_post_processors

        self.config = PreTrainedConfig.from_pretrained(str(folder))
        self.pre, _ = make_pre_post_processors(self.config, pretrained_path=str(folder))
        self.plans_ahead = True
        self.seen: list[dict] = []
        self.batches: list[dict] = []

    def chunk(self, observation, task):
        import torch
        from lerobot.policies.utils import prepare_observation_for_inference

        self.seen.append({k: v.copy() for k, v in observation.items()})
        batch = self.pre(prepare_observation_for_inference(dict(observation), torch.device("cpu"), task))
        self.batches.append({k: v for k, v in batch.items() if k.startswith("observation.")})
        return np.repeat(observation["observation.state"].astype(float)[None], 10, axis=0)

    def reset(self):
        pass


def _roll(rig, folder: Path, out: Path) -> tuple[Recorder, object]:
    options = RolloutOptions(policy=folder, out=out, rig=rig, episodes=1, episode_time_s=2.0, engage_after_s=0.3)
    plan = check_rollout(options)
    policy = Recorder(folder)
    result = Rollout(options, plan, policy).run()
    assert not result.unconnected and result.runner.stats.failure == "" and policy.seen
    return policy, plan


def test_a_policy_trained_with_depth_gets_the_cameras_depth_as_the_dataset_gave_it(dataset, tmp_path):
    import torch
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    _, rig, root = dataset
    folder = policy_folder(root, tmp_path / "with_depth", ("observation.state", COLOUR, DEPTH), None)
    card = PolicyCard.read(folder)
    assert card.inputs[DEPTH] == (1, H, W) and card.is_depth(DEPTH) and not card.is_depth(COLOUR)
    assert card.depth_unit == "mm"  # lerobot-train's default when the training did not say
    out = tmp_path / "rollout.mcap"
    policy, plan = _roll(rig, folder, out)
    assert plan.features.names == ("observation.state", COLOUR, DEPTH)

    seen = policy.seen[-1]
    assert set(seen) == {"observation.state", COLOUR, DEPTH}
    depth = seen[DEPTH]
    assert depth.shape == (H, W, 1) and depth.dtype == np.float32
    # exactly a frame the camera recorded, in millimetres (its counts are 0.1 mm)
    with SessionReader(out) as reader:
        recorded = [m.payload for m in reader.messages(["/camera/cam_front/depth"])]
    assert any(np.array_equal(depth[:, :, 0], d.metres() * np.float32(1000)) for d in recorded)

    # the same form as the dataset's: a LeRobotDataset frame (lerobot-train's default unit) batched, and the
    # live one after lerobot's inference preparation, through the same preprocessor
    ds = LeRobotDataset("lab/depth_demo", root=root, video_backend="pyav")
    frame = ds[len(ds) // 2]
    assert ds.depth_output_unit == "mm" and frame[DEPTH].shape == (1, H, W) and frame[DEPTH].dtype == torch.float32
    batch = policy.pre({k: frame[k][None] for k in ("observation.state", COLOUR, DEPTH)} | {"task": [""]})
    live = policy.batches[-1]
    for key in ("observation.state", COLOUR, DEPTH):
        assert live[key].shape == batch[key].shape and live[key].dtype == batch[key].dtype, key
    # the scene is still (the arm holds): the live depth, normalised, is what the dataset's is, but for the
    # quantisation of the dataset's codec (12-bit log steps: 1.5 mm at 1 m, 6 mm at 4 m) and the renderer
    gap = (live[DEPTH] - batch[DEPTH]).abs()
    both = (frame[DEPTH][None] > 100) & torch.from_numpy(depth[None, None, :, :, 0] > 100).reshape(gap.shape)
    assert float(gap[both].median()) < 0.05, float(gap[both].median())


def test_a_policy_trained_in_metres_gets_metres_and_one_without_depth_gets_none(dataset, tmp_path):
    _, rig, root = dataset
    folder = policy_folder(root, tmp_path / "metres", ("observation.state", DEPTH), "m")
    assert PolicyCard.read(folder).depth_unit == "m"
    policy, _ = _roll(rig, folder, tmp_path / "metres.mcap")
    assert set(policy.seen[-1]) == {"observation.state", DEPTH}  # no colour: it was not trained on it
    metres = policy.seen[-1][DEPTH]
    assert 0.3 < float(np.median(metres[metres > 0])) < 5.0

    folder = policy_folder(root, tmp_path / "no_depth", ("observation.state", COLOUR), None)
    policy, plan = _roll(rig, folder, tmp_path / "no_depth.mcap")
    assert plan.features.names == ("observation.state", COLOUR)
    assert set(policy.seen[-1]) == {"observation.state", COLOUR}
    assert policy.seen[-1][COLOUR].shape == (H, W, 3) and policy.seen[-1][COLOUR].dtype == np.uint8
    with SessionReader(tmp_path / "no_depth.mcap") as reader:
        assert "/camera/cam_front/depth" in reader.topics  # the camera's depth is still recorded
        assert len(list(reader.messages([topics.POLICY_ACTION]))) > 0
