"""webxr.glove and webxr.suit: an XR headset's hand tracking (Quest 3, Pico 4, Vision Pro: any browser with
WebXR hand input) through a page teleprev serves. One page feeds both plugins, as one VMC sender feeds
vmc.glove and vmc.suit:

    [devices.glove]              [devices.suit]
    plugin = "webxr.glove"       plugin = "webxr.suit"
    port = 8443                  port = 8443

The glove publishes the right hand as the SMPL-X hand pose (/glove/<name>/hand) and each tracked hand's
raw WebXR joints (/glove/<name>/xr_left and xr_right: position, orientation and radius of its 25 joints,
in the XR reference space); the suit publishes the right wrist in the suit frame (/suit/<name>/wrist) and the
headset (/suit/<name>/head). A hand out of view sends nothing: the pipeline sees stale input and the
commands brake and hold, as for a glove that goes quiet. See hands.py for the frames, server.py for the
page's connection.

`side = "left"` makes either plugin read the left hand instead (its own SMPL-X pose; its wrist as a mirrored
right wrist, hands.py): a bimanual rig has a glove and a suit per side on one page and port, the left hand
driving the left side.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from teleprev.devices import JointSample, PoseSample, Sample, StreamSpec, smplx
from teleprev_devices.fanout import FanoutDevice, ListenSettings
from teleprev_devices.webxr import certificate, hands
from teleprev_devices.webxr.server import Frame, XrServer, acquire, release

DEFAULT_PORT = 8443


@dataclass
class WebXrSettings(ListenSettings):
    # host 127.0.0.1: this machine (a Quest on USB through `adb reverse`); "0.0.0.0": the network, with a pairing token
    port: int = DEFAULT_PORT
    rate_hz: float = 72.0  # the headset's frame rate (Quest 3: 72, 90 or 120)
    cert_dir: str = ""  # where the certificate and pairing token are kept; "": ~/.local/share/teleprev/webxr
    side: str = "right"  # whose hand and wrist: "right", or "left" (a bimanual rig's left side)

    def __post_init__(self):
        super().__post_init__()
        if self.side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {self.side!r}")

    def cert_folder(self, rig_dir: Path) -> Path:
        return rig_dir / self.cert_dir if self.cert_dir else certificate.default_dir()


V = TypeVar("V", bound=WebXrSettings)


class _WebXrDevice(FanoutDevice[V]):
    def open_receiver(self) -> XrServer:
        s = self.settings
        return acquire(self.context.receivers, s.host, s.port, self.context.clock, s.cert_folder(self.context.rig_dir),
                       self.context.operator)

    def close_receiver(self, server: XrServer) -> None:
        release(self.context.receivers, server, self.settings.port)

    def endpoint(self) -> str:
        port = self._receiver.port if self._receiver is not None else self.settings.port
        return f"HTTPS {self.settings.host}:{port}"

    def operator_urls(self) -> list[str]:
        server = self._receiver
        return server.urls() if server is not None else []

    def silence(self, seconds: float) -> str:
        return f"no XR frames for {seconds:g} s (is the page open in the headset, in an XR session?)"


class WebXrGlove(_WebXrDevice[WebXrSettings], kind="glove"):
    """The right (or `side`'s) hand as the SMPL-X hand pose on /glove/<name>/hand; each tracked hand's raw
    joints on /glove/<name>/xr_left and xr_right (hands.RAW_NAMES)."""

    def streams(self) -> list[StreamSpec]:
        rate = self.settings.rate_hz
        return [StreamSpec(self.topic("hand"), "joints", rate),
                *(StreamSpec(self.topic(f"xr_{side}"), "joints", rate) for side in hands.HANDS)]

    def convert(self, frame: Frame) -> list[Sample]:
        xr = frame.xr
        out = []
        side = self.settings.side
        mine = xr.hand(side)
        if mine is not None:
            pose = hands.side_hand_pose(mine, side)
            out.append(Sample(self.topic("hand"), JointSample(frame.stamp_ns, smplx.HAND_POSE_NAMES, pose)))
        for side in hands.HANDS:
            joints = xr.hand(side)
            if joints is not None:
                out.append(
                    Sample(self.topic(f"xr_{side}"), JointSample(frame.stamp_ns, hands.RAW_NAMES, joints.reshape(-1)))
                )
        return out


class WebXrSuit(_WebXrDevice[WebXrSettings], kind="suit"):
    """The right (or `side`'s) wrist (PoseSample, frame "suit") on /suit/<name>/wrist and the headset on
    /suit/<name>/head."""

    def streams(self) -> list[StreamSpec]:
        rate = self.settings.rate_hz
        return [StreamSpec(self.topic("wrist"), "pose", rate), StreamSpec(self.topic("head"), "pose", rate)]

    def convert(self, frame: Frame) -> list[Sample]:
        xr = frame.xr
        out = []
        mine = xr.hand(self.settings.side)
        if mine is not None:
            position, quat = hands.side_wrist_in_suit(mine, self.settings.side)
            out.append(Sample(self.topic("wrist"), PoseSample(frame.stamp_ns, "suit", position, quat)))
        if xr.head is not None:
            position, quat = hands.head_in_suit(xr.head)
            out.append(Sample(self.topic("head"), PoseSample(frame.stamp_ns, "suit", position, quat)))
        return out
