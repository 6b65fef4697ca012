"""XR hand tracking through a real browser (issue 27): Debian's Chromium, driven by playwright, is a Meta
Quest 3 with hand tracking (Meta's IWER) that plays a recorded operator's right hand (the sim fixture's
glove and suit) into teleprev's XR page, while `teleprev record` (a process of its own) records an engaged
session on the simulated robot (rigs/webxr_sim.toml). The left hand's pinch engages the robot, as an operator's would.

    python bench/webxr.py --json             # about 45 s: 1100 XR frames (the headless browser runs at 60 Hz)
    python bench/webxr.py --quick            # 120 frames

Figures: real_browser (Chromium launched, the page in an immersive-ar session under IWER), xr_frames (frames
the page sent), joint_err_mm_max (the recorded xr_left/xr_right joints against what the page sent, every
joint of every frame), wrist_err_mm_max (the recorded wrist, back in the XR space, against the page's),
frame_loss_frac (frames the page numbered that the file does not hold), browser_to_step_ms_p50 (from the
page sending a frame to the pipeline step on it being done, both clocks this machine's), commands_sent
(arm commands recorded while executing).

JSON keys:
    real_browser            bool
    xr_frames               int
    joint_err_mm_max        float
    wrist_err_mm_max        float
    frame_loss_frac         float
    browser_to_step_ms_p50  float
    commands_sent           int
    recorded_frames         int
    frames_numbered         int
    browser_to_step_ms_p99  float
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from bench.common import parser, percentile, report  # noqa: E402
from teleprev import topics  # noqa: E402
from teleprev.session.reader import SessionReader  # noqa: E402
from teleprev_devices.webxr import hands  # noqa: E402
from tests.helpers.ports import free_tcp_port  # noqa: E402
from tests.helpers.xr_browser import Quest3Browser, recorded_motion  # noqa: E402
from tests.helpers.xr_page import webxr_rig  # noqa: E402


def main() -> None:
    args = parser(__doc__.split("\n\n")[0]).parse_args()
    frames = 120 if args.quick else 1100
    motion = recorded_motion(frames)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        port = free_tcp_port()
        session = tmp / "s.mcap"
        # teleprev in a process of its own, as an operator runs it; the browser is another program.
        record = subprocess.Popen(
            [str(Path(sys.executable).with_name("teleprev")), "record", str(webxr_rig(tmp, port=port)), "--out",
             str(session), "--duration", f"{frames / 60 + 12:.0f}", "--no-preview", "--connect-timeout", "60"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            url = _page_url(record)
            with Quest3Browser(url) as quest:
                version = quest.version
                quest.play(motion)  # queued in the page before XR starts: played one entry per XR frame
                quest.enter("immersive-ar")
                time.sleep(0.5)
                quest.now({"left": {"pinch": 1.0}})  # thumb to index: execute
                time.sleep(0.3)
                quest.now({"left": {"pinch": 0.0}})
                quest.wait_played(timeout_s=frames / 20)
                quest.now({"left": {"pinch": 1.0}})  # and back to preview
                time.sleep(0.3)
                quest.page.evaluate("window.teleprev.state.session.end()")
                time.sleep(0.5)
                sent = quest.sent()
                numbered = quest.state()["seq"]
                errors = list(quest.errors)
            out, _ = record.communicate(timeout=frames / 60 + 60)
        finally:
            if record.poll() is None:
                record.kill()
        if record.returncode != 0:
            print(out, file=sys.stderr)
        figures = measure(session, sent, numbered)
    figures = {"real_browser": bool(version) and figures["xr_frames"] > 0 and not errors, **figures}
    print(f"Chromium {version}; page errors: {errors or 'none'}; teleprev record exited {record.returncode}")
    report("XR hand tracking through a real browser", figures, {
        "real_browser": "true", "xr_frames": ">= 1000", "joint_err_mm_max": "<= 1.0", "wrist_err_mm_max": "<= 1.0",
        "frame_loss_frac": "<= 0.01", "browser_to_step_ms_p50": "<= 20", "commands_sent": ">= 500"}, as_json=args.json)


def _page_url(record: subprocess.Popen) -> str:
    """The page's URL, as `teleprev record` prints it."""
    for line in record.stdout:
        if line.startswith("XR page: open "):
            return line.split()[3]
    raise RuntimeError("teleprev record ended without serving the XR page")


def measure(path: Path, sent, numbered: int) -> dict:
    with SessionReader(path) as reader:
        right = np.array([m.payload.positions for m in reader.messages(["/glove/glove/xr_right"])]).reshape(-1, 25, 8)
        left = np.array([m.payload.positions for m in reader.messages(["/glove/glove/xr_left"])]).reshape(-1, 25, 8)
        wrists = np.array([m.payload.position for m in reader.messages(["/suit/suit/wrist"])])
        heads = reader.topics["/suit/suit/head"].message_count
        steps = {m.payload.stamp_ns: m.log_time_ns for m in reader.messages([topics.STEP_REPORT])}
        gloves = [m.log_time_ns for m in reader.messages(["/glove/glove/hand"])]
        modes = [(m.log_time_ns, m.payload.data["mode"]) for m in reader.messages([topics.MODE])]
        commands = reader.log_times(topics.COMMAND_ARM)
    page_right = sent.values[:, 207:].astype(float).reshape(-1, 25, 8)
    page_left = sent.values[:, 7:207].astype(float).reshape(-1, 25, 8)
    n = min(len(right), len(page_right))
    joint_err = max(np.abs(right[:n, :, :3] - page_right[:n, :, :3]).max(initial=0.0),
                    np.abs(left[:n, :, :3] - page_left[:n, :, :3]).max(initial=0.0)) if n else float("nan")
    wrist_err = (
        np.linalg.norm(wrists[:n] @ hands.A - page_right[:n, 0, :3], axis=1).max(initial=0.0) if n else float("nan")
    )
    lag = [(steps[g] - sent.sent_ms[k] * 1e6) / 1e6 for k, g in enumerate(gloves[:len(sent.sent_ms)]) if g in steps]
    executing = 0
    for (t0, mode), (t1, _) in zip(modes, modes[1:] + [(np.iinfo(np.int64).max, "")]):
        if mode == "execute":
            executing += int(np.count_nonzero((commands >= t0) & (commands < t1)))
    return {
        "xr_frames": len(sent.seq),
        "joint_err_mm_max": 1000.0 * joint_err,
        "wrist_err_mm_max": 1000.0 * wrist_err,
        "frame_loss_frac": (numbered - heads) / numbered if numbered else float("nan"),
        "browser_to_step_ms_p50": percentile(lag, 50) if lag else float("nan"),
        "commands_sent": executing,
        "recorded_frames": heads,
        "frames_numbered": numbered,
        "browser_to_step_ms_p99": percentile(lag, 99) if lag else float("nan"),
    }


if __name__ == "__main__":
    main()
