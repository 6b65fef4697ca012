"""Tables on the terminal: a number or a name is never cut to fit."""

from __future__ import annotations


def print_table(console, table) -> None:
    """Print `table`, wider than the terminal when its columns need it (rich would otherwise shorten cells
    with an ellipsis: a device name, a topic, a count)."""
    from rich.measure import Measurement

    need = Measurement.get(console, console.options.update_width(10_000), table).maximum
    if need > console.width:
        from rich.console import Console

        console = Console(width=need, file=console.file)
    console.print(table)
