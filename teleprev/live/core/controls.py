"""What the operator (keys, the XR page) and scripts ask of a recording, as typed messages.

LoopControls' methods (engage, to_preview, estop, halt, hold, release, start_episode, ...) make one of
these and queue it; the loop thread carries them out in the order they arrive among the samples, so a
replay of the file meets them where the live session did. None is ever dropped.

`at_ns` (episode controls): the session-clock instant the episode event is stamped with, when a schedule
or a key asked for it, however late the loop gets to it (None: when the loop does).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from teleprev.live.core.actuator_host import WireRecord

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
    """The physics world began a scene at at_ns: teleprev.devices.LayoutRecord.to_event(), recorded on
    /events/world."""

    event: dict
    at_ns: int


@dataclass(frozen=True)
class OperatorNote:
    """An operator event recorded as it is (e.g. "ready", "practice_start"); `show`: the preview says `detail`."""

    event: str
    detail: str = ""
    show: bool = False


Control = (Engage | ToPreview | EStop | Halt | Hold | Release | StartEpisode | StopEpisode | DiscardEpisode
           | MarkOutcome | OperatorNote | WorldLayout)


class LoopControls:
    """The session loop's controls, callable from any thread: each queues a typed message for the loop
    thread (never dropped), which carries them out in arrival order among the samples."""

    inbox: Any  # the loop's LoopInbox
    clock: Any  # the session clock

    def send(self, control: Control) -> None:
        self.inbox.put(None, control)

    def engage(self, reason: str = "key", unattended: bool = False) -> None:
        """To execute; `unattended` (a script's engage, recorded as "script") is refused after a device
        fault until the operator engages."""
        self.send(Engage(UNATTENDED if unattended else reason, unattended))

    def to_preview(self, reason: str = "key") -> None:
        self.send(ToPreview(reason))

    def estop(self) -> None:
        self.send(EStop())

    def halt(self, why: str) -> None:
        """Back to preview (the robot brakes to rest), and execute is refused from then on."""
        self.send(Halt(why))

    def hold(self, source: str, why: str, reason: str = "hold") -> None:
        """Back to preview, and execute is refused until `source` releases its hold."""
        if not why:
            raise ValueError("a hold says why execute is refused (release(source) lifts it)")
        self.send(Hold(source, why, reason))

    def release(self, source: str) -> None:
        self.send(Release(source))

    def start_episode(self, task: str = "", at_ns: int | None = None) -> None:
        self.send(StartEpisode(task, at_ns))

    def stop_episode(self, at_ns: int | None = None) -> None:
        self.send(StopEpisode(at_ns))

    def discard_episode(self, at_ns: int | None = None) -> None:
        self.send(DiscardEpisode(at_ns))

    def mark_outcome(self, success: bool) -> None:
        self.send(MarkOutcome(success))

    def note(self, event: str, detail: str = "", show: bool = False) -> None:
        self.send(OperatorNote(event, detail, show))

    def world_layout(self, event: dict, at_ns: int) -> None:
        self.send(WorldLayout(event, at_ns))

    def wired(self, record: WireRecord) -> None:
        """A command an actuator's own process wrote (any thread): queued, to be counted and recorded."""
        self.inbox.put(self.clock.now_ns(), record)
