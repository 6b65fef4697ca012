"""InputWatch: a loop that did not run for longer than the bound (a frozen process) goes back to preview, even
when the samples it finds queued after the freeze are stamped as if nothing had happened."""

from __future__ import annotations

from teleprev.live.core.input_watch import InputWatch

MS = 1_000_000


def test_a_frozen_loop_goes_back_to_preview_though_its_queued_samples_look_continuous():
    watch = InputWatch(bound_ns=1000 * MS, stale_ns=150 * MS)
    watch.engaged(0)
    assert watch.stepped(8 * MS, True, []) is None
    # The first sample after a 2 s freeze was queued just before it: 8 ms after the last usable step.
    event = watch.check(16 * MS, stalled_s=2.0)
    assert event is not None and event.to_preview and "did not run for 2.00 s" in event.detail
    assert watch.stepped(24 * MS, True, []) is None  # back in preview: nothing more until the operator engages


def test_a_short_stall_with_continuous_input_changes_nothing():
    watch = InputWatch(bound_ns=1000 * MS, stale_ns=150 * MS)
    watch.engaged(0)
    assert watch.check(16 * MS, stalled_s=0.5) is None
    assert watch.stepped(24 * MS, True, []) is None and watch.executing
