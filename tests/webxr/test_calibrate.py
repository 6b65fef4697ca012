"""`teleprev calibrate` with the XR page: the headset's forward and the robot's are told apart by the yaw of
a neutral hand, as for a suit (the page played by tests/helpers/xr_page.py over real TLS)."""

from __future__ import annotations

import threading
import time

import numpy as np

from teleprev.retarget.calibration import load_calibration
from teleprev.transforms import rpy_to_matrix
from teleprev_devices.webxr import hands
from tests.helpers.cli import teleprev
from tests.helpers.ports import free_tcp_port
from tests.helpers.xr_hands import local_rotations, xr_hand
from tests.helpers.xr_page import PageClient, webxr_rig


def test_calibrate_learns_the_yaw_between_the_headsets_forward_and_the_robots(tmp_path):
    port = free_tcp_port()
    rig = webxr_rig(tmp_path, port=port)
    yaw = np.radians(30.0)  # the operator's "forward" is 30 degrees left of the headset's
    frame = hands.A.T @ rpy_to_matrix(0.0, 0.0, np.pi + yaw)  # fingers (the hand frame's -x) along it
    right = xr_hand(local_rotations(np.full(15, 0.2), np.zeros(15)), frame, [0.1, 1.1, -0.4])
    stop = threading.Event()

    def play():
        page = None
        while page is None and not stop.is_set():
            try:
                page = PageClient(port)
            except OSError:  # not listening yet
                time.sleep(0.05)
        while not stop.is_set():
            page.frame(right=right)
            time.sleep(1 / 72)
        page.close()

    player = threading.Thread(target=play, daemon=True)
    player.start()
    try:
        out = tmp_path / "cal.toml"
        result = teleprev("calibrate", str(rig), "--hold", "0.3", "--seconds", "0.4", "--out", str(out))
    finally:
        stop.set()
        player.join()
    assert result.returncode == 0, result.stdout + result.stderr
    assert f"XR page: open https://127.0.0.1:{port}/" in result.stdout
    assert abs(load_calibration(out).calibration.suit_yaw - (-yaw)) < 1e-4
