"""The `teleprev` command: groups and commands registered here, each implemented in its own module.

Command modules import only typer and the standard library at import time, so that `teleprev --help`
answers quickly; numpy, torch and lerobot are imported inside the commands that need them.
"""

from __future__ import annotations

import sys

import typer

from teleprev import __version__
from teleprev.cli import robot

app = typer.Typer(
    name="teleprev",
    help="Teleoperation with preview: collect safe, synchronized robot demonstrations from a mocap glove and suit.",
    no_args_is_help=True,
    rich_markup_mode="rich",
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)

MODELS = "Robot and models"

app.add_typer(robot.app, name="robot", rich_help_panel=MODELS)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"teleprev {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", "-V", callback=_version, is_eager=True, help="Print the version and exit."),
) -> None:
    """teleprev: teleoperation with preview for robot-learning data collection."""


def main() -> None:
    """Entry point: user-facing errors print one clear line instead of a traceback."""
    from teleprev.errors import TeleprevError

    try:
        app()
    except TeleprevError as exc:
        from rich.console import Console

        Console(stderr=True).print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
        sys.exit(2)
    except KeyboardInterrupt:
        sys.exit(130)


if __name__ == "__main__":
    main()
