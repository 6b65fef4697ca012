"""How long the operator's input has been lost while executing, and what the session does about it.

A pipeline step whose inputs give no target for a side (missing, stale, non-finite, junk) holds that side:
the command planner brakes it to rest and holds it there (teleprev/pipeline/planner.py). What happens when
the input comes back depends on how long it was gone:

    shorter than the bound   the commands resume from where they are held, at the engage fraction of the
                             speed caps until they meet the targets (the planner's "input_resumed")
    longer than the bound    the session goes back to PREVIEW, and only the operator engages again: a person
                             who looked away during a long loss does not expect the robot to move when
                             tracking returns

A frozen process (SIGSTOP, a swapped-out machine) is a loss too: nothing was read meanwhile, so the first
sample after it comes more than the bound after the last usable one; the loop also sees its own wake-ups
stop (`stalled`) and says so. The bound is the rig's `[session] input_loss_to_preview_s`.

Times are the session clock's; the samples' log times, not the instant the loop gets to them, so a loop that
is behind does not take its own backlog for a loss. Used on the session loop's thread only.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class InputEvent:
    """A transition of the input while executing, for the session's operator events."""

    event: str  # "input_held" | "input_resumed" | "input_lost"
    detail: str
    to_preview: bool = False  # the loss lasted past the bound: back to PREVIEW


class InputWatch:
    def __init__(self, bound_ns: int, stale_ns: int):
        """`bound_ns`: a loss longer than this goes back to preview; `stale_ns`: no usable step for this long
        is a loss (the pipeline's stale limit), even while no sample at all arrives."""
        self.bound_ns = bound_ns
        self.stale_ns = stale_ns
        self.executing = False
        self.last_ok_ns = 0  # the last usable step (or the engage) while executing
        self.held_since_ns: int | None = None  # the first unusable step since then
        self.why = ""  # what the step said about its inputs then (its flags)

    def engaged(self, t_ns: int) -> None:
        self.executing, self.last_ok_ns, self.held_since_ns, self.why = True, t_ns, None, ""

    def left_execute(self) -> None:
        self.executing, self.held_since_ns = False, None

    def stepped(self, t_ns: int, usable: bool, flags: list[str]) -> InputEvent | None:
        """A pipeline step at log time t_ns whose inputs gave both sides a target (`usable`) or not."""
        if not self.executing:
            return None
        seen = self.check(t_ns)
        if seen is not None and seen.to_preview:
            return seen
        if not usable:
            if self.held_since_ns is None:
                self.held_since_ns, self.why = t_ns, ", ".join(flags) or "no target"
                return InputEvent("input_held", f"the input gives no target ({self.why}): the robot holds")
            return seen
        event = None
        if self.held_since_ns is not None:
            gone_s = (t_ns - self.last_ok_ns) / 1e9
            event = InputEvent("input_resumed", f"the input is back after {gone_s:.2f} s: resuming at the engage speed")
        self.last_ok_ns, self.held_since_ns = t_ns, None
        return event

    def check(self, now_ns: int, stalled_s: float = 0.0) -> InputEvent | None:
        """At now_ns (a sample's log time, or the clock when nothing is queued): the loss past the bound, if
        it is one; `stalled_s`: how long the loop itself did not run before now (a frozen process)."""
        if not self.executing:
            return None
        # A loop that did not run past the bound was frozen (SIGSTOP, a suspended laptop): what it finds queued
        # then may be samples stamped inside the freeze, which look continuous, so the stall itself decides.
        if now_ns - self.last_ok_ns <= self.bound_ns and stalled_s * 1e9 <= self.bound_ns:
            if self.held_since_ns is None and now_ns - self.last_ok_ns > self.stale_ns:
                self.held_since_ns, self.why = now_ns, "no input"
                return InputEvent("input_held", f"no input for {self.stale_ns / 1e6:g} ms: the robot holds")
            return None
        gone_s = (now_ns - self.last_ok_ns) / 1e9
        bound_s = self.bound_ns / 1e9
        if stalled_s * 1e9 > self.bound_ns:
            what = f"the session process did not run for {stalled_s:.2f} s (frozen?)"
        else:
            what = f"no usable input for {gone_s:.2f} s" + (f" ({self.why})" if self.why else "")
        self.left_execute()
        return InputEvent("input_lost", f"{what}, more than {bound_s:g} s: back in PREVIEW (press space to engage "
                                        "again)", to_preview=True)

