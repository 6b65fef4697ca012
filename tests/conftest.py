import teleprev  # noqa: F401  first: it pins the numeric platform before numpy loads
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
