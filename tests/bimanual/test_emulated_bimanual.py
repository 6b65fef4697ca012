"""An emulated bimanual rig: two xArm controller emulators and two Dynamixel buses, each side's arm and hand
driven through the real xArm and LEAP plugins and their SDKs, from paced processes of their own, by one
simulated operator. Each side's commands are written on its own wire and arrive at its own controller."""

from __future__ import annotations

from tests.helpers.emulated_bimanual import check_emulated_run, run_emulated_bimanual


def test_two_emulated_arms_and_hands_driven_through_their_sdks(tmp_path):
    run = run_emulated_bimanual(tmp_path)
    assert check_emulated_run(run) == []
