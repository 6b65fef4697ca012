"""`teleprev devices`: the installed device plugins, and a quick check of a rig's devices."""

from __future__ import annotations

from pathlib import Path

import typer

from teleprev.cli.record import WEBXR_HOST_HELP
from teleprev.cli.tables import print_table

app = typer.Typer(help="Device plugins: list what is installed, check a rig's devices, emulate hardware.",
                  no_args_is_help=True)


@app.command("list")
def list_plugins() -> None:
    """Installed plugins (the `teleprev.devices` entry points): kind, module, and whether they load."""
    from rich.console import Console
    from rich.table import Table

    from teleprev.devices import Device, available

    table = Table(title="device plugins", title_justify="left")
    for col in ("plugin", "kind", "module", "status"):
        table.add_column(col, overflow="fold")
    for name, ep in sorted(available().items()):
        try:
            cls = ep.load()
        except Exception as exc:
            table.add_row(name, "?", ep.value, f"[red]cannot load: {type(exc).__name__}: {exc}[/]")
            continue
        if not (isinstance(cls, type) and issubclass(cls, Device)):
            status = "[red]not a teleprev.devices.Device[/]"
        elif not cls.sdk_installed():
            status = f"[yellow]needs the '{cls.extra}' extra[/] (uv sync --extra {cls.extra})"
        else:
            status = "[green]ok[/]"
        table.add_row(name, getattr(cls, "kind", "?"), ep.value, status)
    Console().print(table)


@app.command("check")
def check(
    rig: Path | None = typer.Argument(None, help="Rig file (TOML); default: the all-sim rig."),
    seconds: float = typer.Option(3.0, "--seconds", "-s", min=0.1, help="How long to read from every device."),
    webxr_host: str = typer.Option("", "--webxr-host", help=WEBXR_HOST_HELP),
) -> None:
    """Open every device of a rig, read for a few seconds, and print rates, latency and errors ("lost":
    samples and events the reader could not hand on)."""
    import time

    from rich import box
    from rich.console import Console
    from rich.table import Table

    from teleprev import topics
    from teleprev.cli.pages import announce_pages
    from teleprev.cli.values import check_seconds
    from teleprev.clock import SessionClock
    from teleprev.devices import DeviceRunner
    from teleprev.errors import TeleprevError
    from teleprev.rig import default_rig_path, load_rig

    check_seconds("--seconds", seconds)  # typer's min= lets infinity and NaN through
    console = Console()
    loaded = load_rig(rig or default_rig_path())
    if webxr_host:
        loaded = loaded.with_device_settings("webxr", "--webxr-host", host=webxr_host)
    clock = SessionClock()
    context = loaded.device_context(clock)
    events: list[dict] = []

    def sink(sample, receive_ns: int) -> None:
        if sample.topic == topics.DEVICE_EVENT:
            events.append(sample.payload.data)

    runners: dict[str, DeviceRunner] = {}
    failed: dict[str, str] = {}
    for name, entry in loaded.devices.items():
        try:
            runners[name] = DeviceRunner(entry.cls(name, entry.settings, context), sink, clock)
        except TeleprevError as exc:
            failed[name] = str(exc)
    console.print(f"reading {len(runners)} devices of {loaded.path} for {seconds:g} s ...")
    for r in runners.values():
        r.start()
    try:
        announce_pages(console, [r.device for r in runners.values()])
        time.sleep(seconds)
    finally:
        stats = {name: r.stats() for name, r in runners.items()}
        # what a device found out about its hardware's setup (e.g. a USB adapter's latency timer)
        notes = [f"  {name}: {note}" for name, r in runners.items() for note in getattr(r.device, "notes", list)()]
        for r in runners.values():
            r.stop()

    table = Table(title=f"rig {loaded.path}", title_justify="left", box=box.SIMPLE_HEAD, pad_edge=False)
    for col, just in (("device", "left"), ("plugin", "left"), ("kind", "left"), ("state", "left"), ("msgs", "right"),
                      ("Hz/nominal", "right"), ("latency ms\nmed/max", "right"), ("errors", "right"),
                      ("lost", "right")):
        table.add_column(col, justify=just, no_wrap=True)
    bad = 0
    said: list[str] = []  # each device's last error, under the table: a long message never squeezes it
    for name, entry in loaded.devices.items():
        if name in failed:
            bad += 1
            table.add_row(name, entry.plugin, entry.kind, "[bold red]not opened[/]", "0", "", "", "1", "")
            said.append(f"  {name}: {failed[name]}")
            continue
        s = stats[name]
        healthy = s.received > 0 and s.state == "ok"
        bad += not healthy
        style = {"ok": "green", "gap": "bold yellow", "error": "bold red"}.get(s.state, "dim")
        slow = s.nominal_hz > 0 and s.rate_hz < 0.8 * s.nominal_hz
        table.add_row(
            name, entry.plugin, entry.kind, f"[{style}]{s.state}[/]", str(s.received),
            f"{'[yellow]' if slow else ''}{s.rate_hz:.1f}/{s.nominal_hz:g}{'[/]' if slow else ''}",
            f"{s.latency_ms:.1f}/{s.latency_max_ms:.1f}" if s.received else "",
            f"{'[red]' if s.errors else ''}{s.errors}{'[/]' if s.errors else ''}",
            f"{'[red]' if s.sink_errors else ''}{s.sink_errors}{'[/]' if s.sink_errors else ''}",
        )
        if s.last_error or _skipped(s.skipped):
            said.append(f"  {name}: {s.last_error or _skipped(s.skipped)}")
    print_table(console, table)
    for line in notes + said:
        console.print(line, highlight=False, markup=False, soft_wrap=True)
    for e in events:
        if e["event"] in ("error", "gap", "disconnected"):
            console.print(f"  {e['device']}: {e['event']}: {e.get('message', '')}", highlight=False, markup=False)
    if bad:
        console.print(f"[bold red]{bad} of {len(loaded.devices)} devices did not stream cleanly[/]")
        raise typer.Exit(1)
    console.print(f"[bold green]all {len(loaded.devices)} devices streaming[/]")


@app.command("emulate")
def emulate(
    what: str = typer.Argument(..., help="xarm (a control box on HOST, ports 502 and 30001-30002) | leap (the LEAP "
                                         "Hand's Dynamixel bus on a pseudo-terminal)"),
    host: str = typer.Option("127.0.0.1", help="xarm: the loopback address to serve on (127.x.y.z)."),
    dof: int = typer.Option(6, help="xarm: 6 or 7 joints."),
    port: Path | None = typer.Option(None, help="leap: the path the bus appears at (default: a temporary one)."),
    seconds: float = typer.Option(0.0, min=0.0, help="Stop after this long (0: at Ctrl-C)."),
) -> None:
    """Run an emulated xArm controller or LEAP Hand bus that the real SDKs drive, and print the rig keys that
    point at it: paste them into a rig to dry-run it (`teleprev devices check`, `teleprev record`)."""
    import os
    import signal
    import threading
    import time

    from rich.console import Console

    from teleprev.cli.values import check_seconds
    from teleprev.errors import ConfigError

    if what not in ("xarm", "leap"):
        raise ConfigError(f"nothing to emulate called {what!r}: xarm or leap")
    if what == "xarm" and dof not in (6, 7):
        raise ConfigError(f"--dof must be 6 or 7, got {dof}")
    check_seconds("--seconds", seconds, zero_ok=True)
    console = Console()
    stop = threading.Event()
    try:  # a device answers in microseconds whatever the host does; an emulator only as soon as it is scheduled
        os.nice(-5)
    except OSError:
        pass
    try:
        if what == "xarm":
            from teleprev.emulators.xarm_controller import XArmController

            emulator = XArmController(host=host, dof=dof).start()
            keys, about = emulator.rig_keys(), f"an xArm{dof} controller on {emulator.host} (ports 502, 30001, 30002)"
        elif what == "leap":
            from teleprev.emulators.dynamixel_bus import DynamixelBus

            emulator = DynamixelBus(port).start()
            keys, about = emulator.rig_keys(), f"a LEAP Hand's Dynamixel bus (16 motors) at {emulator.port}"
    except ValueError as exc:  # a host that is not a loopback address, a port that cannot be made
        raise ConfigError(str(exc)) from None
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    console.print(f"emulating {about}; rig keys:", highlight=False)
    print(keys, flush=True)
    console.print("Ctrl-C stops it." if not seconds else f"stops in {seconds:g} s.")
    deadline = time.monotonic() + seconds if seconds else float("inf")
    try:
        while not stop.is_set() and time.monotonic() < deadline:
            stop.wait(0.2)
    finally:
        emulator.stop()


def _skipped(skipped: dict[str, int]) -> str:
    return ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in skipped.items() if v)
