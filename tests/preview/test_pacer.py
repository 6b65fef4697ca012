"""The preview gives up frame rate before the session loop falls behind: at most half the time
drawing, and slower while the loop has a backlog, back to full rate once it has caught up."""

from teleprev.live.record.run import PreviewPacer


def test_the_preview_slows_down_while_the_loop_is_behind_and_recovers():
    backlog = [0]
    pacer = PreviewPacer(25.0, lambda: backlog[0])
    assert abs(pacer.wait_after(0.002) - 0.038) < 1e-9  # 25 fps
    assert abs(pacer.wait_after(0.030) - 0.030) < 1e-9  # a slow frame: half the time drawing at most
    backlog[0] = 500
    waits = [pacer.wait_after(0.002) + 0.002 for _ in range(8)]
    assert waits == sorted(waits) and waits[-1] == PreviewPacer.MAX_INTERVAL_S  # doubling, up to once a second
    backlog[0] = 0
    for _ in range(8):
        wait = pacer.wait_after(0.002)
    assert abs(wait - 0.038) < 1e-9
