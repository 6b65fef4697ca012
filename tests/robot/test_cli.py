"""`teleprev robot ...` and the top-level CLI, run as a user would."""

import subprocess
import sys

from typer.testing import CliRunner

from teleprev.cli.app import app

runner = CliRunner()


def test_help_and_version_answer():
    result = subprocess.run([sys.executable, "-m", "teleprev.cli.app", "--help"], capture_output=True, text=True)
    assert result.returncode == 0 and "robot" in result.stdout
    result = subprocess.run([sys.executable, "-m", "teleprev.cli.app", "--version"], capture_output=True, text=True)
    assert result.stdout.startswith("teleprev ")


def test_help_imports_no_heavy_libraries():
    code = ("import sys; import teleprev.cli.app; "
            "print(sorted(m for m in ('numpy','torch','lerobot','cv2','numba') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stdout.strip()
    assert out == "[]"


def test_robot_info_prints_joint_table_and_neutral_check():
    result = runner.invoke(app, ["robot", "info", "leap_hand_right"])
    assert result.exit_code == 0, result.output
    assert "collision-free" in result.output
    assert "2.094" in result.output and "8.48" in result.output


def test_robot_check_prints_rates_per_link():
    result = runner.invoke(app, ["robot", "check", "leap_hand_right", "--samples", "400"])
    assert result.exit_code == 0, result.output
    assert "self-collision" in result.output and "fingertip_2" in result.output


def test_robot_info_on_a_missing_file_is_one_clear_line(tmp_path):
    missing = tmp_path / "nope.urdf"
    result = subprocess.run(
        [sys.executable, "-m", "teleprev.cli.app", "robot", "info", str(missing)], capture_output=True, text=True
    )
    assert result.returncode == 2
    assert "error:" in result.stderr and "nope.urdf" in result.stderr and "Traceback" not in result.stderr
