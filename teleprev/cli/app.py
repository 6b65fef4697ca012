"""The `teleprev` command: groups and commands registered here, each implemented in its own module.

Command modules import only typer and the standard library at import time, so that `teleprev --help`
answers quickly; numpy, torch and lerobot are imported inside the commands that need them.
"""

from __future__ import annotations

import signal
import sys

import typer

from teleprev import __version__
from teleprev.cli import INTERRUPTED, INTERRUPTED_EXIT, collision, robot
from teleprev.cli import calibrate as calibrate_cli
from teleprev.cli import devices as devices_cli
from teleprev.cli import export as export_cli
from teleprev.cli import import_ as import_cli
from teleprev.cli import record as record_cli
from teleprev.cli import replay as replay_cli
from teleprev.cli import rollout as rollout_cli
from teleprev.cli import session as session_cli
from teleprev.cli import study as study_cli

app = typer.Typer(
    name="teleprev",
    help="Teleoperation with preview: collect safe, synchronized robot demonstrations from a mocap glove and suit.",
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode="rich",
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)

COLLECT = "Collect"
MODELS = "Robot and models"

app.command("record", rich_help_panel=COLLECT)(record_cli.record)
app.command("calibrate", rich_help_panel=COLLECT)(calibrate_cli.calibrate)
app.command("rollout", rich_help_panel=COLLECT)(rollout_cli.rollout)

app.add_typer(devices_cli.app, name="devices", rich_help_panel=COLLECT)

app.add_typer(robot.app, name="robot", rich_help_panel=MODELS)
app.add_typer(collision.app, name="collision", rich_help_panel=MODELS)

SESSIONS = "Sessions"

app.command("info", rich_help_panel=SESSIONS)(session_cli.info)
app.command("recover", rich_help_panel=SESSIONS)(session_cli.recover)
app.command("export", rich_help_panel=SESSIONS)(export_cli.export)
app.command("import", rich_help_panel=SESSIONS)(import_cli.import_)
app.command("replay", rich_help_panel=SESSIONS)(replay_cli.replay)
app.command("eval", rich_help_panel=SESSIONS)(replay_cli.eval_)
app.command("audit", rich_help_panel=SESSIONS)(replay_cli.audit)

STUDY = "User studies"

app.command("survey", rich_help_panel=STUDY)(study_cli.survey)
app.command("study", rich_help_panel=STUDY)(study_cli.study)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"teleprev {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", "-V", callback=_version, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """teleprev: teleoperation with preview for robot-learning data collection."""


def ray_address_default(argv: list[str]) -> list[str]:
    """`--ray [ADDRESS]`: typer has no option whose value may be left out, so `--ray` alone, or followed
    by something that is not a Ray address (a session, a folder, a glob, another option), becomes
    `--ray=local` (start a local instance). Addresses are "local", "auto" and anything with a colon
    (HOST:PORT, ray://HOST:PORT)."""
    out = []
    for k, arg in enumerate(argv):
        if arg == "--ray":
            following = argv[k + 1] if k + 1 < len(argv) else ""
            if not (following in ("local", "auto") or (":" in following and not following.startswith("-"))):
                out.append("--ray=local")
                continue
        out.append(arg)
    return out


def foxglove_port_default(argv: list[str]) -> list[str]:
    """`--foxglove [PORT]`: alone (not followed by a number), it means Foxglove's usual port. A number out of the
    ports' range (-1, 70000) is its value, for the option's range check to refuse."""
    out = []
    for k, arg in enumerate(argv):
        if arg == "--foxglove" and not (k + 1 < len(argv) and _is_number(argv[k + 1])):
            out.append(
                "--foxglove=8765"
            )  # teleprev.live.view.foxglove_view.DEFAULT_PORT (not imported: --help stays fast)
            continue
        out.append(arg)
    return out


def _is_number(arg: str) -> bool:
    try:
        float(arg)
    except ValueError:
        return False
    return True


def plain_help(command) -> None:
    """Help without type labels that say nothing to a user: a flag takes no value (typer shows "<bool>"),
    and a list argument's name already says it takes several (typer shows "<list[str]>")."""
    for param in getattr(command, "params", ()):
        if getattr(param, "is_flag", False):
            param.metavar = ""
        elif param.param_type_name == "argument" and param.nargs != 1:
            param.display_type_rich = lambda ctx: None
    made = command.get_help_option  # --help is made (and kept) when help is asked for

    def help_option(ctx, made=made):
        option = made(ctx)
        if option is not None:
            option.metavar = ""
        return option

    command.get_help_option = help_option
    for sub in getattr(command, "commands", {}).values():
        plain_help(sub)


def main() -> None:
    """Entry point: user-facing errors, and usage errors (an unknown option, a value that is not one of its
    choices or out of its range), print one clear line instead of a traceback or a usage panel."""
    from rich.console import Console
    from rich.markup import escape

    from teleprev.cli.signals import StopSignals
    from teleprev.errors import TeleprevError

    command = typer.main.get_command(app)
    plain_help(command)
    signals = StopSignals()  # SIGTERM and SIGHUP stop every command as Ctrl-C does (its clean-up runs)
    try:
        with signals:
            code = command.main(args=foxglove_port_default(ray_address_default(sys.argv[1:])), prog_name="teleprev",
                                standalone_mode=False)
    except TeleprevError as exc:
        # escape: "[devices.suit]" in a message is where the error is, not rich markup
        Console(stderr=True).print(f"[bold red]error:[/] {escape(str(exc))}", highlight=False, soft_wrap=True)
        sys.exit(2)
    except typer.TyperException as exc:
        context = getattr(exc, "ctx", None)
        if type(exc).__name__ == "NoArgsIsHelpError":  # a bare group: its help is on the screen already
            sys.exit(exc.exit_code)
        where = f" (see {context.command_path} --help)" if context is not None else ""
        message = exc.format_message().replace("Value error, ", "")  # typer's wording for a value not among the choices
        Console(stderr=True).print(f"[bold red]error:[/] {escape(message)}{escape(where)}",
                                   highlight=False, soft_wrap=True)
        sys.exit(exc.exit_code)
    except typer.Abort:  # end of input at a prompt
        sys.exit(1)
    except KeyboardInterrupt:
        stopped = signals.received not in (None, signal.SIGINT)
        Console(stderr=True).print(f"stopped by {signals.name}" if stopped else INTERRUPTED, highlight=False)
        sys.exit(signals.exit_code if stopped else INTERRUPTED_EXIT)
    code = code if isinstance(code, int) else 0
    # A signal that stopped a command without clean-up of its own: typer turns the interrupt into exit 130
    # without a word (and a command that ends quietly on Ctrl-C, as `devices emulate`, returns 0).
    if signals.received == signal.SIGINT and code == INTERRUPTED_EXIT:
        Console(stderr=True).print(INTERRUPTED, highlight=False)
    elif signals.received is not None and signals.received != signal.SIGINT and code in (0, INTERRUPTED_EXIT):
        Console(stderr=True).print(f"stopped by {signals.name}", highlight=False)
        code = signals.exit_code
    sys.exit(code)


if __name__ == "__main__":
    main()
