"""The export's frame timeline: camera-locked frame times, no future samples for observations, the
command right after each frame for actions, held camera frames, gaps trimmed at the ends and split
inside. Pure numpy on stamps: every expectation below is worked out by hand from the stamps."""

import numpy as np
import pytest

from teleprev.export.timeline import act, frame_grid, observe, plan_episode

MS = 1_000_000
FPS = 30
P = 1_000_000_000 / FPS  # ns


def camera(n, start=0, jitter_ms=0.0, drift_ppm=0.0, seed=0):
    rng = np.random.default_rng(seed)
    return (start + np.arange(n) * P * (1 + drift_ppm * 1e-6) + rng.normal(0, jitter_ms * MS, n)).astype(np.int64)


def test_frames_follow_the_camera_and_stay_on_an_even_grid():
    cam = camera(300, start=5_000 * MS, jitter_ms=1.0, drift_ppm=-40.0)
    f = frame_grid(cam, 5_000 * MS - 1, 20_000 * MS, FPS, 100 * MS)
    assert len(f.time_ns) == 300 and f.fresh.all() and f.camera.ok.all()
    assert np.array_equal(f.time_ns, cam)  # a frame's time is its camera frame's time
    assert np.array_equal(f.camera.index, np.arange(300))
    assert np.all(np.abs(f.time_ns - f.grid_ns) <= P / 2)  # and within half a period of k / fps
    assert np.all(np.diff(f.grid_ns) - P <= 1) and np.all(np.diff(f.grid_ns) - P >= -1)


def test_a_dropped_camera_frame_is_held_and_a_long_gap_is_not():
    cam = np.delete(camera(100), [10] + list(range(50, 60)))
    f = frame_grid(cam, 0, 10**10, FPS, 100 * MS)
    assert len(f.time_ns) == 100
    assert not f.fresh[10] and f.camera.ok[10]  # one frame missing: the previous image, at the grid time
    assert f.camera.index[10] == 9 and f.time_ns[10] == f.grid_ns[10]
    assert f.camera.err_ns[10] == f.grid_ns[10] - cam[9]
    held = np.flatnonzero(~f.fresh[45:65]) + 45
    assert list(held) == list(range(50, 60))
    # holds up to 100 ms are fine (frames 50..52 are 33, 67, 100 ms old), older ones are a gap
    assert list(np.flatnonzero(~f.camera.ok)) == list(range(53, 60))


def test_observations_never_come_from_the_future():
    stamps = np.array([0, 10, 20, 30, 40]) * MS
    times = np.array([-1, 0, 5, 19, 20, 21, 200]) * MS
    look = observe(stamps, times, max_gap_ns=100 * MS)
    assert list(look.index) == [-1, 0, 0, 1, 2, 2, 4]
    assert list(look.err_ns // MS) == [0, 0, 5, 9, 0, 1, 160]
    assert list(look.ok) == [False, True, True, True, True, True, False]  # none yet; 160 ms old
    assert np.all(stamps[look.index[look.ok]] <= times[look.ok])


def test_actions_are_the_command_sent_right_after_the_frame():
    cmd = np.array([3, 11, 19, 27, 35, 43, 51, 59, 150]) * MS
    times = np.array([0, 33, 66, 100]) * MS
    look = act(cmd, times, FPS, max_gap_ns=100 * MS)
    # first command at or after each frame time and before the next frame's time
    assert list(look.index) == [0, 4, 7, 7]
    assert list(look.err_ns // MS) == [3, 2, 7, 41]
    # frame at 100 ms: no command in [100, 133) -> the last one (59 ms) holds, 41 ms old
    assert list(look.ok) == [True, True, True, True]
    late = act(cmd, np.array([300 * MS]), FPS, max_gap_ns=100 * MS)
    assert not late.ok[0]  # the last command is 150 ms old


def test_plan_trims_the_ends_splits_at_gaps_and_names_the_streams():
    cam = camera(150)  # 5 s
    arm = np.arange(0, 5_000, 10) * MS
    cmd = np.arange(1_000, 5_000, 8) * MS  # execute mode from 1 s on
    cmd = cmd[(cmd < 2_500 * MS) | (cmd >= 3_000 * MS)]  # back to preview for half a second
    plan = plan_episode(
        "cam", cam, {"arm": (arm, False), "cmd": (cmd, True)}, 0, 5_000 * MS, FPS, 100 * MS, min_frames=15
    )
    assert len(plan.gaps) == 2
    lead, inner = plan.gaps
    assert lead.at_edge and lead.streams == ("cmd",) and lead.first == 0
    assert cam[lead.stop - 1] < 1_000 * MS <= cam[lead.stop]  # trimmed up to the first command
    assert not inner.at_edge and inner.streams == ("cmd",)
    # frames up to 100 ms after the last command before the pause keep it (the robot holds its target)
    assert cam[inner.first] > 2_492 * MS + 100 * MS >= cam[inner.first - 1]
    assert cam[inner.stop] >= 3_000 * MS > cam[inner.stop - 1]
    assert plan.pieces == [(lead.stop, inner.first), (inner.stop, 150)]


def test_short_pieces_are_left_out():
    cam = np.delete(camera(100), list(range(20, 30)) + list(range(35, 45)))
    plan = plan_episode("cam", cam, {}, 0, 10**10, FPS, 50 * MS, min_frames=10)
    # 20..29 and 35..44 missing: frames 20 and 35 hold the previous image (33 ms old), 21 and 36 would
    # be 67 ms old; 30..35 is a piece of 6 frames
    assert plan.pieces == [(0, 21), (45, 100)]
    assert plan.short == [(30, 36)]


def test_without_a_camera_frames_run_on_a_fixed_clock():
    arm = np.arange(0, 2_000, 10) * MS
    plan = plan_episode(None, None, {"arm": (arm, False)}, 0, 2_000 * MS, FPS, 100 * MS, min_frames=1)
    assert len(plan.frames.time_ns) == 60
    assert np.array_equal(plan.frames.time_ns, (np.arange(60) * 1_000_000_000) // FPS)
    assert plan.pieces == [(0, 60)]
    assert plan.lookups["arm"].err_ns.max() <= 10 * MS


@pytest.mark.parametrize("fps", [15, 10])
def test_a_lower_dataset_rate_takes_every_n_th_camera_frame(fps):
    cam = camera(90, jitter_ms=0.5)
    f = frame_grid(cam, 0, 10**10, fps, 100 * MS)
    step = 30 // fps
    assert f.fresh.all()
    # grid points run to half a dataset period past the last camera frame (89): the last one takes it
    assert np.array_equal(f.camera.index, np.minimum(np.arange(len(f.time_ns)) * step, 89))
    assert np.all(np.abs(f.time_ns - f.grid_ns) * 2 * fps <= 1_000_000_000)


def test_actions_sample_the_commanded_trajectory_between_the_commands():
    """A jerk-limited arm profile is piecewise cubic: between two commands that carry their positions and
    velocities, the cubic Hermite sampled at the frames is the profile itself; the hand's commands are
    straight segments; a switch steps."""
    from types import SimpleNamespace

    from teleprev.export.session import _sampled
    from teleprev.export.timeline import trajectory

    stamps = np.arange(0, 400_000_000, 8_333_333, dtype=np.int64)
    t = stamps / 1e9
    q = (2.0 + 0.5 * t - 3.0 * t**2 + 4.0 * t**3)[:, None]
    v = (0.5 - 6.0 * t + 12.0 * t**2)[:, None]
    frames = np.arange(0, 350_000_000, 33_333_333, dtype=np.int64) + 1_234_567
    look = trajectory(stamps, frames, max_gap_ns=100_000_000)
    assert look.ok.all() and (look.next >= 0).all()
    stream = SimpleNamespace(stamps=stamps, values=q, velocities=v)
    g = frames / 1e9
    exact = 2.0 + 0.5 * g - 3.0 * g**2 + 4.0 * g**3
    np.testing.assert_allclose(_sampled(stream, look, np.arange(len(frames)), "hermite")[:, 0], exact, atol=1e-12)
    straight = _sampled(stream, look, np.arange(len(frames)), "linear")[:, 0]
    assert np.abs(straight - exact).max() > 1e-6  # (a chord, not the curve)
    held = _sampled(stream, look, np.arange(len(frames)), "hold")[:, 0]
    np.testing.assert_array_equal(held, q[look.index, 0])
    # a command older than max_gap holds no frame; a gap between commands holds the last one while fresh
    late = trajectory(stamps, np.array([stamps[-1] + 50_000_000, stamps[-1] + 150_000_000]), max_gap_ns=100_000_000)
    assert late.ok.tolist() == [True, False] and (late.next == -1).all()
