"""The session loop of a bimanual rig: one ordered stream, a pipeline and a paced sender per side.

Everything the single-arm loop does (ordering, recording, the gate, episodes, input loss, faults) it does
here too, through SessionLoop's own code; what differs is what a sample feeds and where commands go:
- each sample feeds the BimanualDriver (teleprev/pipeline/bimanual.py), which steps the side whose glove
  it is and records that side's results on its own topics (/pipeline/left/corrected, ...);
- each side has its own CommandSender (its own planner and limits, in a paced process of its own) and
  relay; a tick is recorded on the side's topics (/command/left/arm, /command/left/hand,
  /command/left/tick). Updates from both sides' steps reach both senders, mode switches together;
- a device that fails faults its side (BimanualDriver.fault): that side halts if the device is its
  actuator, the other side brakes to rest; both stay in preview until the operator engages.
An actuator in a process of its own (the real xArm and LEAP plugins) gets its commands from its side's
sender, and what it wrote is recorded on its side's /command/<side>/wire.
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, replace

from teleprev import topics
from teleprev.live.core.actuator_host import WireRecord
from teleprev.live.core.controls import ToPreview
from teleprev.live.core.input_watch import InputWatch
from teleprev.live.core.loop import SessionLoop
from teleprev.live.core.relay import CommandRelay, tick_records
from teleprev.messages import Logged, Sample
from teleprev.pipeline.bimanual import BimanualDriver, side_topic
from teleprev.status import SideView


@dataclass(frozen=True)
class SideTick:
    """A sender's tick, with the side whose sender made it."""

    side: str
    item: object  # sender.SentTick

    @property
    def late_ns(self) -> int:
        return self.item.late_ns


@dataclass(frozen=True)
class SideWire:
    """A command one side's actuator process wrote (actuator_host.WireRecord), with its side."""

    side: str
    record: WireRecord


class RelayPair:
    """Both sides' CommandRelays, seen by SessionLoop's code as its one relay."""

    def __init__(self, relays: dict[str, CommandRelay]):
        self.relays = relays
        self.sent: Counter = Counter()  # commands the actuators took, per "<side>/<kind>"
        self.errors: Counter = Counter()
        self.actuators = {f"{side}/{kind}": port for side, r in relays.items() for kind, port in r.actuators.items()}
        self.sender = self  # (SessionLoop stops "the sender" when a halt itself fails)

    @property
    def active(self) -> bool:
        return any(r.active for r in self.relays.values())

    def start(self) -> None:
        for r in self.relays.values():
            r.start()

    def stop(self, timeout: float) -> None:
        for r in self.relays.values():
            r.stop(timeout)

    def pass_updates(self, updates: dict[str, list]) -> None:
        for side, ups in updates.items():
            self.relays[side].pass_updates(ups)

    def count(self) -> None:
        """The per-side counts, gathered (the preview and the file's metadata read `sent` and `errors`)."""
        for side, r in self.relays.items():
            for kind, n in r.sent.items():
                self.sent[f"{side}/{kind}"] = n
            for kind, n in r.errors.items():
                self.errors[f"{side}/{kind}"] = n


PREVIEWED_SIDE = "right"  # the side whose step the snapshot's own fields carry


class BimanualLoop(SessionLoop):
    def __init__(self, clock, log, driver: BimanualDriver, *, inbox, actuators: dict[str, dict], senders: dict,
                 device_sides: dict[str, str], side_frames: dict | None = None,
                 hosted: dict[str, frozenset[str]] | None = None, input_loss_to_preview_s: float = 1.0, **kwargs):
        """`actuators` and `senders`: per side, as SessionLoop takes them for one; `device_sides`: device name ->
        its side (a failure of one faults that side); `hosted`: per side, the kinds ("arm", "hand") whose
        actuator runs in a process of its own (its sender hands it the commands); `side_frames`: each side's
        robot on /tf (bimanual_session.py's SideFrames: `sample(driver, arm_state)`)."""
        super().__init__(clock, log, None, inbox=inbox, input_loss_to_preview_s=input_loss_to_preview_s, **kwargs)
        self.driver = driver
        self.side_frames = side_frames or {}
        self._arm_topics = {driver.inputs[side].topics.arm: side for side in self.side_frames}
        self.device_sides = device_sides
        relays = {}
        for side, sender in senders.items():
            pipeline = driver.drivers[side].pipeline
            relays[side] = CommandRelay(
                clock, actuators[side], sender, (pipeline.arm_names, pipeline.effector_names),
                on_tick=lambda received, item, side=side: self.inbox.put(received, SideTick(side, item)),
                on_gone=lambda side=side: self.halt(f"the {side} command sender stopped"),
                hosted=(hosted or {}).get(side, frozenset()))
        self.relay = RelayPair(relays)
        self.stats.commands_sent, self.stats.command_errors = self.relay.sent, self.relay.errors
        stale_ms = max(d.pipeline.cfg.stale_ms for d in driver.drivers.values())
        watched = not any(d.topics.action for d in driver.drivers.values())  # (a policy's actions are not)
        self.input_watch = InputWatch(int(input_loss_to_preview_s * 1e9), int(stale_ms * 1e6)) if watched else None
        self.snapshot = replace(self.snapshot, stale_ms=stale_ms)

    def stop(self, timeout: float = 5.0) -> None:
        super().stop(timeout)
        self.relay.count()

    def _sample(self, sample: Sample, receive_ns: int) -> None:
        t = self._stamp(receive_ns)
        msg = self._record(sample, t)
        payload = msg.payload
        if self.failure:
            return
        started = time.perf_counter_ns()
        outputs = self.driver.feed(msg)
        side = self._arm_topics.get(sample.topic)
        if side is not None:
            tf = self.side_frames[side].sample(self.driver.drivers[side], payload)
            if tf is not None:
                self._log(Logged(topics.TF, self._stamp(), tf))
        stepped = [o for o in outputs.values() if o.result is not None]
        if not stepped:
            return
        if len(self.stats.step_ns) < 100_000:
            self.stats.step_ns.append(time.perf_counter_ns() - started)
        for out in stepped:
            update = out.result.update
            usable = out.result.arm_target is not None if update is None else \
                update.arm is not None and update.hand is not None
            if self.input_watch is not None:
                self._input_event(self.input_watch.stepped(t, usable, out.result.report.get("flags", [])))
        self._pass_updates()
        for out in stepped:
            for topic, value in out.logged:
                self._log(Logged(topic, self._stamp(), value))
        self.relay.count()
        # The terminal preview draws both sides; the snapshot's own step and joints are the right side's (the
        # XR page's status reads those).
        previous = {view.side: view for view in self.snapshot.sides}
        views = []
        for side, shown in self.driver.drivers.items():
            latest, pipeline = shown.latest, shown.pipeline
            step = outputs[side].result if side in outputs and outputs[side].result is not None else \
                getattr(previous.get(side), "step", None)
            views.append(SideView(side, step, pipeline.measured(latest.get(shown.topics.arm), pipeline.arm_names),
                                  pipeline.measured(latest.get(shown.topics.effector), pipeline.effector_names)))
        right = next(view for view in views if view.side == PREVIEWED_SIDE)
        self.snapshot = replace(
            self.snapshot, mode=self.driver.mode, step=right.step, measured_arm=right.measured_arm,
            measured_effector=right.measured_effector, sides=tuple(views),
            commands_sent=sum(self.stats.commands_sent.values()), dropped=sum(self.stats.dropped.values()))

    def wired_side(self, side: str, record: WireRecord) -> None:
        """A command one side's actuator process wrote (any thread): queued, to be counted and recorded."""
        self.inbox.put(self.clock.now_ns(), SideWire(side, record))

    def _tick(self, item: SideTick | SideWire, receive_ns: int) -> None:
        """One side's tick, or a command its actuator's process wrote, on that side's topics."""
        if isinstance(item, SideWire):
            r = item.record
            self.relay.relays[item.side].wire(r.kind, r.sent)
            data = {"kind": r.kind, "seq": r.seq, "t_ns": r.t_ns, "call_ms": r.call_ns / 1e6, "sent": r.sent}
            if r.error:
                data["error"] = r.error
            self._event(side_topic(topics.COMMAND_WIRE, item.side), "teleprev.CommandWire", data, receive_ns,
                        stamp_ns=r.wire_ns)
            return
        self.stats.ticks += 1
        if len(self.stats.late_ns) < 1_000_000:
            self.stats.late_ns.append(item.late_ns)
        for msg in tick_records(item.item, self.relay.relays[item.side], self._stamp, receive_ns):
            self._log(replace(msg, topic=side_topic(msg.topic, item.side)))

    def _device_failed(self, data: dict) -> None:
        """A device failed: its side faults (halting if it is that side's actuator), the other side brakes
        to rest; recorded as a switch to preview, and the gate refuses to engage until the operator does."""
        name = str(data.get("device", ""))
        self.stats.device_failures[name] += 1
        side = self.device_sides.get(name)
        message = f"device {name} failed: {data.get('message', '')}"
        self.gate.faulted(message)
        if side is not None and (self.driver.mode == "execute" or self.relay.active):
            actuator = name in {getattr(p, "name", None) for p in self.relay.relays[side].actuators.values()}
            t = self._stamp()
            self.driver.fault(side, message, t)
            switch = {"mode": "preview", "reason": f"device {name} failed", "side": side}
            if actuator:
                switch["halt"] = True
            self._event(topics.MODE, "teleprev.ModeSwitch", switch, t)
            self._pass_updates()
            if self.input_watch is not None:
                self.input_watch.left_execute()
            message += f"; the {side} side stops, the other brakes to rest: back in PREVIEW (press space to engage)"
        elif self.driver.mode == "execute":  # a device of no side (a camera): both brake to rest
            self._apply(ToPreview(f"device {name} failed"))
            message += "; both sides brake to rest, back in PREVIEW (press space to engage again)"
        self.snapshot = replace(self.snapshot, message=message, fault=self.gate.fault)
