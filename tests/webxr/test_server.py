"""The XR page's server at its edges, over real TLS and WebSockets on loopback: tokens, garbage, takeovers,
lost frames, and a page left open while teleprev restarts."""

import time
import urllib.error
import urllib.request

import numpy as np
import pytest
from websockets.exceptions import ConnectionClosed, InvalidStatus

from teleprev.clock import SessionClock
from teleprev.devices import DeviceContext
from teleprev.errors import DeviceError
from teleprev_devices.webxr import WebXrGlove, WebXrSuit, hands, wire
from teleprev_devices.webxr.plugins import WebXrSettings
from tests.helpers.xr_page import PageClient, insecure, open_hand


@pytest.fixture
def context():
    return DeviceContext(SessionClock())


@pytest.fixture
def xr(context, tmp_path):
    """A webxr glove and suit sharing one server on loopback (any free port)."""
    glove, suit = _open(context, tmp_path)
    yield glove, suit
    glove.disconnect()
    suit.disconnect()


def _open(context, tmp_path, host="127.0.0.1", port=0):
    settings = WebXrSettings(host=host, port=port, cert_dir=str(tmp_path / "cert"))
    glove, suit = WebXrGlove("g", settings, context), WebXrSuit("s", settings, context)
    glove.connect()
    suit.connect()
    return glove, suit


def _read_until(device, count, timeout_s=5.0):
    got, deadline = [], time.monotonic() + timeout_s
    while len(got) < count and time.monotonic() < deadline:
        got.extend(device.read(0.05))
    return got


def test_frames_become_the_glove_hand_the_raw_joints_the_wrist_and_the_head(xr, tmp_path):
    glove, suit = xr
    page = PageClient(glove._receiver.port)
    right = open_hand()
    right[0, :3] = [0.1, 1.2, -0.4]
    for _ in range(5):
        page.frame(right=right)
    page.frame(right=None)  # the right hand out of view: no hand, no wrist, the head still
    samples = _read_until(glove, 10) + _read_until(suit, 11)
    by_topic = {}
    for s in samples:
        by_topic.setdefault(s.topic, []).append(s.payload)
    assert len(by_topic["/glove/g/hand"]) == 5 and len(by_topic["/suit/s/wrist"]) == 5
    assert len(by_topic["/suit/s/head"]) == 6 and len(by_topic["/glove/g/xr_right"]) == 5
    assert "/glove/g/xr_left" not in by_topic  # the left hand was not tracked
    raw = by_topic["/glove/g/xr_right"][0]
    assert raw.names == hands.RAW_NAMES
    np.testing.assert_array_equal(raw.positions, right.astype(np.float32).reshape(-1))
    np.testing.assert_allclose(by_topic["/suit/s/wrist"][0].position, [0.4, -0.1, 1.2], atol=1e-6)
    page.close()


def test_off_this_machine_every_request_needs_the_token_and_refusals_are_counted(context, tmp_path):
    glove, suit = _open(context, tmp_path, host="0.0.0.0")
    try:
        port = glove._receiver.port
        url = glove.operator_urls()[-1]
        token = url.split("token=")[1]
        assert url == f"https://127.0.0.1:{port}/?token={token}" and len(token) >= 16
        with pytest.raises(InvalidStatus, match="403"):
            PageClient(port)
        with pytest.raises(InvalidStatus, match="403"):
            PageClient(port, token="guess")
        with pytest.raises(urllib.error.HTTPError, match="403"):
            urllib.request.urlopen(f"https://127.0.0.1:{port}/", context=insecure())
        page = urllib.request.urlopen(url, context=insecure()).read().decode()
        assert "xr.js" in page
        assert glove.counters()["refused_connections"] == 3
        client = PageClient(port, token=token)
        client.frame(right=open_hand())
        assert _read_until(glove, 2)
        client.close()
    finally:
        glove.disconnect()
        suit.disconnect()
    # the same certificate and token the next time: the page the operator bookmarked still works
    glove, suit = _open(context, tmp_path, host="0.0.0.0")
    try:
        assert glove.operator_urls()[-1].endswith(f"?token={token}")
    finally:
        glove.disconnect()
        suit.disconnect()


def test_garbage_and_nan_are_counted_and_skipped_and_the_stream_goes_on(xr, tmp_path):
    glove, suit = xr
    page = PageClient(glove._receiver.port)
    page.ws.send(b"\x00" * 10)
    page.ws.send(b"XXXX" + wire.pack(0, 1.0, 1.0)[4:])
    page.ws.send("not json")
    page.ws.send('{"type": "teleport"}')
    bad = open_hand()
    bad[3, 1] = np.nan
    page.frame(right=bad)
    page.frame(right=open_hand())
    samples = _read_until(glove, 2)
    assert [s.topic for s in samples] == ["/glove/g/hand", "/glove/g/xr_right"]
    counts = glove.counters()
    assert counts["malformed_messages"] == 4 and counts["non_finite"] == 1
    page.close()


def test_missing_sequence_numbers_are_counted_as_lost_frames(xr, tmp_path):
    glove, suit = xr
    page = PageClient(glove._receiver.port)
    for seq in (0, 1, 2, 5, 6, 10):
        page.frame(right=open_hand(), seq=seq)
    assert len(_read_until(glove, 12)) == 12
    assert glove.counters()["lost_sequence_gaps"] == 5
    page.close()


def test_a_newer_page_takes_over_and_the_older_is_closed(xr, tmp_path):
    glove, suit = xr
    first = PageClient(glove._receiver.port)
    first.frame(right=open_hand())
    assert _read_until(glove, 2)
    second = PageClient(glove._receiver.port)
    with pytest.raises(ConnectionClosed) as closed:
        for _ in range(50):
            first.ws.recv(timeout=0.2)
    assert closed.value.rcvd.code == 4000
    second.frame(right=open_hand())
    assert _read_until(glove, 2)
    second.close()


def test_actions_without_a_recording_are_answered_not_done(xr, tmp_path):
    glove, suit = xr
    page = PageClient(glove._receiver.port)
    assert "no session is recording" in page.action("toggle_mode")["refused"]
    page.close()


def test_a_port_in_use_is_a_clear_device_error(xr, tmp_path):
    glove, suit = xr
    other = WebXrGlove(
        "h", WebXrSettings(port=glove._receiver.port, cert_dir=str(tmp_path / "cert")), DeviceContext(SessionClock())
    )
    with pytest.raises(DeviceError, match=r"cannot listen on 127.0.0.1:\d+ .*another program"):
        other.connect()
