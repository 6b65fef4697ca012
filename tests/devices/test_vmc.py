"""vmc.suit / vmc.glove: real OSC bundles sent over UDP loopback from another socket."""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest
from pythonosc.udp_client import SimpleUDPClient

from teleprev import topics
from teleprev.clock import SessionClock
from teleprev.devices.contract import DeviceContext
from teleprev.devices.runner import DeviceRunner
from teleprev.human.smplx import JOINT_INDEX, angles_from_hand_pose, hand_pose_from_values
from teleprev.transforms import axis_angle_to_matrix, matrix_to_quat, quat_to_matrix
from teleprev_devices.vmc import VmcGlove, VmcSuit
from teleprev_devices.vmc.decode import VmcDecoder
from teleprev_devices.vmc.plugins import BODY_POSE_NAMES, VmcSettings, VmcSuitSettings
from tests.helpers.ports import free_port
from tests.helpers.vmc import arm_frame, arm_messages, bone, bundle, msg, unity_quat
from tests.helpers.wait import wait_until


@pytest.fixture
def context():
    return DeviceContext(SessionClock())


def read_until(device, n, timeout=2.0):
    out, deadline = [], time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        out.extend(device.read(0.05))
    return out


def test_index_flexion_sent_over_osc_comes_out_as_the_same_flexion(context):
    port = free_port()
    glove = VmcGlove("g", VmcSettings(port=port), context)
    glove.connect()
    try:
        client = SimpleUDPClient("127.0.0.1", port)
        flex = {"RightIndexProximal": 0.7, "RightMiddleIntermediate": 1.1, "RightLittleDistal": 0.4}
        # Curling towards the palm in Unity: the finger (+x in T-pose) turns towards the palm (-y),
        # i.e. a negative turn about Unity z. Check that geometry first, so the test cannot agree
        # with a sign mistake in the plugin.
        q = unity_quat([0, 0, 1], -0.7)
        tip = quat_to_matrix(q) @ np.array([1.0, 0.0, 0.0])
        assert tip[1] < 0  # towards the palm
        abd = 0.2  # index abduction towards the thumb (+z in Unity, forward in T-pose)
        q_index = unity_quat([0, 1, 0], -abd)  # turning +x towards +z is about -y in Unity's math
        assert (quat_to_matrix(q_index) @ [1.0, 0, 0])[2] > 0
        q_index_both = quat_to_matrix(q) @ quat_to_matrix(q_index)  # curled, then sideways in the curled frame
        msgs = [bone("RightIndexProximal", (0.03, 0, 0), matrix_to_quat(q_index_both))]
        msgs += [bone(n, (0.03, 0, 0), unity_quat([0, 0, 1], -f)) for n, f in flex.items() if n != "RightIndexProximal"]
        client.send(bundle(*msgs))
        samples = read_until(glove, 1)
        assert len(samples) == 1 and samples[0].topic == "/glove/g/hand"
        js = samples[0].payload
        pose = hand_pose_from_values(js.names, js.positions)
        flexion, abduction = angles_from_hand_pose(pose)
        assert flexion[JOINT_INDEX["index1"]] == pytest.approx(0.7, abs=1e-6)
        assert abduction[JOINT_INDEX["index1"]] == pytest.approx(abd, abs=1e-6)
        assert flexion[JOINT_INDEX["middle2"]] == pytest.approx(1.1, abs=1e-6)
        assert flexion[JOINT_INDEX["pinky3"]] == pytest.approx(0.4, abs=1e-6)  # Little -> pinky
        untouched = [j for j in JOINT_INDEX if j not in ("index1", "middle2", "pinky3")]
        assert np.allclose(pose[[JOINT_INDEX[j] for j in untouched]], 0.0)
        # Geometrically: SMPL-X's finger (-x) under the output rotation is Unity's curled finger, mirrored.
        r = axis_angle_to_matrix(pose[JOINT_INDEX["middle2"]])
        unity_tip = quat_to_matrix(unity_quat([0, 0, 1], -1.1)) @ [1.0, 0, 0]
        assert np.allclose(r @ [-1.0, 0, 0], np.diag([-1.0, 1, 1]) @ unity_tip)
    finally:
        glove.disconnect()


def test_suit_wrist_chains_root_and_bones_into_the_suit_frame(context):
    port = free_port()
    suit = VmcSuit("s", VmcSuitSettings(port=port), context)
    suit.connect()
    try:
        client = SimpleUDPClient("127.0.0.1", port)
        # T-pose, avatar at the origin facing Unity +z: the right hand is 0.67 m to the right (+x),
        # 1.35 m up; in the suit frame right is -y and up is +z.
        client.send(arm_frame())
        pose = read_until(suit, 1)[0].payload
        assert pose.frame_id == "suit"
        assert np.allclose(pose.position, [0.0, -0.67, 1.35])
        r = pose.matrix()[:3, :3]
        assert np.allclose(r @ [-1.0, 0, 0], [0, -1, 0])  # fingers: the operator's right
        assert np.allclose(r @ [0, -1.0, 0], [0, 0, -1])  # palm down
        assert np.allclose(r @ [0, 0, 1.0], [1, 0, 0])  # thumb forward

        # Forearm turned forward (Unity +x -> +z is a -90 degree turn about Unity y), avatar moved 1 m
        # forward (Unity +z): hand 0.25 m in front of the elbow, fingers forward.
        client.send(arm_frame(root_pos=(0, 0, 1.0), elbow_quat=unity_quat([0, 1, 0], -np.pi / 2)))
        pose = read_until(suit, 1)[0].payload
        assert np.allclose(pose.position, [1.25, -0.42, 1.35])
        r = pose.matrix()[:3, :3]
        assert np.allclose(r @ [-1.0, 0, 0], [1, 0, 0])

        # The avatar turned to face Unity +x (a +90 degree turn about Unity y): its right is now Unity -z,
        # which is the suit's -x.
        client.send(arm_frame(root_quat=unity_quat([0, 1, 0], np.pi / 2)))
        pose = read_until(suit, 1)[0].payload
        assert np.allclose(pose.position, [-0.67, 0.0, 1.35])
    finally:
        suit.disconnect()


def test_suit_body_joints_and_device_time(context):
    port = free_port()
    suit = VmcSuit("s", VmcSuitSettings(port=port, body=True), context)
    assert [s.topic for s in suit.streams()] == ["/suit/s/wrist", "/suit/s/body"]
    suit.connect()
    try:
        client = SimpleUDPClient("127.0.0.1", port)
        elbow = unity_quat([0, 1, 0], -0.5)
        client.send(arm_frame(elbow_quat=elbow, t=1000.0))
        first = read_until(suit, 2)
        time.sleep(0.05)  # sent 50 ms later but claims 7.8125 ms: device time decides the spacing
        client.send(arm_frame(elbow_quat=elbow, t=1000.0078125))
        second = read_until(suit, 2)
        body = {s.topic: s.payload for s in first}["/suit/s/body"]
        assert body.names == BODY_POSE_NAMES
        values = body.as_dict()
        # D R D: a turn about Unity y becomes the opposite turn about SMPL-X y.
        assert values["right_elbow.y"] == pytest.approx(0.5) and values["right_elbow.x"] == pytest.approx(0.0)
        assert values["left_knee.x"] == 0.0
        assert second[0].payload.stamp_ns - first[0].payload.stamp_ns == 7_812_500
        assert first[0].payload.stamp_ns <= context.clock.now_ns()
    finally:
        suit.disconnect()


def test_garbage_is_counted_and_skipped_without_stopping_the_stream(context):
    port = free_port()
    glove = VmcGlove("g", VmcSettings(port=port), context)
    glove.connect()
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        good = bone("RightIndexProximal", (0.03, 0, 0), unity_quat([0, 0, 1], -0.3))
        sender.sendto(b"\x00\x01garbage that is not OSC", ("127.0.0.1", port))
        sender.sendto(b"#bundle\x00" + b"\xff" * 11, ("127.0.0.1", port))  # a truncated bundle
        sender.sendto(bundle(bone("RightPinkyProximal", (0, 0, 0), (0, 0, 0, 1))).dgram, ("127.0.0.1", port))
        sender.sendto(bundle(bone("RightRingProximal", (0, 0, 0), (0, 0, float("nan"), 1))).dgram, ("127.0.0.1", port))
        sender.sendto(bundle(msg("/VMC/Ext/Bone/Pos", "RightRingDistal", "x", 1.0)).dgram, ("127.0.0.1", port))
        # garbage next to a good bone in one bundle: the good bone still counts
        sender.sendto(
            bundle(bone("NoSuchBone"), bone("RightMiddleProximal", (0, 0, 0), (float("inf"), 0, 0, 1)), good).dgram,
            ("127.0.0.1", port),
        )
        samples = read_until(glove, 1)
        assert len(samples) == 1
        pose = hand_pose_from_values(samples[0].payload.names, samples[0].payload.positions)
        assert np.isfinite(pose).all()
        assert angles_from_hand_pose(pose)[0][0] == pytest.approx(0.3)
        wait_until(lambda: glove.counters()["malformed_packets"] >= 2, 5.0, what="two malformed packets counted")
        assert {k: v for k, v in glove.counters().items() if v} == {
            "malformed_packets": 2, "malformed_messages": 1, "unknown_bones": 2, "non_finite": 2}
        sender.sendto(bundle(good).dgram, ("127.0.0.1", port))
        assert len(read_until(glove, 1)) == 1  # still streaming
    finally:
        sender.close()
        glove.disconnect()


def test_suit_and_glove_share_one_port_and_the_runner_reports_skipped_garbage():
    clock = SessionClock()
    context = DeviceContext(clock)
    port = free_port()
    suit = VmcSuit("s", VmcSuitSettings(port=port), context)
    glove = VmcGlove("g", VmcSettings(port=port), context)
    got: list = []
    runners = [DeviceRunner(d, lambda s, t: got.append(s), clock, reconnect_s=0.1) for d in (suit, glove)]
    for r in runners:
        r.start()
    client = SimpleUDPClient("127.0.0.1", port)
    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        wait_until(lambda: all(r.connected for r in runners), 10.0, what="both runners connected")
        for k in range(30):
            fingers = bone("RightIndexProximal", (0.03, 0, 0), unity_quat([0, 0, 1], -0.01 * k))
            client.send(bundle(*arm_messages(), fingers))
            if k == 10:
                raw.sendto(b"not osc", ("127.0.0.1", port))
            time.sleep(0.01)
        # the runner turns counters into events once a second
        wait_until(lambda: {(s.payload.data["device"], s.payload.data["event"]) for s in list(got)
                            if s.topic == topics.DEVICE_EVENT} >= {("s", "skipped"), ("g", "skipped")},
                   10.0, what="both devices' skipped events")
        client.send(arm_frame())
        wait_until(lambda: sum(s.topic == "/suit/s/wrist" for s in list(got)) == 31, 5.0, what="the 31st wrist sample")
    finally:
        raw.close()
        for r in runners:
            r.stop()
    by_topic = {}
    for s in got:
        by_topic.setdefault(s.topic, []).append(s.payload)
    assert len(by_topic["/suit/s/wrist"]) == 31
    assert len(by_topic["/glove/g/hand"]) == 30
    events = [e.data for e in by_topic[topics.DEVICE_EVENT]]
    assert {(e["device"], e["event"]) for e in events} >= {
        ("s", "connected"),
        ("g", "connected"),
        ("s", "skipped"),
        ("g", "skipped"),
    }
    assert any("1 malformed packets" in e["message"] for e in events if e["event"] == "skipped")
    assert not [e for e in events if e["event"] == "error"]  # skipped input is no failure
    assert runners[1].stats().skipped["malformed_packets"] == 1
    assert suit.context.receivers == {}  # the last one out closed the shared socket


def test_timeout_turns_silence_into_a_fault_naming_the_port(context):
    from teleprev.errors import DeviceError

    port = free_port()
    glove = VmcGlove("g", VmcSettings(port=port, timeout_s=0.2), context)
    glove.connect()
    try:
        t0 = time.monotonic()
        with pytest.raises(DeviceError, match=f"no VMC frames on UDP 127.0.0.1:{port} for 0.2 s"):
            while time.monotonic() - t0 < 2.0:
                glove.read(0.05)
        assert 0.2 <= time.monotonic() - t0 < 0.6
    finally:
        glove.disconnect()


def test_port_in_use_is_a_clear_device_error(context):
    from teleprev.errors import DeviceError

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        glove = VmcGlove("g", VmcSettings(port=port), context)
        with pytest.raises(DeviceError, match=f"127.0.0.1:{port}"):
            glove.connect()
        glove.disconnect()


def test_settings_are_checked_when_the_rig_loads(tmp_path):
    from teleprev.errors import ConfigError
    from teleprev.rig import load_rig

    rig = tmp_path / "rig.toml"
    rig.write_text('[devices.suit]\nplugin = "vmc.suit"\nhost = "localhost-ish"\n')
    with pytest.raises(ConfigError, match=r"\[devices.suit\].*host must be an IPv4 address"):
        load_rig(rig)
    rig.write_text('[devices.suit]\nplugin = "vmc.suit"\nport = 70000\n')
    with pytest.raises(ConfigError, match="port must be 0..65535"):
        load_rig(rig)
    rig.write_text('[devices.glove]\nplugin = "vmc.glove"\nallow = ["192.168.1.300"]\n')
    with pytest.raises(ConfigError, match=r"rig.toml \[devices.glove\]: allow: '192.168.1.300' is not an IPv4 address"):
        load_rig(rig)
    rig.write_text('[devices.suit]\nplugin = "vmc.suit"\nbody = true\nport = 39540\n')
    entry = load_rig(rig).devices["suit"]
    assert entry.settings.host == "127.0.0.1" and entry.settings.body and entry.kind == "suit"


def wait_counter(device, key, n, timeout=5.0):
    """The device's counters once `key` has counted `n` (the caller checks it stopped there)."""
    wait_until(lambda: device.counters().get(key, 0) >= n, timeout, what=f"{key} >= {n}")
    return device.counters()


def test_out_of_range_and_non_unit_packets_are_counted_and_skipped_and_the_receiver_lives_on(context):
    """/VMC/Ext/T = 1e300 once ended the receiving thread (OverflowError); a 1e300 quaternion became NaN."""
    port = free_port()
    glove = VmcGlove("g", VmcSettings(port=port), context)
    glove.connect()
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    good = bone("RightIndexProximal", (0.03, 0, 0), unity_quat([0, 0, 1], -0.3))
    try:
        sender.sendto(bundle(good, msg("/VMC/Ext/T", 1e300, types="d")).dgram, ("127.0.0.1", port))
        sender.sendto(bundle(bone("RightIndexProximal", (0.03, 0, 0), (1e300, 0, 0, 1), double=True),
                             msg("/VMC/Ext/T", 1.0, types="d")).dgram, ("127.0.0.1", port))
        sender.sendto(bundle(bone("RightIndexProximal", (0.03, 0, 0), (0.5, 0, 0, 0.5))).dgram, ("127.0.0.1", port))
        sender.sendto(bundle(bone("RightIndexProximal", (1e300, 0, 0), double=True)).dgram, ("127.0.0.1", port))
        wait_counter(glove, "non_unit_rotations", 2)
        counters = wait_counter(glove, "out_of_range", 2)  # the last packet's; they are read in order
        assert counters["out_of_range"] == 2 and counters["non_unit_rotations"] == 2
        assert glove.read(0.05) == []  # nothing of those four reached the device
        assert glove._receiver._thread.is_alive() and not glove._receiver.fanout.failure
        sender.sendto(bundle(good, msg("/VMC/Ext/T", 2.0, types="d")).dgram, ("127.0.0.1", port))
        samples = read_until(glove, 1)
        assert len(samples) == 1 and np.isfinite(samples[0].payload.positions).all()
    finally:
        sender.close()
        glove.disconnect()


def test_a_datagram_that_makes_the_parser_raise_is_counted_and_the_next_one_is_read(monkeypatch):
    """What the decoding process does with each datagram (VmcDecoder.datagram), here in the test's process so
    that the parser can be made to raise."""
    decoder = VmcDecoder()
    parse = decoder.parse
    monkeypatch.setattr(decoder, "parse", lambda data, t: parse(data, t) if data != b"boom" else 1 / 0)
    assert decoder.datagram(b"boom", [], ("127.0.0.1", 5), 1) is None
    assert decoder.counters.failed_packets == 1
    frame = decoder.datagram(bundle(bone("RightIndexProximal", (0.03, 0, 0))).dgram, [], ("127.0.0.1", 5), 2)
    assert frame is not None and frame.updated == {"RightIndexProximal"}


def test_a_clock_outlier_is_counted_and_recorded_as_an_event():
    clock = SessionClock()
    port = free_port()
    glove = VmcGlove("g", VmcSettings(port=port), DeviceContext(clock))
    got: list = []
    runner = DeviceRunner(glove, lambda s, t: got.append(s), clock).start()
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        wait_until(lambda: runner.connected, 10.0, what="the runner connected")
        for k in range(12):  # 10 ms apart in sender time; the eighth claims to be 5 s in the future
            t = 50.0 + 0.01 * k + (5.0 if k == 7 else 0.0)
            sender.sendto(bundle(bone("RightIndexProximal", (0.03, 0, 0)), msg("/VMC/Ext/T", t, types="d")).dgram,
                          ("127.0.0.1", port))
            time.sleep(0.01)
        wait_until(lambda: sum(s.topic == "/glove/g/hand" for s in list(got)) == 12, 5.0, what="12 hand samples")
    finally:
        runner.stop()
        sender.close()
    events = [s.payload.data for s in got if s.topic == topics.DEVICE_EVENT]
    assert any(e["event"] == "skipped" and "1 clock outliers" in e["message"] for e in events), events
    hands = [s.payload.stamp_ns for s in got if s.topic == "/glove/g/hand"]
    assert len(hands) == 12
    kept = np.array(hands[:7] + hands[8:])  # the others keep the offset: 10 ms apart, the outlier's gap aside
    # The offset is the least delay seen so far, so a first datagram that waited for a busy CPU moves the
    # next stamps by that wait (0.3 ms seen beside another test process); an outlier taken in would move
    # them by 5 s.
    assert np.allclose(np.diff(kept), [10e6] * 6 + [20e6] + [10e6] * 3, atol=2e6)


def test_only_allowed_senders_get_through_and_the_others_are_counted(context):
    port = free_port()
    glove = VmcGlove("g", VmcSettings(port=port, allow=("127.0.0.2",)), context)
    assert VmcSettings().host == "127.0.0.1"  # listeners stay on loopback unless told otherwise
    glove.connect()
    allowed, other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM), socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    allowed.bind(("127.0.0.2", 0))
    other.bind(("127.0.0.1", 0))
    frame = bundle(bone("RightIndexProximal", (0.03, 0, 0), unity_quat([0, 0, 1], -0.3))).dgram
    try:
        for _ in range(3):
            other.sendto(frame, ("127.0.0.1", port))
        assert wait_counter(glove, "disallowed_senders", 3)["disallowed_senders"] == 3
        assert glove.read(0.05) == []
        allowed.sendto(frame, ("127.0.0.1", port))
        assert len(read_until(glove, 1)) == 1
        # a second device on the same socket must accept the same senders
        from teleprev.errors import DeviceError

        suit = VmcSuit("s", VmcSuitSettings(port=port), context)
        with pytest.raises(DeviceError, match=r"allow different senders"):
            suit.connect()
        suit.disconnect()
    finally:
        allowed.close()
        other.close()
        glove.disconnect()


def test_frames_missing_from_the_sender_time_are_counted_as_sequence_gaps(context):
    from tests.helpers.vmc import VmcSender

    port = free_port()
    glove = VmcGlove("g", VmcSettings(port=port), context)
    glove.connect()
    sender = VmcSender(port)
    try:
        start = time.monotonic()
        for k in range(60):  # 200 Hz; frames 20, 21 and 45 are lost on the way (never arrive)
            if k not in (20, 21, 45):
                sender.send(sender.frame(k, 200.0))
            time.sleep(max(0.0, start + (k + 1) / 200 - time.monotonic()))
        assert len(read_until(glove, 57)) == 57
        counters = glove.counters()
        assert counters["lost_sequence_gaps"] == 3 and counters["lost_socket_overruns"] == 0
        assert counters["clock_outliers"] == 0 and counters["lost_queue_overflow"] == 0
    finally:
        sender.stop()
        glove.disconnect()


def test_frames_the_device_did_not_read_in_time_are_counted_as_queue_overflow(context):
    from teleprev_devices.fanout import QUEUE

    port = free_port()
    glove = VmcGlove("g", VmcSettings(port=port), context)
    glove.connect()
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for k in range(QUEUE + 10):  # nobody reads meanwhile
            sender.sendto(bundle(bone("RightIndexProximal", (0.03, 0, 0))).dgram, ("127.0.0.1", port))
            if k % 50 == 0:
                time.sleep(0.02)  # (kept under the socket's own buffer)
        assert wait_counter(glove, "lost_queue_overflow", 10)["lost_queue_overflow"] == 10
        assert len(glove.read(0.05)) == QUEUE
    finally:
        sender.close()
        glove.disconnect()


def test_a_thousand_fuzzed_datagrams_never_stop_the_receiver_nor_reach_the_glove_as_nan(context):
    from tests.helpers.vmc import VmcSender, fuzz_datagram

    rng = np.random.default_rng(7)
    port = free_port()
    glove = VmcGlove("g", VmcSettings(port=port), context)
    glove.connect()
    sender = VmcSender(port)
    got = []
    try:
        for k in range(1000):
            sender.send(fuzz_datagram(rng, sender.frame(k, 60.0)) if k % 10 else sender.frame(k, 60.0))
            if k % 20 == 0:
                got.extend(glove.read(0.005))
        time.sleep(0.2)
        got.extend(glove.read(0.05))
        assert glove._receiver._process.poll() is None  # the decoding process took it all
        assert glove._receiver._thread.is_alive() and not glove._receiver.fanout.failure
        values = np.array([s.payload.positions for s in got])
        assert len(values) >= 75 and np.isfinite(values).all()
        counters = glove.counters()
        assert sum(v for k, v in counters.items() if not k.startswith("lost_")) >= 750
    finally:
        sender.stop()
        glove.disconnect()


def test_an_unreadable_bundle_element_is_counted_not_logged(context, capfd):
    port = free_port()
    glove = VmcGlove("g", VmcSettings(port=port), context)
    glove.connect()
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        good = bundle(bone("RightIndexProximal", (0.03, 0, 0))).dgram
        element = b"junk" * 4
        sender.sendto(good + len(element).to_bytes(4, "big") + element, ("127.0.0.1", port))  # python-osc warns here
        assert len(read_until(glove, 1)) == 1
        assert glove.counters()["malformed_messages"] == 1
        assert "Could not identify" not in capfd.readouterr().err
    finally:
        sender.close()
        glove.disconnect()
