"""A real Chromium (Debian's package), driven by playwright, as a Meta Quest 3 (Meta's IWER, from npm) with
hand tracking, opening teleprev's XR page: for tests/webxr/test_browser.py and bench/webxr.py.

    with Quest3Browser(url) as quest:
        quest.enter("immersive-ar")          # the page's own button
        quest.play(frames)                   # recorded hand motion, one entry per XR frame
        quest.sent()                         # what the page sent, frame by frame

scripts/test.sh installs both (apt-get install chromium; npm ci in tests/webxr/browser). Missing, they are
an error here, never a skip.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from teleprev.session.reader import SessionReader
from teleprev.transforms import quat_from_axis_angle
from tests.helpers.xr_hands import RADIUS_M, from_glove_and_suit, matrices

BROWSER_DIR = Path(__file__).resolve().parents[1] / "webxr" / "browser"
IWER_BUILD = BROWSER_DIR / "node_modules" / "iwer" / "build" / "iwer.min.js"
QUEST3 = BROWSER_DIR / "quest3.js"
# WebGL on the CPU (SwiftShader), as a machine without a GPU has it.
ARGS = ["--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"]
FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "sim_v3.mcap"


def chromium_path() -> str:
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    if path is None:
        raise RuntimeError("Chromium is missing: `apt-get install chromium` (scripts/test.sh installs it)")
    if not IWER_BUILD.exists():
        raise RuntimeError(f"IWER is missing: `npm ci --prefix {BROWSER_DIR}` (scripts/test.sh installs it)")
    return path


@dataclass
class SentFrames:
    seq: np.ndarray  # (n,) the page's sequence numbers
    present: np.ndarray  # (n,) wire bits: 1 headset, 2 left, 4 right
    sent_ms: np.ndarray  # (n,) the page's clock (epoch ms) as it sent each
    values: np.ndarray  # (n, 407) float32: head (7), left (200), right (200), as on the wire


class Quest3Browser:
    def __init__(self, url: str):
        from playwright.sync_api import sync_playwright

        executable = chromium_path()
        self._pw = sync_playwright().start()
        try:
            self.browser = self._pw.chromium.launch(executable_path=executable, headless=True, args=ARGS)
            self.context = self.browser.new_context(ignore_https_errors=True)  # the operator accepts it once
            self.page = self.context.new_page()
            self.page.add_init_script(path=str(IWER_BUILD))
            self.page.add_init_script(path=str(QUEST3))
            self.errors: list[str] = []
            self.page.on("pageerror", lambda e: self.errors.append(str(e)))
            self.page.goto(url + ("&" if "?" in url else "?") + "log=1")  # the page keeps what it sent (sent())
        except BaseException:
            self.close()
            raise

    @property
    def version(self) -> str:
        return self.browser.version

    def __enter__(self) -> Quest3Browser:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        try:
            if getattr(self, "browser", None) is not None:
                self.browser.close()
        finally:
            self._pw.stop()

    def enter(self, mode: str = "immersive-ar", timeout_s: float = 20.0) -> None:
        """Press the page's button for `mode` and wait until XR frames reach teleprev."""
        self.page.click("#enter-ar" if mode == "immersive-ar" else "#enter-vr")
        self.page.wait_for_function("window.teleprev.state.session && window.teleprev.state.connected "
                                    "&& window.teleprev.state.sent > 0", timeout=timeout_s * 1000)

    def play(self, entries: list[dict], chunk: int = 100) -> None:
        for k in range(0, len(entries), chunk):
            self.page.evaluate("e => window.xrPlayback.queue.push(...e)", entries[k:k + chunk])

    def wait_played(self, timeout_s: float = 60.0) -> None:
        self.page.wait_for_function("window.xrPlayback.queue.length === 0", timeout=timeout_s * 1000, polling=100)

    def now(self, entry: dict) -> None:
        """Apply an entry at once (between frames), e.g. {"left": {"pinch": 1}}."""
        self.page.evaluate("e => window.xrPlayback.apply(e)", entry)

    def state(self) -> dict:
        return self.page.evaluate("({seq: window.teleprev.state.seq, sent: window.teleprev.state.sent, "
                                  "status: window.teleprev.state.status, actions: window.teleprev.actions})")

    def sent(self) -> SentFrames:
        raw = self.page.evaluate(
            "({values: window.teleprev.log.map(v => Array.from(v)), heads: window.teleprev.heads})"
        )
        heads = raw["heads"]
        return SentFrames(np.array([h["seq"] for h in heads]), np.array([h["present"] for h in heads]),
                          np.array([h["sent_ms"] for h in heads]), np.array(raw["values"], dtype=np.float32))


def recorded_motion(frames: int, rate_hz: float = 60.0) -> list[dict]:
    """`frames` entries of a recorded operator's right hand and wrist (and, as "source", the glove's hand
    pose each was made from) (the sim fixture's glove and suit,
    played forwards then backwards as often as needed) with the head turning slowly: IWER's playback."""
    reader = SessionReader(FIXTURE)
    try:
        glove = [(m.payload.stamp_ns, m.payload.positions) for m in reader.messages(["/glove/glove/hand"])]
        suit = [
            (m.payload.stamp_ns, m.payload.position, m.payload.orientation)
            for m in reader.messages(["/suit/suit/wrist"])
        ]
    finally:
        reader.close()
    g_t = np.array([t for t, _ in glove])
    s_t = np.array([t for t, *_ in suit])
    t0, t1 = max(g_t[0], s_t[0]), min(g_t[-1], s_t[-1])
    span = (t1 - t0) / 1e9
    entries = []
    for k in range(frames):
        u = (k / rate_hz) % (2 * span)
        t = t0 + int(1e9 * (u if u < span else 2 * span - u))
        hand = glove[min(np.searchsorted(g_t, t), len(glove) - 1)][1]
        _, position, quat = suit[min(np.searchsorted(s_t, t), len(suit) - 1)]
        joints = from_glove_and_suit(hand, position, quat, lift=(0.0, 0.8, 0.0))
        yaw = 0.2 * np.sin(0.5 * k / rate_hz)
        head = [0.0, 1.6, 0.0, *quat_from_axis_angle(np.array([0.0, yaw, 0.0])).tolist()]
        entries.append({"head": head, "right": {"joints": matrices(joints).tolist(), "radii": [RADIUS_M] * 25},
                        "source": np.asarray(hand, dtype=float).tolist()})  # (IWER ignores what it does not know)
    return entries
