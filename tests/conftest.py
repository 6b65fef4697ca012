# isort: off
import teleprev  # noqa: F401  first: it pins the numeric platform before numpy loads
# isort: on
import numpy as np
import pytest


@pytest.fixture(scope="session")
def hand():
    from teleprev.robot.model import load_robot

    return load_robot("leap_hand_right")


@pytest.fixture(scope="session")
def xarm6():
    from teleprev.robot.model import load_robot

    return load_robot("xarm6")


@pytest.fixture(scope="session")
def hand_checker(hand):
    """FCL deciding every contact: the independent reference the compiled check is tested against."""
    from teleprev.robot.collision import FclSelfCollisionChecker

    return FclSelfCollisionChecker(hand)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def forkserver():
    """Local workers fork from one server that has imported what eval's and export's workers preload.

    A process has a single fork server, started with the preload of the first executor that runs; in a
    test run an eval corpus comes first, and every export worker after it would import lerobot on its
    own (seconds each). Started here, in the background, with both."""
    import multiprocessing
    from multiprocessing import forkserver as server

    from teleprev.evaluation.corpus import PRELOAD as EVAL_PRELOAD
    from teleprev.export.parallel import PRELOAD as EXPORT_PRELOAD

    multiprocessing.get_context("forkserver").set_forkserver_preload(
        ["teleprev.corpus.orphans", *EVAL_PRELOAD, *EXPORT_PRELOAD])
    server.ensure_running()


@pytest.fixture(scope="session")
def sim_session(tmp_path_factory):
    """A fresh recording on the default sim rig (one pick_place episode of 3 s, engaged 0.5 s in), shared by
    the tests that read one; a test that changes a session copies it first."""
    from tests.helpers.sessions import record_sim

    path = tmp_path_factory.mktemp("sim_session") / "clean.mcap"
    record_sim(path, seconds=3.0, engage_after=0.5)
    return path


@pytest.fixture(scope="session")
def sim_dataset(sim_session, tmp_path_factory):
    """sim_session exported with the default recipe as the LeRobot dataset lab/sim (its root), shared by the
    tests that read one (and never change it)."""
    from tests.helpers import cli

    root = tmp_path_factory.mktemp("sim_dataset") / "sim"
    ran = cli.teleprev("export", sim_session, "--repo-id", "lab/sim", "--root", root)
    assert ran.returncode == 0, ran.stderr + ran.stdout
    return root


@pytest.fixture(scope="session")
def sim_corpus(tmp_path_factory):
    """A folder of three short sim sessions, a.mcap, b.mcap and c.mcap (tests.helpers.sessions.record_corpus),
    shared by the corpus tests (which only read it)."""
    from tests.helpers.sessions import record_corpus

    return record_corpus(tmp_path_factory.mktemp("corpus"))
