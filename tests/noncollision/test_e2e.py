"""A tiny run of the whole module through the CLI: dataset -> CPN -> grid search -> CCN -> Corrector."""

import json

import numpy as np
from safetensors import safe_open
from typer.testing import CliRunner

from teleprev.cli.app import app
from teleprev.noncollision.corrector import Corrector


def _run(*args):
    result = CliRunner().invoke(app, list(map(str, args)))
    assert result.exit_code == 0, f"{args[:2]} failed:\n{result.output}\n{result.exception!r}"
    return result.output


def test_tiny_end_to_end(tmp_path, hand, hand_checker):
    data, models = tmp_path / "data", tmp_path / "models"
    cpn, ccn = models / "cpn_leap_hand.safetensors", models / "ccn_leap_hand.safetensors"
    out = _run(
        "collision",
        "dataset",
        data,
        "--uniform",
        4000,
        "--boundary",
        4000,
        "--shard-size",
        2000,
        "--workers",
        2,
        "--seed",
        1,
    )
    assert "wrote 8,000 configurations" in out
    assert "resumed" in _run(
        "collision", "dataset", data, "--uniform", 4000, "--boundary", 4000, "--shard-size", 2000, "--seed", 1
    )

    out = _run("collision", "train-cpn", data, "--out", cpn, "--epochs", 3, "--hidden", "64,64", "--batch-size", 512,
               "--heldout-uniform", 2000, "--heldout-boundary", 1000)
    assert "epoch   3/3" in out and "held-out: cpn_auc_min_link" in out
    card = (models / "cpn_leap_hand.md").read_text()
    assert "teleprev collision train-cpn" in card and "cpn_auc_min_link" in card

    grid = tmp_path / "grid"
    out = _run("collision", "grid-search", data, "--cpn", cpn, "--out", grid, "--alphas", "1", "--betas", "0.3,3",
               "--epochs", 1, "--hidden", "64,64", "--max-train", 3000, "--val-exact", 200)
    chosen = json.loads(grid.with_suffix(".json").read_text())["chosen"]
    assert len(json.loads(grid.with_suffix(".json").read_text())["points"]) == 2 and chosen["beta"] in (0.3, 3.0)
    assert "**chosen**" in grid.with_suffix(".md").read_text()

    out = _run(
        "collision",
        "train-ccn",
        data,
        "--cpn",
        cpn,
        "--out",
        ccn,
        "--grid",
        grid.with_suffix(".json"),
        "--epochs",
        3,
        "--hidden",
        "64,64",
        "--val-exact",
        200,
        "--heldout-uniform",
        500,
        "--heldout-trajectory",
        200,
    )
    assert f"beta = {chosen['beta']:g}" in out and "held-out: ccn_valid_frac" in out
    with safe_open(str(ccn), framework="numpy") as f:
        meta = f.metadata()
    assert (
        meta["urdf_sha256"] == hand.urdf_sha256 and json.loads(meta["training"])["settings"]["beta"] == chosen["beta"]
    )
    assert "ccn_valid_frac" in (models / "ccn_leap_hand.md").read_text()

    corrector = Corrector.load(models, hand, hand_checker)
    q = hand.sample_uniform(600, np.random.default_rng(11))
    invalid = q[hand_checker.pair_matrix(q).any(axis=1)][:300]
    results = [corrector.correct(x) for x in invalid]
    outputs = np.array([r.q for r in results])
    assert not hand_checker.pair_matrix(outputs).any()
    assert np.all(outputs >= hand.lower) and np.all(outputs <= hand.upper)
    assert {r.action for r in results} <= {"ccn", "fallback"}
