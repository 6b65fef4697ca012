"""`teleprev record --engage-after` that never engaged exits 1 and says why in one line (issue 42, item 4):
a session that asked to execute and ran all in preview is a failed run for the script that started it."""

from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.model import load_robot
from teleprev.session.reader import SessionReader
from tests.helpers.cli import teleprev
from tests.helpers.sessions import COLLIDING_LEAP_HOME, colliding_hand_rig


def _error_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("error:")]


def test_a_refused_engage_exits_1_naming_the_refusal(tmp_path):
    assert SelfCollisionChecker(load_robot("leap_hand_right")).collides(COLLIDING_LEAP_HOME)
    out = tmp_path / "s.mcap"
    ran = teleprev("record", colliding_hand_rig(tmp_path), "--duration", "1.5", "--engage-after", "0.3",
                   "--no-preview", "--out", out)
    assert ran.returncode == 1, ran.stdout + ran.stderr
    [line] = _error_lines(ran.stderr)
    assert "never engaged (--engage-after 0.3 s)" in line and "self-collision" in line, line
    with SessionReader(out) as reader:  # the session is complete all the same
        assert len(reader.episodes()) == 1


def test_an_engage_time_no_episode_reached_exits_1(tmp_path):
    out = tmp_path / "s.mcap"
    ran = teleprev("record", "--duration", "1", "--engage-after", "2", "--no-preview", "--out", out)
    assert ran.returncode == 1, ran.stdout + ran.stderr
    [line] = _error_lines(ran.stderr)
    assert "never engaged (--engage-after 2 s): no episode lasted until then" in line, line


def test_an_engaged_session_exits_0(tmp_path):
    ran = teleprev("record", "--duration", "2", "--engage-after", "0.3", "--no-preview", "--out", tmp_path / "s.mcap")
    assert ran.returncode == 0 and not _error_lines(ran.stderr), ran.stdout + ran.stderr
