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
