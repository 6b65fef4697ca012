"""Depth cameras: a RealSense through librealsense's software_device, recorded, exported and faulted.

    python bench/depth.py [--json] [--quick]

A D405 (0.1 mm depth unit) made of the SDK's software_device feeds 640x480 depth and colour at 30 fps; the
realsense.camera plugin reads it through the SDK, and the session's DeviceRunner and Recorder write it to an
MCAP as `teleprev record` does (tests/helpers/depth_session.py).

Figures:
  depth_fps                   frames recorded per second: the camera's 30 fps times the share of the frames it
                              fed during the episode that the session holds (target >= 30)
  depth_fed_fps               frames per second the software camera fed, on its own clock (a loaded machine
                              slows it: it skips frames it is late for, as a camera drops them)
  depth_frames_lost           frames fed during the episode that the session does not have
  depth_sync_ms_max           the largest gap between the session stamps of one frame's depth and colour, less
                              the gap between their hardware stamps (target <= 1)
  depth_stamp_drift_ms_max    how far the session stamps move against the hardware stamps over the recording
                              (ClockSync's offset improving as faster deliveries are seen)
  depth_roundtrip_err_m_max   session -> dataset (teleprev export) -> LeRobotDataset, against the frames the
                              camera was fed (which the session holds exactly: depth_frames_exact), in metres,
                              over pixels within lerobot's range (target <= depth_quant_step_m_at_1m)
  depth_quant_step_m_at_1m    lerobot's 12-bit log quantisation step at 1 m
  depth_session_mb_per_min    the depth stream alone, per storage form, written by the session writer (zstd
                              chunks): "raw" foxglove.RawImage 16UC1, "png" 16-bit PNG
  depth_write_ms_per_frame    CPU per depth frame for each form (encoding and compression)
  depth_faults_run            faults injected into a streaming camera: frames stop, the hardware clock jumps
                              forward and back, the camera is unplugged (and plugged back in)
  depth_faults_silent         faults no device event reported (target 0 over >= 10)
--quick records 2 s at 320x240 (the faults run at 160x120 either way): a smoke run, not the figures.
Per-form figures (depth_session_mb_per_min, depth_write_ms_per_frame: {"raw": .., "png": ..}) are printed
beside these.

JSON keys:
    depth_fps                       float
    depth_fed_fps                   float
    depth_frames_lost               int
    depth_sync_ms_max               float
    depth_stamp_drift_ms_max        float
    depth_frames_exact              int
    depth_frames_recorded           int
    depth_record_cpu_ms_per_frame   float
    depth_frames_dropped            int
    depth_roundtrip_err_m_max       float
    depth_quant_step_m_at_1m        float
    depth_export_frames             int
    depth_export_s                  float
    depth_faults_run                int
    depth_faults_silent             int
"""

from __future__ import annotations

import math
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from bench.common import parser, report  # noqa: E402
from teleprev.devices import DeviceContext, DeviceRunner, SessionClock  # noqa: E402
from teleprev.messages import DepthSample, ImageSample, Logged  # noqa: E402
from teleprev.session.reader import SessionReader  # noqa: E402
from teleprev.session.writer import McapSessionWriter  # noqa: E402
from teleprev_devices.realsense import RealSenseCamera, RealSenseSettings  # noqa: E402
from teleprev_devices.realsense_software import SoftwareRealSense  # noqa: E402
from tests.helpers.depth_session import record_depth_session  # noqa: E402
from tests.helpers.wait import WaitTimeout, wait_until  # noqa: E402

FPS = 30
DEPTH, COLOUR = "/camera/wrist/depth", "/camera/wrist/image"
# lerobot.configs.video's defaults (checked against lerobot when the export runs)
DEPTH_MIN, DEPTH_MAX, SHIFT, QMAX = 0.01, 10.0, 3.5, 4095


def quant_step_m(depth_m: float) -> float:
    return (depth_m + SHIFT) * (math.log(DEPTH_MAX + SHIFT) - math.log(DEPTH_MIN + SHIFT)) / QMAX


def recorded(path: Path) -> tuple[list[DepthSample], list[ImageSample], int, int]:
    """Depth and colour of the session, and its episode's start and stop."""
    with SessionReader(path) as r:
        (episode,) = r.episodes()
        depth = [m.payload for m in r.messages([DEPTH])]
        colour = [m.payload for m in r.messages([COLOUR])]
    return depth, colour, episode.start_ns, episode.stop_ns


def timing_figures(camera: SoftwareRealSense, depth: list[DepthSample], colour: list[ImageSample],
                   start_ns: int, stop_ns: int) -> dict:
    numbers = [SoftwareRealSense.number_of(d.depth) for d in depth]
    exact = all(np.array_equal(d.depth, camera.depth_for(n)) for d, n in zip(depth, numbers))
    hardware_ns = {f.number: round(f.hardware_ms * 1e6) for f in camera.fed}
    colour_stamps = np.array(sorted(c.stamp_ns for c in colour))
    sync = []
    for d in depth:  # the software camera stamps a frame's depth and colour alike: hardware gap 0
        i = int(np.clip(np.searchsorted(colour_stamps, d.stamp_ns), 1, len(colour_stamps) - 1))
        sync.append(min(abs(d.stamp_ns - colour_stamps[i - 1]), abs(d.stamp_ns - colour_stamps[i])))
    offsets = np.array([d.stamp_ns - hardware_ns[n] for d, n in zip(depth, numbers)])
    inside = sorted({n for d, n in zip(depth, numbers) if start_ns <= d.stamp_ns < stop_ns})
    fed_inside = inside[-1] - inside[0] + 1  # the camera numbers every frame it feeds
    span_s = (hardware_ns[inside[-1]] - hardware_ns[inside[0]]) / 1e9
    return {
        "depth_fps": FPS * len(inside) / fed_inside,  # the camera's rate, less the frames not recorded
        "depth_fed_fps": (fed_inside - 1) / span_s,  # what the software camera fed, on its own clock
        "depth_frames_lost": fed_inside - len(inside),
        "depth_sync_ms_max": max(sync) / 1e6,
        "depth_stamp_drift_ms_max": float(offsets.max() - offsets.min()) / 1e6,
        "depth_frames_exact": int(exact),
    }


def storage_figures(depth: list[DepthSample]) -> tuple[dict, dict]:
    """MB per minute and CPU ms per frame of the depth stream alone, in each form."""
    sizes, cpu = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for form in ("raw", "png"):
            path = Path(tmp) / f"{form}.mcap"
            t0 = time.process_time()
            with McapSessionWriter(path, fsync=False) as w:
                for d in depth:
                    w.write(Logged(DEPTH, d.stamp_ns, DepthSample(d.stamp_ns, d.frame_id, d.depth, d.scale_m, form)))
            cpu[form] = (time.process_time() - t0) * 1000 / len(depth)
            sizes[form] = path.stat().st_size / 1e6 / (len(depth) / FPS / 60)
    return sizes, cpu


def roundtrip_figures(path: Path, depth: list[DepthSample], camera: SoftwareRealSense, frames: int) -> dict:
    from lerobot.configs import video as lerobot_video
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from teleprev.export.recipe import recipe_from_table
    from teleprev.export.run import ExportOptions, export

    assert (lerobot_video.DEFAULT_DEPTH_MIN, lerobot_video.DEFAULT_DEPTH_MAX, lerobot_video.DEFAULT_DEPTH_SHIFT,
            lerobot_video.DEPTH_QMAX) == (DEPTH_MIN, DEPTH_MAX, SHIFT, QMAX), "lerobot's depth quantiser changed"
    recipe = recipe_from_table({"feature": [
        {"name": "observation.state", "streams": ["arm_state"]},
        {"name": "action", "streams": ["arm_state"], "timing": "next"},
        {"name": "observation.images.{camera}_depth", "streams": ["depth:*"]}]}, "bench-depth.toml")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "ds"
        t0 = time.perf_counter()
        export(ExportOptions([path], "bench/depth", root, recipe))
        export_s = time.perf_counter() - t0
        ds = LeRobotDataset("bench/depth", root=root, video_backend="pyav", depth_output_unit="m")
        def fed_metres(d: DepthSample) -> np.ndarray:  # what the camera was fed for this recorded frame
            return camera.depth_for(SoftwareRealSense.number_of(d.depth)).astype(np.float32) * np.float32(d.scale_m)

        worst, last = 0.0, 0
        for k in range(min(frames, len(ds))):
            got = ds[k]["observation.images.wrist_depth"].numpy().reshape(depth[0].depth.shape)
            # the fed frame it is: the best match from the last one matched (a frame the exporter held) to 25
            # on (the scene repeats every 30 frames)
            errors = []
            for d in depth[last:last + 26]:
                f = fed_metres(d)
                errors.append(float(np.abs(got - f)[f >= DEPTH_MIN].max()))
            last += int(np.argmin(errors))
            worst = max(worst, min(errors))
    return {"depth_roundtrip_err_m_max": worst, "depth_quant_step_m_at_1m": quant_step_m(1.0),
            "depth_export_frames": len(ds), "depth_export_s": export_s}


def fault_figures(faults: int) -> dict:
    """Faults into a streaming camera, one at a time, each waited out; silent: no event reported it."""
    camera = SoftwareRealSense(serial="000000000405", model="D405", width=160, height=120).start()
    clock = SessionClock()
    events: list[tuple[int, str, str]] = []  # (receive ns, event, message)
    depth_frames = [0]

    def sink(sample, receive_ns):
        if sample.topic == "/events/device":
            events.append((receive_ns, sample.payload.data["event"], sample.payload.data["message"]))
        elif isinstance(sample.payload, DepthSample):
            depth_frames[0] += 1

    device = RealSenseCamera("wrist", RealSenseSettings(serial=camera.serial, width=160, height=120,
                                                        stall_timeout_s=0.3), DeviceContext(clock))
    runner = DeviceRunner(device, sink, clock, reconnect_s=0.2).start()
    kinds = ["stop", "jump_forward", "unplug", "jump_back"]
    silent = 0
    try:
        for i in range(faults):
            n = depth_frames[0]
            wait_until(lambda: depth_frames[0] > n + 5, 15, what="frames before the fault")
            kind = kinds[i % len(kinds)]
            since = clock.now_ns()

            def reported(event: str, text: str) -> bool:
                return any(t >= since and e == event and text in m for t, e, m in events)

            if kind == "stop":
                camera.pause()
                seen = _wait(lambda: reported("error", "no frames for"))
                camera.resume()
            elif kind == "unplug":
                camera.unplug()
                seen = _wait(lambda: reported("error", "no RealSense camera with serial"))
                camera.replug()
            else:
                camera.jump_clock_ms(4000.0 if kind == "jump_forward" else -4000.0)
                seen = _wait(lambda: reported("skipped", "timestamp jumps"))
            silent += not seen
    finally:
        runner.stop()
        camera.stop()
    return {"depth_faults_run": faults, "depth_faults_silent": silent}


def _wait(condition, timeout_s: float = 5.0) -> bool:
    try:
        wait_until(condition, timeout_s)
        return True
    except WaitTimeout:
        return False


def main() -> None:
    args = parser(__doc__.splitlines()[0]).parse_args()
    seconds, (width, height) = (2.0, (320, 240)) if args.quick else (6.0, (640, 480))
    figures: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        camera = SoftwareRealSense(serial="000000000405", model="D405", width=width, height=height, fps=FPS)
        cpu0 = time.process_time()
        rec = record_depth_session(Path(tmp) / "session.mcap", camera, seconds, align_depth=False)
        cpu_s = time.process_time() - cpu0
        depth, colour, start_ns, stop_ns = recorded(rec.path)
        figures.update(timing_figures(camera, depth, colour, start_ns, stop_ns))
        figures["depth_frames_recorded"] = len(depth)
        # the whole process per frame: the feeding camera, the plugin, the recorder, the arm stream
        figures["depth_record_cpu_ms_per_frame"] = cpu_s * 1000 / len(depth)
        figures["depth_frames_dropped"] = rec.summary.streams[DEPTH].dropped  # queue full, or shed (writer behind)
        sizes, cpu = storage_figures(depth)
        figures["depth_session_mb_per_min"] = {k: round(v, 1) for k, v in sizes.items()}
        figures["depth_write_ms_per_frame"] = {k: round(v, 2) for k, v in cpu.items()}
        figures.update(roundtrip_figures(rec.path, depth, camera, 30 if args.quick else 150))
    figures.update(fault_figures(10 if args.quick else 12))
    targets = {"depth_fps": ">= 30", "depth_sync_ms_max": "<= 1", "depth_frames_exact": "1",
               "depth_roundtrip_err_m_max": f"<= {quant_step_m(1.0):.4f} (the step at 1 m)",
               "depth_faults_silent": "0 (over >= 10)"}
    report(f"depth cameras (a {width}x{height} RealSense through software_device)", figures, targets, args.json)


if __name__ == "__main__":
    main()
