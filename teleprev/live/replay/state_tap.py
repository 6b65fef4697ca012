"""The latest state each actuator reports, for a replay's engage ramp and its screen."""

from __future__ import annotations

from teleprev.messages import JointSample


class StateTap:
    """Keeps the latest state each actuator reports, for the engage ramp and the screen."""

    def __init__(self):
        self.latest: dict[str, JointSample] = {}

    def sink(self, sample, receive_ns: int) -> None:
        if isinstance(sample.payload, JointSample):
            self.latest[sample.topic] = sample.payload
