import threading
import time

import pytest

from tests.helpers.wait import WaitTimeout, wait_until


def test_returns_the_first_truthy_value():
    box = []
    threading.Timer(0.05, lambda: box.append(7)).start()
    assert wait_until(lambda: box and box[0], timeout_s=5) == 7


def test_times_out_naming_what_it_waited_for():
    started = time.monotonic()
    with pytest.raises(WaitTimeout, match="the door; last value 0"):
        wait_until(lambda: 0, timeout_s=0.1, what="the door")
    assert time.monotonic() - started < 2
