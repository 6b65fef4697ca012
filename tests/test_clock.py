"""ClockSync: a device clock mapped onto the session clock, robust to one bad stamp, following real jumps."""

import numpy as np

from teleprev.clock import ClockSync

MS = 1_000_000
OFFSET = 3_000_000_000_000  # device clock = session clock - OFFSET


def stream(n, rate_hz=120.0, seed=0, start=10**18):
    """(true session time, device stamp, receive time) of a jittered stream: 2 ms latency + up to 3 ms jitter."""
    rng = np.random.default_rng(seed)
    t = start + (np.arange(n) * 1e9 / rate_hz).astype(np.int64)
    receive = t + 2 * MS + rng.integers(0, 3 * MS, n)
    return t, t - OFFSET, receive


def test_one_stamp_from_the_future_is_rejected_and_lock_is_kept():
    t, dev, rx = stream(600)
    sync = ClockSync(latency_ns=2 * MS)
    errors = []
    for i in range(len(t)):
        stamp = dev[i] + (5_000 * MS if i == 300 else 0)  # one stamp 5 s ahead
        mapped = sync.observe(int(stamp), int(rx[i]))
        if i != 300 and i > 10:
            errors.append(abs(mapped - t[i]))
    assert max(errors) < 1 * MS
    assert sync.rejected == 1 and sync.relocks == 0
    assert sync.last_rejected_ns == rx[300]


def test_a_real_clock_jump_relocks_within_a_bounded_number_of_samples():
    t, dev, rx = stream(600)
    sync = ClockSync(latency_ns=2 * MS, relock_after=8)
    jump = 7_000 * MS  # the device clock is reset 7 s ahead from sample 300 on
    late = []
    for i in range(len(t)):
        stamp = dev[i] + (jump if i >= 300 else 0)
        mapped = sync.observe(int(stamp), int(rx[i]))
        if i >= 300 and abs(mapped - t[i]) > 1 * MS:
            late.append(i)
    assert sync.relocks == 1
    assert late and max(late) < 300 + 8  # wrong only until the run of agreeing stamps relocks it


def test_a_device_clock_that_goes_back_relocks_too():
    t, dev, rx = stream(600)
    sync = ClockSync(latency_ns=2 * MS)
    for i in range(len(t)):
        stamp = dev[i] - (4_000 * MS if i >= 200 else 0)
        mapped = sync.observe(int(stamp), int(rx[i]))
    assert sync.relocks == 1 and sync.rejected == 0
    assert abs(mapped - t[-1]) < 1 * MS


def test_late_deliveries_are_not_outliers():
    t, dev, rx = stream(400)
    sync = ClockSync(latency_ns=2 * MS)
    for i in range(len(t)):
        delay = 150 * MS if i % 50 == 0 else 0  # a host stall delays some packets
        mapped = sync.observe(int(dev[i]), int(rx[i] + delay))
        if i > 10:
            assert abs(mapped - t[i]) < 1 * MS
    assert sync.rejected == 0 and sync.relocks == 0
