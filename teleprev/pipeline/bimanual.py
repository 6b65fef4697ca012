"""Two sides, one operator: a PipelineDriver per side, fed from one ordered stream, switched together.

Each side's driver reads its own devices' topics and makes its own planner's updates; what this adds is
what holds the two together:
- one mode: preview and execute switch both sides or neither (an engage one side refuses is refused for
  both, with that side's reason), so the operator never has one robot moving and the other previewing;
- a fault on one side brakes both (`fault`): the faulted side halts (its controller has stopped it; nothing
  more is sent), the other brakes to rest and holds its last command. Braking both rather than letting the
  healthy side go on: in a bimanual task one hand often holds what the other works on (a lid, a cup being
  poured), and a side that keeps following the operator while its partner is stopped pulls the object out
  of the stopped hand or drops it. The healthy hand keeps its grip, since its last command is held;
- the left glove is a left hand: its SMPL-X pose is mirrored into the right hand's terms before
  retargeting (teleprev/human/mirror.py), and the left LEAP Hand mirrors the right one joint for joint with
  the same signs (urdf/leap_hand_left.urdf), so the right hand's retargeting and Corrector apply unchanged.

A side's recorded streams are the single-arm ones with the side after the first segment of the topic
(`side_topic`): /pipeline/left/retargeted, /command/right/arm.
"""

from __future__ import annotations

from dataclasses import dataclass

from teleprev.human.mirror import mirror_hand_pose
from teleprev.messages import Event, JointSample, Logged
from teleprev.pipeline.cross_side import CrossSideGuard
from teleprev.pipeline.driver import InputTopics, Outputs, PipelineDriver
from teleprev.pipeline.planner import ModeUpdate, TargetUpdate


def side_topic(topic: str, side: str) -> str:
    """A single-arm topic as one side's: "/pipeline/retargeted" -> "/pipeline/left/retargeted"."""
    head, _, rest = topic.strip("/").partition("/")
    return f"/{head}/{side}/{rest}" if rest else f"/{head}/{side}"


@dataclass(frozen=True)
class SideInputs:
    side: str
    topics: InputTopics
    mirrored: bool = False  # the glove is the operator's left hand: mirrored into the right hand's terms


@dataclass(frozen=True)
class ModeState:
    mode: str


class BimanualDriver:
    def __init__(self, sides: dict[str, tuple[PipelineDriver, SideInputs]], guard: CrossSideGuard | None = None):
        """`guard`: the check that keeps the two sides apart (teleprev/pipeline/cross_side.py); None: none."""
        self.drivers = {side: driver for side, (driver, _) in sides.items()}
        self.inputs = {side: inputs for side, (_, inputs) in sides.items()}
        self.guard = guard
        self.faults: dict[str, str] = {}  # side -> why it faulted, until the operator engages again
        self._updates: dict[str, list] = {side: [] for side in self.drivers}  # for the planners, guarded

    @property
    def mode(self) -> str:
        modes = {d.state.mode for d in self.drivers.values()}
        return modes.pop() if len(modes) == 1 else "mixed"

    @property
    def state(self) -> ModeState:
        """What a single-arm driver's `state.mode` tells (LiveSession.settle reads it): both sides' mode."""
        return ModeState(self.mode)

    def _for_side(self, side: str, msg: Logged) -> Logged:
        inputs = self.inputs[side]
        if inputs.mirrored and msg.topic == inputs.topics.hand and isinstance(msg.payload, JointSample):
            p = msg.payload
            mirrored = JointSample(p.stamp_ns, p.names, mirror_hand_pose(p.positions, p.names))
            return Logged(msg.topic, msg.log_time_ns, mirrored)
        return msg

    def feed(self, msg: Logged) -> dict[str, Outputs]:
        """One logged sample to both sides; each side's outputs, their topics made the side's."""
        out = {}
        for side, driver in self.drivers.items():
            o = driver.feed(self._for_side(side, msg))
            contacts = self._collect(side)
            if contacts:
                _mark_held(o, contacts)
            o.logged = [(side_topic(topic, side), payload) for topic, payload in o.logged]
            out[side] = o
        return out

    def _collect(self, side: str) -> list[tuple[str, str]]:
        """The updates `side`'s driver made, through the guard, onto the planner's queue; the contacts of one held."""
        driver, held = self.drivers[side], []
        for update in driver.take_updates():
            if self.guard is not None:
                update, contacts = self.guard.guard(side, update, driver.state.mode == "execute")
                held += contacts
            self._updates[side].append(update)
        return held

    def request_mode(self, mode: str, t_ns: int) -> str:
        """Both sides switch, or neither: "" or why (naming the side) it was refused."""
        if mode == "execute":
            for side, driver in self.drivers.items():
                _, refused = driver.pipeline.set_mode(driver.state, mode, driver._inputs(t_ns))
                if refused:
                    return f"{side}: {refused}"
            self.faults.clear()
        for side, driver in self.drivers.items():
            refused = driver.request_mode(mode, t_ns)
            if refused:  # set_mode is pure and was asked above: only an unknown mode gets here
                return f"{side}: {refused}"
        return ""

    def fault(self, side: str, reason: str, t_ns: int) -> None:
        """`side` faulted: it halts at once, the other side brakes to rest; both stay in preview."""
        self.faults[side] = reason
        for name, driver in self.drivers.items():
            driver.request_mode("estop" if name == side else "preview", t_ns)

    def take_updates(self) -> dict[str, list[TargetUpdate | ModeUpdate]]:
        """Each side's planner updates made since the last call, in order (a held target replaced)."""
        for side in self.drivers:
            self._collect(side)
        out, self._updates = self._updates, {side: [] for side in self.drivers}
        return out


def _mark_held(out: Outputs, contacts: list[tuple[str, str]]) -> None:
    """The step's recorded report says its target was held, and which links (left, right) it would have joined."""
    for _, payload in out.logged:
        if isinstance(payload, Event) and payload.schema == "teleprev.StepReport":
            payload.data["flags"] = [*payload.data.get("flags", []), "cross_side_held"]
            payload.data["cross_side_contacts"] = [f"left:{a}|right:{b}" for a, b in contacts]
    if out.result is not None:
        out.result.report.setdefault("flags", [])
        out.result.report["flags"] = [*out.result.report["flags"], "cross_side_held"]
