"""Whether a recording may switch to execute, and why not.

The pipeline refuses an engage for reasons of the moment (nothing previewed yet, a hand inside its
clearance margin); the gate refuses it for reasons of the session, each one a GateState:

    HALTED    for good: the recording, the session loop, the command sender or a policy failed
    HELD      for now: someone holds execute back (a timed episodes' reset, a policy that has not acted
              yet in its episode) until they release it
    FAULTED   a device failed, or the operator's input was lost past the bound (live/core/input_watch.py):
              nothing engages by itself any more; the operator's engage (a key) is let through and clears it
    OPEN      nothing of the session's stands in the way

It is used on the session loop's thread only (SessionLoop carries out every control there).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass


class GateState(enum.Enum):
    OPEN = "open"
    FAULTED = "faulted"
    HELD = "held"
    HALTED = "halted"


@dataclass(frozen=True)
class Refusal:
    state: GateState
    why: str
    tell: bool = False  # record the refusal for the operator (once per fault: why it stays in preview)


class ExecuteGate:
    def __init__(self) -> None:
        self._halt = ""
        self._holds: dict[str, str] = {}  # why, by who holds
        self._fault = ""
        self._fault_told = False

    @property
    def state(self) -> GateState:
        """The strongest reason there is (halted over held over faulted)."""
        if self._halt:
            return GateState.HALTED
        if self._holds:
            return GateState.HELD
        return GateState.FAULTED if self._fault else GateState.OPEN

    @property
    def fault(self) -> str:
        """Why the session stays in preview until the operator engages (a device failed, the input was lost), or ""."""
        return self._fault

    def halt(self, why: str) -> None:
        self._halt = why

    def hold(self, source: str, why: str) -> None:
        self._holds[source] = why

    def release(self, source: str) -> None:
        self._holds.pop(source, None)

    def faulted(self, message: str) -> None:
        self._fault, self._fault_told = message, False

    def engaged(self) -> None:
        """An engage was accepted: the operator has taken over from a fault."""
        self._fault = ""

    def refusal(self, unattended: bool) -> Refusal | None:
        """Why an engage is refused now (None: it may go to the pipeline)."""
        if self._halt:
            return Refusal(GateState.HALTED, self._halt)
        if self._holds:
            return Refusal(GateState.HELD, "; ".join(self._holds.values()))
        if self._fault and unattended:
            tell, self._fault_told = not self._fault_told, True
            return Refusal(
                GateState.FAULTED, f"{self._fault} (an unattended session does not engage again after a fault)", tell
            )
        return None
