"""Timed episodes: N episode periods of a fixed length separated by reset periods, as lerobot-record's
num_episodes / episode_time_s / reset_time_s.

Every boundary is planned from an anchor on the session clock (the plan's start), never from the end of
the period before, so a late wake-up delays one boundary and not the ones after it. Ending a period
early (the operator's `n`, `d`, `a`) moves the anchor to that instant: the next period then gets its
full length, and the ones after it are planned from there.

    episode 1/N | reset | episode 2/N | reset | ... | episode N/N     (no reset after the last)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from teleprev.errors import ConfigError

MARKS = {"y": True, "f": False, "-": None}  # --marks: success, failure, unmarked
PLAN_RECORD = "episode_plan"  # the session's metadata record holding the plan


@dataclass(frozen=True)
class EpisodeTimes:
    """A timed plan: `episodes` episodes of `episode_s` seconds, `reset_s` seconds between them; each
    engages `engage_after_s` into it (None: stays in preview); `marks` (y, f, -, one per episode,
    cycling; "": none) marks each episode a success or failure when it ends."""

    episodes: int
    episode_s: float
    reset_s: float = 0.0
    engage_after_s: float | None = None
    marks: str = ""

    def check(self) -> EpisodeTimes:
        """Itself, or ConfigError naming the option (as `teleprev record` spells it) that is wrong."""
        if not isinstance(self.episodes, int) or self.episodes < 1:
            raise ConfigError(f"--episodes must be 1 or more, got {self.episodes}")
        if not 0 < self.episode_s < math.inf:
            raise ConfigError(f"--episode-time must be a positive number of seconds, got {self.episode_s:g}")
        if not 0 <= self.reset_s < math.inf:
            raise ConfigError(f"--reset-time must be 0 or more seconds, got {self.reset_s:g}")
        if self.engage_after_s is not None and not 0 <= self.engage_after_s < self.episode_s:
            raise ConfigError(f"--engage-after must be 0 or more seconds and less than --episode-time "
                              f"({self.episode_s:g} s), got {self.engage_after_s:g}")
        wrong = sorted(set(self.marks) - set(MARKS))
        if wrong:
            raise ConfigError(f"--marks takes y (success), f (failure) and - (unmarked), one per episode; "
                              f"got {''.join(wrong)!r} in {self.marks!r}")
        return self

    @property
    def total_s(self) -> float:
        return self.episodes * self.episode_s + (self.episodes - 1) * self.reset_s

    def mark(self, episode: int) -> bool | None:
        """The outcome --marks gives the episode numbered `episode` (0-based): True, False or None."""
        return MARKS[self.marks[episode % len(self.marks)]] if self.marks else None

    def describe(self) -> str:
        """The plan in one line (`teleprev info`): "4 x 1.5 s, resets 1 s, engage after 0.3 s, marks yf-"."""
        engage = "preview only" if self.engage_after_s is None else f"engage after {self.engage_after_s:g} s"
        marks = f", marks {self.marks}" if self.marks else ""
        return f"{self.episodes} x {self.episode_s:g} s, resets {self.reset_s:g} s, {engage}{marks}"

    def to_record(self, rest_s: float) -> dict[str, str]:
        """The metadata record (strings); rest_s: how long before an episode's end it switches to preview."""
        return {"episodes": str(self.episodes), "episode_s": repr(self.episode_s), "reset_s": repr(self.reset_s),
                "engage_after_s": "" if self.engage_after_s is None else repr(self.engage_after_s),
                "marks": self.marks, "preview_before_end_s": repr(rest_s)}

    @classmethod
    def from_record(cls, record: dict[str, str]) -> EpisodeTimes:
        engage = record.get("engage_after_s", "")
        return cls(int(record["episodes"]), float(record["episode_s"]), float(record.get("reset_s", "0")),
                   float(engage) if engage else None, record.get("marks", ""))


@dataclass(frozen=True)
class Period:
    """One period of a running plan: an episode (number: which of the plan's episodes, 0-based; a
    re-recorded one repeats its number) or the reset after episode `number`; start and end on the session
    clock (ns)."""

    kind: str  # "episode" | "reset"
    number: int
    start_ns: int
    end_ns: int

    def left_s(self, now_ns: int) -> float:
        return max(0.0, (self.end_ns - now_ns) / 1e9)


class Schedule:
    """Where a running plan stands: its current period, and what comes after it."""

    def __init__(self, plan: EpisodeTimes, start_ns: int):
        self.plan = plan
        self.episodes = plan.episodes  # episode periods in all (a re-recorded episode adds one)
        self._anchor_ns, self._anchor_s = start_ns, 0.0
        self._index = 0  # periods so far: even ones are episodes, odd ones resets
        self._number = 0  # the plan's episode the current (or last) episode period records
        self._repeat = False  # the next episode period records `_number` again
        self.current: Period | None = self._period()

    def _offset_s(self, index: int) -> float:
        """Seconds from the plan's start to the start of period `index`, with every period at full length."""
        p = self.plan
        return index // 2 * (p.episode_s + p.reset_s) + index % 2 * p.episode_s

    def _at(self, index: int) -> int:
        return self._anchor_ns + round((self._offset_s(index) - self._anchor_s) * 1e9)

    def _period(self) -> Period:
        kind = "episode" if self._index % 2 == 0 else "reset"
        return Period(kind, self._number, self._at(self._index), self._at(self._index + 1))

    @property
    def label(self) -> str:
        """What the current period is, for the screen and the spoken cue."""
        c = self.current
        if c is None:
            return "done"
        if c.kind == "episode":
            return f"episode {c.number + 1}/{self.plan.episodes}"
        return "reset"

    def advance(self, at_ns: int | None = None) -> Period | None:
        """End the current period at its planned end, or at `at_ns` (ended early: the plan is anchored
        there from now on); the next period, or None when the plan is done."""
        c = self.current
        if c is None:
            return None
        if at_ns is not None and at_ns < c.end_ns:
            self._anchor_ns, self._anchor_s = at_ns, self._offset_s(self._index + 1)
        last_episode = c.kind == "episode" and self._index // 2 + 1 >= self.episodes
        self._index += 1
        if c.kind == "reset":
            self._number += 0 if self._repeat else 1
            self._repeat = False
        self.current = None if last_episode else self._period()
        return self.current

    def redo(self) -> None:
        """The current (or last) episode is recorded again: one more episode period, with its number."""
        self.episodes += 1
        self._repeat = True
