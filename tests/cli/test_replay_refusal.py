"""`replay` of commands a robot could only follow slower than recorded is refused with the refusal alone:
it said "can be played at 1.00x at most", a speed that is no option (slower than 1x a servo arm stops
between commands), and for a dataset the 1.00x read as if 1x were fine."""

from __future__ import annotations

from pathlib import Path

from tests.helpers.cli import teleprev

SIM_RIG = Path(__file__).parents[2] / "rigs" / "sim.toml"


def test_the_refusal_alone(sim_dataset, tmp_path):
    # The session's commands are planned below the arm's limits (arm_plan_fraction), so the dataset's actions
    # exceed them only on a robot with lower ones: a rig at half the acceleration and a fifth of the jerk.
    rig = tmp_path / "slow.toml"
    slower = "[pipeline]\narm_acceleration = 5.0\narm_jerk = 100.0\n"
    rig.write_text(SIM_RIG.read_text().replace("[pipeline]\n", slower, 1))
    ran = teleprev("replay", sim_dataset, "--episode", "0", "--to", "sim", "--config", rig, "--engage-after", "0",
                   "--no-preview")
    assert ran.returncode == 2, ran.stdout + ran.stderr
    assert ran.stderr.strip() == (f"error: {sim_dataset}: the dataset's actions exceed the robot's acceleration or "
                                  "jerk limit at 1x, and slower than 1x a servo arm would stop between them: add "
                                  "--smooth to re-command them through the jerk-limited generator")
    assert "at most" not in ran.stdout + ran.stderr
