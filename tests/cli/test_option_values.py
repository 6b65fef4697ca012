"""Every numeric (or choice) option of every command with a value out of its range, NaN, infinity or
unknown is refused before the work: one line naming the option and what it takes, exit 2, nothing
written. The encoder settings were accepted (a crf x264 clamps, a gop of 10^8, an encoder named 'bogus'
that fell back to the default) or refused by the encoder after an episode's frames were read, with a
traceback (a preset x264 does not have)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli.test_mistakes import nothing_made, one_line
from tests.helpers.cli import teleprev

FIXTURE = Path(__file__).parents[1] / "fixtures" / "sim_v2.mcap"
EXPORT = ["export", FIXTURE, "--repo-id", "lab/x", "--root", "ds"]


@pytest.mark.parametrize("args, said", [
    # export's encoder settings
    ([*EXPORT, "--crf", "60"], "crf must be 0..51 for h264, got 60"),
    ([*EXPORT, "--crf", "-1"], "crf must be 0..51 for h264, got -1"),
    ([*EXPORT, "--codec", "av1", "--crf", "64"], "crf must be 0..63 for av1, got 64"),
    ([*EXPORT, "--preset", "bogus"], "for h264 the preset is one of ultrafast, superfast"),
    ([*EXPORT, "--codec", "hevc", "--preset", "7"], "for hevc the preset is one of ultrafast"),
    ([*EXPORT, "--codec", "av1", "--preset", "fast"], "for av1 the preset is an SVT-AV1 preset number 0..13"),
    ([*EXPORT, "--gop", "0"], "gop (the keyframe interval, in frames) must be 1..1000, got 0"),
    ([*EXPORT, "--gop", "100000000"], "gop (the keyframe interval, in frames) must be 1..1000, got 100000000"),
    ([*EXPORT, "--encoder", "bogus"], "encoder must be teleprev or lerobot, got 'bogus'"),
    ([*EXPORT, "--codec", "vp9"], "'vp9' is not one of 'h264', 'hevc', 'av1'"),
    # export's other numbers
    ([*EXPORT, "--workers", "0"], "--workers must be at least 1, got 0"),
    ([*EXPORT, "--fps", "-1"], "'--fps'"),
    ([*EXPORT, "--holdout", "1.5"], "--holdout must be a fraction between 0 and 1, got 1.5"),
    ([*EXPORT, "--max-gap-ms", "-5"], "max_gap_ms must be a finite number > 0, got -5"),
    ([*EXPORT, "--max-gap-ms", "nan"], "max_gap_ms must be a finite number > 0, got nan"),  # was accepted
    ([*EXPORT, "--max-gap-ms", "inf"], "max_gap_ms must be a finite number > 0, got inf"),
    (["import", FIXTURE, "--repo-id", "lab/x", "--root", "ds", "--fps", "-2"], "'--fps'"),
    # replay, eval
    (["replay", FIXTURE, "--engage-after", "-1", "--to", "sim"], "--engage-after must be 0 or more seconds, got -1"),
    (["replay", FIXTURE, "--engage-after", "nan", "--to", "sim"], "--engage-after must be 0 or more seconds, got nan"),
    (["replay", FIXTURE, "--speed", "inf"], "--speed must be a finite multiple of the recorded speed"),
    (["replay", FIXTURE, "--speed", "0"], "'--speed'"),
    (["replay", FIXTURE, "--foxglove", "70000"], "'--foxglove'"),
    (["eval", FIXTURE, "--rows", "0"], "'--rows'"),
    (["eval", FIXTURE, "--workers", "0"], "'--workers'"),
    # record, rollout, calibrate, devices
    (["record", "--duration", "3", "--connect-timeout", "nan"], "--connect-timeout must be a positive number"),
    (["record", "--duration", "inf"], "--duration must be a positive number of seconds, got inf"),
    (["record", "--duration", "3", "--foxglove", "99999"], "'--foxglove'"),
    (["record", "--duration", "3", "--foxglove", "-1"], "'--foxglove'"),  # was "No such option: -1"
    (["replay", FIXTURE, "--foxglove", "-5"], "'--foxglove'"),
    (["rollout", "--policy", "nowhere", "--episodes", "0"], "--episodes must be 1 or more, got 0"),
    (["rollout", "--policy", "nowhere", "--episode-time", "-1"], "--episode-time must be a positive number"),
    # named before the policy folder is looked for (they named the missing policy instead)
    (["rollout", "--policy", "nowhere", "--task", "bogus"], "--task: task 'bogus' is not one"),
    (["rollout", "--policy", "nowhere", "--recipe", "bogus"], "bogus: no such recipe file"),
    (["calibrate", "--seconds", "nan", "--hold", "1"], "--seconds must be a positive number of seconds, got nan"),
    (["calibrate", "--seconds", "1", "--hold", "-5"], "--hold must be 0 or more seconds, got -5"),
    (["devices", "check", "--seconds", "0"], "'--seconds'"),
    (["devices", "check", "--seconds", "inf"], "--seconds must be a positive number of seconds, got inf"),  # traceback
    # seeds: numpy's generators take none below 0 (a ValueError traceback after the work began)
    (["robot", "exclusions", "leap_hand_right", "--seed", "-1"], "'--seed'"),
    (["collision", "dataset", "made", "--seed", "-1"], "'--seed'"),
    ([*EXPORT, "--seed", "-1"], "'--seed'"),
    # the collision trainers, before torch loads: a device torch does not know (a traceback after the training
    # data was read), a learning rate of 0 (trained nothing and wrote the model), a URDF that is not there
    (["collision", "train-cpn", FIXTURE.parent, "--device", "bogus"], "--device must be auto, cpu, cuda"),
    (["collision", "train-ccn", FIXTURE.parent, "--device", "cuda:x"], "--device must be auto, cpu, cuda"),
    (["collision", "train-cpn", FIXTURE.parent, "--lr", "0"], "--lr must be a finite learning rate more than 0"),
    (["collision", "dataset", "made", "--robot", "bogus"], "--robot: bogus: no such URDF file"),
])
def test_an_option_value_out_of_range_is_refused_before_the_work(tmp_path, args, said):
    run = teleprev(*args, cwd=tmp_path)
    assert run.returncode == 2, (run.returncode, run.stdout, run.stderr)
    assert said in one_line(run), run.stderr
    nothing_made(tmp_path)


def test_a_recipe_with_a_preset_the_encoder_lacks_is_refused_when_it_loads(tmp_path):
    from teleprev.export.recipe import load_recipe

    recipe = Path(__file__).parents[2] / "datasets" / "recipes" / "default.toml"
    bad = tmp_path / "bad.toml"
    bad.write_text(recipe.read_text().replace('preset = "ultrafast"', 'preset = "warp"'))
    run = teleprev(*EXPORT, "--recipe", bad, cwd=tmp_path)
    assert run.returncode == 2 and "for h264 the preset is one of" in one_line(run) and str(bad) in run.stderr
    load_recipe("default")  # the shipped recipes pass
    load_recipe("sent_commands")
