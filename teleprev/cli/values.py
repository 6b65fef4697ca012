"""Numeric option values a command refuses before it does any work: one line naming the option, the value
and the range, exit 2 (ConfigError). For what typer's own `min=`/`max=` cannot say: NaN and infinity
(a float option takes "nan" and "inf"), and ranges open at one end."""

from __future__ import annotations

import math

from teleprev.errors import ConfigError


def check_seconds(option: str, value: float | None, *, zero_ok: bool = False) -> None:
    """A duration in seconds: positive (or 0 or more with `zero_ok`) and finite; None: not given."""
    if value is None:
        return
    if not math.isfinite(value) or value < 0 or (value == 0 and not zero_ok):
        wanted = "0 or more seconds" if zero_ok else "a positive number of seconds"
        raise ConfigError(f"{option} must be {wanted}, got {value:g}")


def check_finite(option: str, value: float | None, what: str) -> None:
    """A value the command's own range check (typer's min=) lets through as infinity or NaN."""
    if value is not None and not math.isfinite(value):
        raise ConfigError(f"{option} must be {what}, got {value:g}")


def check_positive(option: str, value: float | None, what: str) -> None:
    """A value that must be more than 0 and finite, where typer's min= can say only "0 or more"."""
    if value is not None and not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{option} must be {what}, got {value:g}")
