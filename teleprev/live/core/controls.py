"""What the operator (keys, the XR page) and scripts ask of a recording, as typed messages.

SessionLoop's methods (engage, to_preview, estop, halt, hold, release, start_episode, ...) make one of
these and queue it; the loop thread carries them out in the order they arrive among the samples, so a
replay of the file meets them where the live session did. None is ever dropped.

`at_ns` (episode controls): the session-clock instant the episode event is stamped with, when a schedule
or a key asked for it, however late the loop gets to it (None: when the loop does).
"""

from __future__ import annotations

from dataclasses import dataclass

UNATTENDED = "script"  # the reason an unattended engage is recorded with


@dataclass(frozen=True)
class Engage:
    """Switch to execute. `unattended`: a script's, refused after a device fault until the operator engages."""

    reason: str = "key"
    unattended: bool = False


@dataclass(frozen=True)
class ToPreview:
    """Switch to preview: the commands brake to rest. `halt` (an actuator failed): nothing more is sent."""

    reason: str = "key"
    halt: bool = False


@dataclass(frozen=True)
class EStop:
    """teleprev sends nothing more at once; the controller stops the robot itself."""


@dataclass(frozen=True)
class Halt:
    """Back to preview, and execute is refused from then on (the recording, the loop or a policy failed)."""

    why: str


@dataclass(frozen=True)
class Hold:
    """Back to preview, and execute refused while `source` holds (a timed episodes' reset, a policy that has
    not acted yet in its episode); `reason` is recorded with the switch."""

    source: str
    why: str
    reason: str = "hold"


@dataclass(frozen=True)
class Release:
    """`source` holds execute back no more."""

    source: str


@dataclass(frozen=True)
class StartEpisode:
    """A new episode of `task` ("": the last one's), stopping the running one."""

    task: str = ""
    at_ns: int | None = None


@dataclass(frozen=True)
class StopEpisode:
    at_ns: int | None = None


@dataclass(frozen=True)
class DiscardEpisode:
    """The running episode (or the last one) discarded."""

    at_ns: int | None = None


@dataclass(frozen=True)
class MarkOutcome:
    """The operator's mark of the running (or last) episode: y success, f failure."""

    success: bool


@dataclass(frozen=True)
class WorldLayout:
    """The physics world began a scene at at_ns (teleprev.devices.LayoutRecord), recorded on /events/world."""

    layout: dict
    reason: str
    at_ns: int


@dataclass(frozen=True)
class OperatorNote:
    """An operator event recorded as it is (e.g. "ready", "practice_start"); `show`: the preview says `detail`."""

    event: str
    detail: str = ""
    show: bool = False


Control = (Engage | ToPreview | EStop | Halt | Hold | Release | StartEpisode | StopEpisode | DiscardEpisode
           | MarkOutcome | OperatorNote | WorldLayout)
