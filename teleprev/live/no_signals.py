"""A live run (a replay, a rollout) without a command's stop signals: in tests and scripts, where no
teleprev.cli.signals.StopSignals defers, checks and guards the clean-up."""

from __future__ import annotations

import contextlib


class NoSignals:
    def deferred(self):
        return contextlib.nullcontext()

    def finishing(self):
        return contextlib.nullcontext()

    def check(self) -> None:
        pass
