"""A LeRobot policy saved by `lerobot-train` (its `pretrained_model` folder), loaded with lerobot's own API.

    PolicyCard.read(path)    what the folder says of itself, from its JSON files alone (no torch): the
                             policy type, its input and output features with their shapes, the fps of
                             the dataset it was trained on (when that dataset's folder is still there),
                             and the unit its depth maps were given in (lerobot-train's
                             --dataset.depth_output_unit: "mm" unless the training said "m")
    LeRobotPolicy.load(path) the policy (lerobot.policies.factory.get_policy_class) and its saved pre- and
                             post-processors (make_pre_post_processors), run once on a blank observation:
                             `chunk(observation)` gives the actions it plans from one observation, in the
                             dataset's units

torch and lerobot are imported by `load` only (`teleprev rollout`), never by the live path itself.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from teleprev.errors import ConfigError

FILES = ("config.json", "model.safetensors")  # what a saved policy needs (the processors' JSON too)
# lerobot.configs.video.DEFAULT_DEPTH_UNIT (not imported: lerobot loads in ~15 s): the unit LeRobotDataset, and so
# lerobot-train, gives depth maps in unless told otherwise
LEROBOT_DEPTH_UNIT = "mm"
DEPTH_UNITS_M = {"m": 1.0, "mm": 1000.0}  # depth unit -> its units per metre


@dataclass(frozen=True)
class PolicyCard:
    path: Path
    type: str
    inputs: dict[str, tuple[int, ...]]  # feature name -> shape (images: channels, height, width)
    outputs: dict[str, tuple[int, ...]]
    dataset_fps: int  # 0: unknown (the training dataset's folder is gone)
    depth_unit: str = LEROBOT_DEPTH_UNIT  # what the training dataset returned depth maps in: "m" or "mm"

    def is_depth(self, name: str) -> bool:
        """A depth-map input: one channel (LeRobot's <camera>_depth features, (1, H, W); colour has three)."""
        shape = self.inputs[name]
        return len(shape) == 3 and shape[0] == 1

    @classmethod
    def read(cls, path: Path) -> PolicyCard:
        """Refuses (ConfigError naming the folder) what is no saved LeRobot policy."""
        path = Path(path)
        where = str(path)
        if not path.is_dir():
            raise ConfigError("no such policy folder (a `pretrained_model` folder written by lerobot-train)", where)
        missing = [f for f in FILES if not (path / f).is_file()]
        if missing:
            raise ConfigError(f"not a saved LeRobot policy: {', '.join(missing)} missing", where)
        processors = sorted(p.name for p in path.glob("policy_*processor*.json"))
        if not any("preprocessor" in p for p in processors) or not any("postprocessor" in p for p in processors):
            raise ConfigError(
                "the policy's pre/post-processors (policy_preprocessor.json, policy_postprocessor.json) are "
                "missing: save it with lerobot-train",
                where,
            )
        try:
            config = json.loads((path / "config.json").read_text())
            inputs = {k: tuple(v["shape"]) for k, v in config["input_features"].items()}
            outputs = {k: tuple(v["shape"]) for k, v in config["output_features"].items()}
            kind = str(config["type"])
        except (ValueError, KeyError, TypeError) as exc:
            raise ConfigError(
                f"config.json is not a LeRobot policy config ({type(exc).__name__}: {exc})", where
            ) from None
        check_weights(path / "model.safetensors")
        return cls(path, kind, inputs, outputs, _dataset_fps(path), _depth_unit(path))


def check_weights(path: Path) -> None:
    """Refuse (ConfigError) weights that cannot be read: a truncated file, a damaged header, no tensors.
    safetensors checks the header and every tensor's place in the file on opening (no torch, no data read)."""
    from safetensors import safe_open

    try:
        with safe_open(str(path), framework="numpy") as f:
            names = list(f.keys())
    except Exception as exc:  # safetensors' own error types (SafetensorError), and OSError
        raise ConfigError(f"the policy's weights cannot be read (truncated or damaged?): {exc}", str(path)) from None
    if not names:
        raise ConfigError("the policy's weights file holds no tensors", str(path))


def _dataset_fps(path: Path) -> int:
    """The fps of the dataset the policy was trained on, from train_config.json's dataset root (0: unknown)."""
    try:
        train = json.loads((path / "train_config.json").read_text())
        root = train.get("dataset", {}).get("root")
        return int(json.loads((Path(root) / "meta" / "info.json").read_text())["fps"]) if root else 0
    except (OSError, ValueError, KeyError, TypeError):
        return 0


def _depth_unit(path: Path) -> str:
    """The depth unit the policy was trained on (train_config.json's dataset.depth_output_unit; lerobot's default
    where it does not say). Refuses (ConfigError) a unit lerobot does not have."""
    try:
        train = json.loads((path / "train_config.json").read_text())
        unit = (train.get("dataset") or {}).get("depth_output_unit") or LEROBOT_DEPTH_UNIT
    except (OSError, ValueError, AttributeError):
        return LEROBOT_DEPTH_UNIT
    if unit not in DEPTH_UNITS_M:
        raise ConfigError(f"train_config.json's dataset.depth_output_unit is {unit!r}, not one of "
                          f"{', '.join(DEPTH_UNITS_M)}", str(path / "train_config.json"))
    return unit


class LeRobotPolicy:
    """A loaded policy: observations (numpy, as a dataset's frames hold them) in, actions out."""

    def __init__(self, card: PolicyCard, policy, preprocessor, postprocessor, device: str):
        self.card = card
        self.policy = policy
        self.preprocessor = preprocessor
        self.postprocessor = postprocessor
        self.device = device
        # ACT plans a chunk from each observation alone (predict_action_chunk); other policies keep queues and
        # histories of their own, which only their select_action feeds: one action a call, in their order
        self.plans_ahead = card.type == "act"

    @classmethod
    def load(cls, path: Path) -> LeRobotPolicy:
        import torch
        from lerobot.configs.policies import PreTrainedConfig
        from lerobot.policies.factory import get_policy_class, make_pre_post_processors

        card = PolicyCard.read(path)
        config = PreTrainedConfig.from_pretrained(str(path))
        device = "cuda" if config.device == "cuda" and torch.cuda.is_available() else "cpu"
        config.device = device
        if hasattr(config, "pretrained_backbone_weights"):  # the trained weights replace them: download nothing
            config.pretrained_backbone_weights = None
        try:
            policy = get_policy_class(config.type).from_pretrained(str(path), config=config)
        except Exception as exc:  # tensors missing or shaped unlike the config: torch's and safetensors' own errors
            raise ConfigError(f"the policy's weights do not load into its {config.type} model: "
                              f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}",
                              str(path / "model.safetensors")) from None
        policy.to(device)
        policy.eval()
        override = {"device": device}
        pre, post = make_pre_post_processors(config, pretrained_path=str(path),
                                             preprocessor_overrides={"device_processor": override},
                                             postprocessor_overrides={"device_processor": override})
        loaded = cls(card, policy, pre, post, device)
        loaded.warm_up()
        return loaded

    def warm_up(self) -> None:
        """One inference on a blank observation, then a reset: torch's first call (allocations, kernel
        choice) costs seconds, which the first episode's first plan must not wait for."""
        def zeros(name, shape):
            if len(shape) != 3:
                return np.zeros(shape, np.float32)
            return np.zeros((shape[1], shape[2], shape[0]), np.float32 if self.card.is_depth(name) else np.uint8)

        blank = {name: zeros(name, shape) for name, shape in self.card.inputs.items()}
        self.chunk(blank, "")
        self.reset()

    def reset(self) -> None:
        """A new episode: the policy forgets what it kept of the last (its queues, its history)."""
        self.policy.reset()

    def chunk(self, observation: dict[str, np.ndarray], task: str) -> np.ndarray:
        """(n, action width) float64: ACT's plan from this observation, one action per frame from now (its
        n_action_steps); for other policies the next action of their own sequence (n = 1)."""
        import torch
        from lerobot.policies.utils import prepare_observation_for_inference

        with torch.inference_mode():
            batch = prepare_observation_for_inference(dict(observation), torch.device(self.device), task,
                                                      getattr(self.policy.config, "robot_type", None))
            batch = self.preprocessor(batch)
            if self.plans_ahead:
                actions = self.policy.predict_action_chunk(batch)  # (1, chunk, width)
                actions = actions[:, :self.policy.config.n_action_steps]
            else:
                actions = self.policy.select_action(batch)[:, None]  # (1, 1, width)
            actions = self.postprocessor(actions)
        return np.asarray(actions.detach().to("cpu", torch.float64).numpy()).reshape(-1, actions.shape[-1])
