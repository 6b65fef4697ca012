"""Between the session loop and the robot: the actuators' ports, and the paced command sender both ways.

The relay thread takes each tick the sender reports, passes its commands to the arm and the end effector
that run in the session process (the actuators' `send`: the commands never wait for the session loop), and
hands the tick on for the loop to record. An actuator in a process of its own (`hosted`:
teleprev/live/core/actuator_host.py) had its command from the sender itself; its process's WireRecords
are counted here (`wire`). The loop passes the planner's updates (targets, mode switches) to the sender
through `pass_updates`. `active` says whether the sender is commanding (executing, or braking to rest).
"""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Callable

from teleprev import topics
from teleprev.clock import SessionClock
from teleprev.devices.contract import Actuator
from teleprev.messages import Event, JointSample, Logged
from teleprev.pipeline.planner import ModeUpdate


class CommandRelay:
    def __init__(self, clock: SessionClock, actuators: dict[str, Actuator], sender,
                 names: tuple[tuple[str, ...], tuple[str, ...]], on_tick: Callable[[int, object], None],
                 on_gone: Callable[[], None], hosted: frozenset[str] = frozenset()):
        """`actuators` maps "arm" and "hand" to ActuatorPorts, or to ActuatorHosts for the kinds in `hosted`
        (the dict is used as it is, not copied);
        `sender` a CommandSender, started before `start` (None: the pipeline sends its commands itself);
        `names` the arm's and the end effector's joint names; `on_tick(received_ns, SentTick)` and
        `on_gone()` (the sender died) are called on the relay thread."""
        self.clock = clock
        self.actuators = actuators
        self.hosted = hosted
        self.sender = sender
        self.arm_names, self.effector_names = names
        self._on_tick = on_tick
        self._on_gone = on_gone
        self.sent: Counter = Counter()  # commands the actuators took, per kind
        self.errors: Counter = Counter()  # commands a device that was down or refused did not take
        self.active = False  # the sender is commanding (executing, or braking to rest)
        self._mode_seq = 0  # the last mode switch passed to the sender
        self._thread: threading.Thread | None = None
        self.stopping = False

    def start(self) -> None:
        if self.sender is not None:
            self._thread = threading.Thread(target=self._relay, name="command-relay", daemon=True)
            self._thread.start()

    def stop(self, timeout: float) -> None:
        """Stop the sender, and wait until its last ticks have been handed on."""
        self.stopping = True
        if self.sender is not None:
            self.sender.stop()
            if self._thread:
                self._thread.join(timeout)

    def send(self, kind: str, command: JointSample | None) -> None:
        """Through an ActuatorPort: never raises; a device that is down or refuses is counted, not retried."""
        if command is None or kind in self.hosted:  # (the sender handed it to the actuator's process)
            return
        port = self.actuators.get(kind)
        if port is None:
            return
        if port.send(command):
            self.sent[kind] += 1
        else:
            self.errors[kind] += 1

    def wire(self, kind: str, sent: bool) -> None:
        """A command an actuator's own process wrote (sent), or that its device did not take."""
        if sent:
            self.sent[kind] += 1
        else:
            self.errors[kind] += 1

    def pass_updates(self, updates) -> None:
        """The planner's updates, to the sender, in order (on the session loop's thread)."""
        for update in updates:
            if isinstance(update, ModeUpdate):
                self._mode_seq = update.seq
                if update.mode == "halt":
                    self.active = False  # the planner sends nothing more from its next tick
                elif update.mode == "execute":
                    self.active = True
            self.sender.send(update)

    def _relay(self) -> None:
        from teleprev.live.core.sender import SentTick

        while True:
            items = self.sender.receive(0.2)
            if items is None:  # the sender has gone
                self.active = False
                if not self.stopping:
                    self._on_gone()
                return
            for item in items:
                if not isinstance(item, SentTick):
                    continue
                tick = item.tick
                if tick.seq >= self._mode_seq:  # (a tick from before the last mode switch says nothing now)
                    self.active = tick.active
                received = self.clock.now_ns()
                if tick.arm is not None:
                    self.send("arm", JointSample(tick.t_ns, self.arm_names, tick.arm, tick.arm_v))
                if tick.hand is not None:
                    self.send("hand", JointSample(tick.t_ns, self.effector_names, tick.hand, tick.hand_v))
                self._on_tick(received, item)


def tick_records(item, relay: CommandRelay, stamp, receive_ns: int) -> list[Logged]:
    """One of the sender's ticks as the session records it: its commands (stamped at the tick, logged at
    `receive_ns`) and which updates it had (CommandTick). `stamp` makes log times strictly increasing."""
    tick, out = item.tick, []
    for topic, names, q, v in ((topics.COMMAND_ARM, relay.arm_names, tick.arm, tick.arm_v),
                               (topics.COMMAND_HAND, relay.effector_names, tick.hand, tick.hand_v)):
        if q is not None:
            out.append(Logged(topic, stamp(receive_ns), JointSample(tick.t_ns, names, q, v)))
    data = {"seq": tick.seq, "late_ms": item.late_ns / 1e6, "flags": list(tick.flags), "active": tick.active}
    out.append(Logged(topics.COMMAND_TICK, stamp(), Event(tick.t_ns, "teleprev.CommandTick", data)))
    return out
