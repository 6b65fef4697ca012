"""A stand-in for the XR page in tests of the server's edges (tokens, garbage, takeovers): a real WebSocket
over real TLS on loopback, sending what page/xr.js sends (wire.pack). The page itself is tested in a real
browser (tests/webxr/test_browser.py). And the rig that serves the page, for those tests and bench/webxr.py."""

from __future__ import annotations

import json
import ssl
import time

import numpy as np
from websockets.sync.client import connect

from teleprev.paths import data_dir
from teleprev_devices.webxr import wire


def insecure() -> ssl.SSLContext:
    """TLS that accepts teleprev's self-signed certificate, as a browser does once the operator accepts it."""
    context = ssl.create_default_context()
    context.check_hostname = False
    context.verify_mode = ssl.CERT_NONE
    return context


def open_hand() -> np.ndarray:
    """(25, 8) joints of a right hand at rest: every joint's frame the identity, 8 mm radius."""
    joints = np.zeros((25, 8))
    joints[:, 6] = 1.0
    joints[:, 7] = 0.008
    joints[:, 2] = -0.4 - 0.01 * np.arange(25)
    return joints


class PageClient:
    def __init__(self, port: int, token: str = ""):
        query = f"?token={token}" if token else ""
        self._connecting = connect(f"wss://127.0.0.1:{port}/ws{query}", ssl=insecure(), open_timeout=5)
        self.ws = self._connecting.__enter__()
        self.seq = 0

    def frame(self, right=None, left=None, head=(0.0, 1.6, 0.0, 0.0, 0.0, 0.0, 1.0), seq=None) -> None:
        now_ms = time.time() * 1000.0
        self.ws.send(wire.pack(self.seq if seq is None else seq, now_ms, now_ms, head=head, left=left, right=right))
        self.seq = (self.seq if seq is None else seq) + 1

    def action(self, action: str, via: str = "") -> dict:
        """Send an action as the page does (`via`: "gesture" for a pinch) and return the server's answer."""
        self.ws.send(json.dumps({"type": "action", "action": action, "via": via}))
        while True:
            message = json.loads(self.ws.recv(timeout=5))
            if message["type"] == "ack":
                return message

    def close(self) -> None:
        self._connecting.__exit__(None, None, None)


def webxr_rig(tmp_path, port: int = 0, input_loss_to_preview_s: float | None = None):
    """The shipped webxr_sim rig on `port` (0: any free one), its certificate kept in tmp_path; with
    `input_loss_to_preview_s`, that [session] bound instead of the default."""
    text = (data_dir("rigs") / "webxr_sim.toml").read_text().replace("port = 8443", f"port = {port}")
    if input_loss_to_preview_s is not None:
        text += f"\n[session]\ninput_loss_to_preview_s = {input_loss_to_preview_s}\n"
    text = text.replace('rate_hz = 72.0', f'rate_hz = 72.0\ncert_dir = "{tmp_path / "cert"}"')
    path = tmp_path / "webxr.toml"
    path.write_text(text)
    return path


def bimanual_webxr_rig(tmp_path):
    """A bimanual rig driven by the XR page: a webxr.glove and a webxr.suit per side (the left pair with
    side = "left") on one page, any free port, its certificate kept in tmp_path; sim arms and hands."""
    cert = tmp_path / "cert"
    sides = "".join(
        f'[sides.{side}]\narm = "arm_{side}"\nhand = "hand_{side}"\nglove = "glove_{side}"\nsuit = "suit_{side}"\n'
        f'mount_xyz = [0.0, {0.3 if side == "left" else -0.3}, 0.0]\n\n'
        + "".join(f'[devices.{kind}_{side}]\nplugin = "webxr.{kind}"\nport = 0\nside = "{side}"\n'
                  f'cert_dir = "{cert}"\n\n' for kind in ("glove", "suit"))
        + f'[devices.arm_{side}]\nplugin = "sim.arm"\n\n[devices.hand_{side}]\nplugin = "sim.hand"\n\n'
        for side in ("left", "right"))
    path = tmp_path / "bimanual_webxr.toml"
    path.write_text(f'[rig]\nname = "xr_bimanual"\n\n[pipeline]\ntcp_link = "palm_lower"\n\n{sides}')
    return path
