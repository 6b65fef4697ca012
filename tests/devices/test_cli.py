"""`teleprev devices list` and `teleprev devices check`, and rig files with device errors."""

from __future__ import annotations

import socket
import threading
import time

import cv2
import numpy as np
import pytest
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder
from typer.testing import CliRunner

from teleprev.cli.app import app
from teleprev.errors import ConfigError
from teleprev.rig import load_rig
from tests.helpers.ports import free_port

runner = CliRunner()


def test_list_shows_every_plugin_with_kind_module_and_missing_extras():
    result = runner.invoke(app, ["devices", "list"], env={"COLUMNS": "160"})
    assert result.exit_code == 0, result.output
    lines = {line.split()[1]: line for line in result.output.splitlines() if line.startswith("│")}
    for name, kind in (
        ("vmc.suit", "suit"),
        ("vmc.glove", "glove"),
        ("opencv.camera", "camera"),
        ("replay.hand", "hand"),
        ("sim.glove", "glove"),
    ):
        assert kind in lines[name] and "ok" in lines[name]
    assert "teleprev_devices.vmc:VmcSuit" in lines["vmc.suit"]
    import importlib.util

    for name, extra, module in (("xarm.arm", "xarm", "xarm"), ("leap.hand", "leap", "dynamixel_sdk")):
        expected = "ok" if importlib.util.find_spec(module) else f"needs the '{extra}' extra"
        assert expected in lines[name]


def write_video(path, frames=40, fps=20.0):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (64, 48))
    for i in range(frames):
        writer.write(np.full((48, 64, 3), (i * 5) % 256, np.uint8))
    writer.release()


def vmc_sender(port: int, stop: threading.Event, rate_hz=60.0):
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    names = ["Hips", "Spine", "RightUpperArm", "RightLowerArm", "RightHand"]
    while not stop.is_set():
        b = OscBundleBuilder(IMMEDIATELY)
        for n in names:
            m = OscMessageBuilder("/VMC/Ext/Bone/Pos")
            m.add_arg(n)
            for v in (0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0):
                m.add_arg(v)
            b.add_content(m.build())
        sock.sendto(b.build().dgram, ("127.0.0.1", port))
        time.sleep(1.0 / rate_hz)
    sock.close()


def test_check_reads_a_rig_and_reports_rates_and_the_device_that_is_silent(tmp_path):
    write_video(tmp_path / "table.avi")
    suit_port, glove_port = free_port(), free_port()
    rig = tmp_path / "rig.toml"
    rig.write_text(
        f'[devices.cam]\nplugin = "opencv.camera"\nsource = "table.avi"\n\n'
        f'[devices.suit]\nplugin = "vmc.suit"\nport = {suit_port}\nrate_hz = 60.0\n\n'
        f'[devices.glove]\nplugin = "vmc.glove"\nport = {glove_port}\n'  # nobody sends here
    )
    stop = threading.Event()
    sender = threading.Thread(target=vmc_sender, args=(suit_port, stop), daemon=True)
    sender.start()
    try:
        result = runner.invoke(app, ["devices", "check", str(rig), "--seconds", "1.5"], env={"COLUMNS": "200"})
    finally:
        stop.set()
        sender.join()
    out = result.output
    assert result.exit_code == 1, out  # the silent glove fails the check
    rows = {
        line.split()[0]: line.split()
        for line in out.splitlines()
        if line.strip().split(" ")[0] in ("cam", "suit", "glove")
    }
    cam, suit, glove = rows["cam"], rows["suit"], rows["glove"]
    assert cam[1:4] == ["opencv.camera", "camera", "ok"] and 20 <= int(cam[4]) <= 31
    cam_rate, cam_nominal = map(float, cam[5].split("/"))
    assert cam_nominal == 20.0 and 15 < cam_rate < 25
    assert suit[1:4] == ["vmc.suit", "suit", "ok"] and 45 <= int(suit[4]) <= 95
    assert float(suit[5].split("/")[0]) > 40
    assert glove[1:5] == ["vmc.glove", "glove", "gap", "0"]
    assert "glove: gap: no data for" in out and "1 of 3 devices did not stream cleanly" in out


def test_check_reports_a_device_that_cannot_open_and_keeps_the_others(tmp_path):
    """On an 80-column terminal too: nothing in the table is cut short (it widens instead), and the error
    is said in full under it."""
    write_video(tmp_path / "table.avi", frames=200)
    rig = tmp_path / "rig.toml"
    rig.write_text('[devices.cam]\nplugin = "opencv.camera"\nsource = "table.avi"\n\n'
                   '[devices.unplugged_wrist_camera]\nplugin = "opencv.camera"\nsource = "unplugged.avi"\n')
    result = runner.invoke(app, ["devices", "check", str(rig), "--seconds", "0.5"], env={"COLUMNS": "80"})
    assert result.exit_code == 1
    assert "no such video file" in result.output and "unplugged.avi" in result.output and "…" not in result.output
    cam = next(line.split() for line in result.output.splitlines() if line.strip().startswith("cam "))
    assert cam[3] == "ok" and int(cam[4]) >= 8
    gone = next(
        line.split() for line in result.output.splitlines() if line.strip().startswith("unplugged_wrist_camera ")
    )
    assert gone[1:4] == ["opencv.camera", "camera", "error"]


GLOVE = '[devices.glove]\nplugin = "sim.glove"\n'


@pytest.mark.parametrize(
    "body, message",
    [
        (
            '[devices.suit]\nplugin = "vmc.suit"\nprot = 39539\n',
            r"rig.toml \[devices.suit\]: unknown key 'prot' \(known keys: host, port",
        ),
        (
            '[devices.suit]\nplugin = "vmc.suit"\nport = "39539"\n',
            r"rig.toml \[devices.suit\].port: expected an integer, got '39539'",
        ),
        (
            '[devices.cam]\nplugin = "opencv.camra"\n',
            r"rig.toml \[devices.cam\]: unknown device plugin 'opencv.camra' \(installed: .*opencv.camera",
        ),
        ("[devices.cam]\nsource = 0\n", r"rig.toml \[devices.cam\]: missing required key 'plugin'"),
        ('[devices.glove]\nplugin = "replay.glove"\n', r"rig.toml \[devices.glove\]: session is required"),
        ('[rig]\nname = "x"\n', r"rig.toml: no devices"),
        # values, not only keys (issue 15 item 8)
        ('[pipeline]\ntrigger = "suit"\n' + GLOVE, r"rig.toml \[pipeline\]: unknown key 'trigger': it was removed"),
        ('[pipeline]\ntrigger = "glove"\n' + GLOVE, r"rig.toml \[pipeline\]: unknown key 'trigger'"),
        (
            '[pipeline]\ngripper_joint = "index9"\n' + GLOVE,
            r"rig.toml \[pipeline\]: gripper_joint must be an SMPL-X hand joint",
        ),
        (
            '[pipeline]\ntcp_link = "palm"\n' + GLOVE,
            r"rig.toml \[pipeline\].tcp_link: the robot 'xarm6_leap_hand' has no link 'palm'",
        ),
        ('[rig]\nrobot = "xarm9"\n' + GLOVE, r"rig.toml \[rig\].robot: no such robot 'xarm9'"),
        ('[rig]\nend_effector = "suction"\n' + GLOVE, r"rig.toml \[rig\].end_effector: expected one of"),
        (
            '[rig]\ncalibration = "calib/none.toml"\n' + GLOVE,
            r"rig.toml \[rig\].calibration: no such file .*calib/none.toml",
        ),
        ('[rig]\nmodels = "no_models"\n' + GLOVE, r"rig.toml \[rig\].models: no such folder .*no_models"),
        ('[devices.glove]\nplugin = "sim.glove"\ntask = "juggle"\n', r"rig.toml \[devices.glove\]: task must be"),
    ],
)
def test_rig_errors_name_the_file_table_and_key(tmp_path, body, message):
    rig = tmp_path / "rig.toml"
    rig.write_text(body)
    with pytest.raises(ConfigError, match=message):
        load_rig(rig)


def test_a_rig_missing_a_device_kind_says_which(tmp_path):
    rig = tmp_path / "rig.toml"
    rig.write_text('[devices.cam]\nplugin = "opencv.camera"\n')
    with pytest.raises(ConfigError, match=r"rig.toml: the rig has no glove and no suit device"):
        load_rig(rig).require("glove", "suit")


def test_cli_prints_rig_errors_as_one_line(tmp_path):
    from tests.helpers.cli import teleprev

    rig = tmp_path / "rig.toml"
    rig.write_text('[devices.suit]\nplugin = "vmc.suit"\nhost = "not-an-ip"\n')
    result = teleprev("devices", "check", rig)
    assert result.returncode == 2
    assert (
        "error:" in result.stderr
        and "[devices.suit]" in result.stderr
        and "host must be an IPv4 address" in result.stderr
    )
    assert "Traceback" not in result.stderr


def test_a_rig_recorded_with_the_removed_trigger_key_still_loads():
    from teleprev.rig import default_rig_path, load_rig_text

    text = default_rig_path().read_text().replace("[pipeline]\n", '[pipeline]\ntrigger = "glove"\n')
    assert "trigger" in text
    assert load_rig_text(text, "session.mcap: recorded rig").pipeline == load_rig(default_rig_path()).pipeline
