"""A tiny ACT trained by lerobot-train on a LeRobot dataset (CPU, offline, no pretrained backbone), for the
rollout tests and bench/rollout.py: what a user's `lerobot-train` run makes, at the smallest size."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

# ACT's smallest useful shape: one encoder and decoder layer, 32-wide; a chunk of 45 actions (1.5 s at
# 30 fps) covers an inference of about a second on a busy 2-core machine (640 x 480 images, resnet18).
TINY_ACT = ("--policy.type=act", "--policy.device=cpu", "--policy.push_to_hub=false",
            "--policy.pretrained_backbone_weights=null", "--policy.dim_model=32", "--policy.n_heads=2",
            "--policy.dim_feedforward=64", "--policy.n_encoder_layers=1", "--policy.n_decoder_layers=1",
            "--policy.latent_dim=8", "--policy.chunk_size=45", "--policy.n_action_steps=45")


def lerobot_train_command(dataset_root: Path, repo_id: str, out_dir: Path, steps: int = 2) -> list[str]:
    return [str(Path(sys.executable).with_name("lerobot-train")), f"--dataset.repo_id={repo_id}",
            f"--dataset.root={dataset_root}", "--dataset.video_backend=pyav", *TINY_ACT, f"--steps={steps}",
            "--batch_size=2", "--num_workers=0", f"--save_freq={steps}", "--log_freq=1", "--wandb.enable=false",
            f"--output_dir={out_dir}"]


def train_tiny_act(dataset_root: Path, repo_id: str, out_dir: Path, steps: int = 2, timeout_s: float = 300) -> Path:
    """The trained policy's pretrained_model folder (lerobot-train's checkpoints/last/pretrained_model)."""
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "WANDB_MODE": "disabled"}
    ran = subprocess.run(lerobot_train_command(dataset_root, repo_id, out_dir, steps), env=env, capture_output=True,
                         text=True, timeout=timeout_s)
    folder = out_dir / "checkpoints" / "last" / "pretrained_model"
    if ran.returncode != 0 or not (folder / "model.safetensors").is_file():
        raise AssertionError(f"lerobot-train failed ({ran.returncode}):\n{ran.stdout[-3000:]}\n{ran.stderr[-3000:]}")
    return folder
