"""One line of the terminal preview's device table: a device's runner stats and the loop's drops for it."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DeviceRow:
    name: str
    kind: str
    state: str  # ok | gap | error | connecting
    rate_hz: float
    nominal_hz: float
    latency_ms: float
    dropped: int  # samples the session loop's queue had no room for
    lost: int  # samples the device's runner could not hand to the loop (the sink raised)
    errors: int
    lost_input: int = 0  # input lost before the device read it (socket overruns, sequence gaps, its queue)
    hint: str = ""  # what the operator has to do for it to stream (e.g. open the XR page's URL), or ""
