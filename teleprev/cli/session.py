"""`teleprev info SESSION` and `teleprev recover SESSION`: inspect a recorded session, rescue a cut one."""

from __future__ import annotations

from pathlib import Path

import typer

from teleprev.cli.tables import print_table

SESSION_ARG = typer.Argument(..., help="A session file (.mcap).", show_default=False)


def _time(ns: int | None) -> str:
    if ns is None:
        return "-"
    import datetime as dt

    return dt.datetime.fromtimestamp(ns / 1e9, dt.UTC).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + " UTC"


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return str(n)


def _plan_line(record: dict[str, str]) -> str:
    """The timed-episodes plan a session was recorded to, in one line (its fields as they are, where the
    record does not read as a plan)."""
    from rich.markup import escape

    from teleprev.live.record.schedule import EpisodeTimes

    try:
        line = EpisodeTimes.from_record(record).describe()
    except (KeyError, ValueError):
        line = ", ".join(f"{k}={v}" for k, v in sorted(record.items()))
    return escape(line)


_NOT_SKIPPED = ("received", "loop_dropped", "sink_errors", "failures")


def info(
    session: Path = SESSION_ARG,
    as_json: bool = typer.Option(False, "--json", help="Print the facts as one JSON object instead of tables."),
) -> None:
    """Print a session's streams (count, rate, gaps, drops), device events, episodes and duration."""
    from teleprev.session.summary import GAP_FACTOR, PREVIEW_ONLY, device_lost, summarize

    s = summarize(session)
    if as_json:
        import json

        typer.echo(json.dumps(s.to_json(), indent=1))
        return
    from rich import box
    from rich.console import Console
    from rich.table import Table

    console = Console()
    sess = s.metadata.get("session", {})
    tp = s.metadata.get("teleprev", {})
    head = Table.grid(padding=(0, 2))
    head.add_column(style="bold")
    head.add_column()
    head.add_row("file", f"{s.path}  ({_size(s.file_bytes)})")
    head.add_row("start", _time(s.start_ns))
    head.add_row("duration", f"{s.duration_s:.3f} s")
    head.add_row("messages", f"{s.message_count} in {len(s.streams)} streams")
    for key in ("operator", "task", "participant", "condition"):
        if sess.get(key):
            head.add_row(key, sess[key])
    plan = s.metadata.get("episode_plan")
    if plan:
        head.add_row("episode plan", _plan_line(plan))
    if tp:
        version, fmt = tp.get("software_version", "?"), tp.get("format_version", "?")
        head.add_row("recorded by", f"teleprev {version} (format {fmt})")
    if s.recovered:
        rec = s.metadata["recover"]
        lost = f"; damaged and lost: bytes {rec['damaged']}" if rec.get("damaged") else ""
        head.add_row("recovered", f"[yellow]yes[/]: rewritten by `teleprev recover` ({rec.get('stop', '')}{lost})")
    if s.has_recorder_counters:
        style = "bold red" if s.dropped else "green"
        head.add_row("dropped", f"[{style}]{s.dropped}[/]")
    else:
        head.add_row("dropped", "[yellow]unknown[/] (no recorder counters: the recorder did not close the file)")
    if s.device_counts:
        lost = {d: device_lost(c) for d, c in s.device_counts.items()}
        detail = ", ".join(f"{d} {n}" for d, n in sorted(lost.items()) if n)
        head.add_row(
            "lost before recording", f"[bold red]{sum(lost.values())}[/] ({detail}; see devices)" if detail else "0"
        )
    if s.preview_only:
        head.add_row("commands", f"[yellow]none[/]: {PREVIEW_ONLY}")
    if s.sender is not None:
        c = s.sender
        rate = f"{c.rate_hz:g} Hz, " if c.rate_hz else ""
        priority = {True: "real-time priority", False: "[yellow]no real-time priority[/]", None: ""}[c.realtime]
        style = "green" if c.gap_ms_max <= 25.0 else "bold red"
        head.add_row("command sender", f"{rate}{priority}: {c.ticks} ticks, late p50 {c.late_ms_p50:.2f} / p99 "
                     f"{c.late_ms_p99:.2f} / max {c.late_ms_max:.2f} ms; longest gap between commands "
                     f"[{style}]{c.gap_ms_max:.1f} ms[/]")
    failures = s.device_failures
    if failures:
        head.add_row("failed devices", "[bold red]" + ", ".join(f"{d} ({n}x)" for d, n in sorted(failures.items()))
                     + "[/] (see device events)")
    console.print(head)

    table = Table(title="streams", title_justify="left", box=box.SIMPLE_HEAD, pad_edge=False)
    table.add_column("topic", no_wrap=True)
    table.add_column("schema", no_wrap=True)
    for col in ("count", "Hz", "max gap ms", f"gaps>{GAP_FACTOR:g}x", "dropped", "backwards"):
        table.add_column(col, justify="right", no_wrap=True)
    for st in s.streams:
        dropped = "-" if st.dropped is None else (f"[bold red]{st.dropped}[/]" if st.dropped else "0")
        if st.errors:
            dropped += f" [red]+{st.errors} rejected[/]"
        table.add_row(
            st.topic, st.schema.removeprefix("foxglove.").removeprefix("teleprev."), str(st.count),
            "-" if st.rate_hz is None else f"{st.rate_hz:.2f}",
            "-" if st.max_gap_s is None else f"{st.max_gap_s * 1e3:.1f}",
            f"[yellow]{st.gaps}[/]" if st.gaps else "0", dropped,
            f"[red]{st.backwards}[/]" if st.backwards else "0",
        )
    print_table(console, table)
    for line in s.recorder_errors:
        console.print(f"[red]rejected[/] {line}", highlight=False)

    if s.device_counts:
        dev = Table(title="devices", title_justify="left", box=box.SIMPLE_HEAD, pad_edge=False)
        dev.add_column("device", no_wrap=True)
        for col in ("received", "lost", "socket overruns", "sequence gaps", "queue overflow", "loop dropped",
                    "skipped", "failures"):
            dev.add_column(col, justify="right", no_wrap=True)
        for name, c in sorted(s.device_counts.items()):
            skipped = sum(v for k, v in c.items() if k not in _NOT_SKIPPED and not k.startswith("lost_"))
            lost = device_lost(c)
            dev.add_row(
                name,
                str(c.get("received", 0)),
                f"[bold red]{lost}[/]" if lost else "0",
                *(
                    str(c.get(k, 0))
                    for k in ("lost_socket_overruns", "lost_sequence_gaps", "lost_queue_overflow", "loop_dropped")
                ),
                f"[yellow]{skipped}[/]" if skipped else "0",
                f"[bold red]{c.get('failures', 0)}[/]" if c.get("failures") else "0",
            )
        print_table(console, dev)

    if s.device_events:
        ev = Table(title="device events", title_justify="left", box=box.SIMPLE_HEAD, pad_edge=False)
        for col in ("time", "device", "event", "message"):
            ev.add_column(col)
        for d in s.device_events:
            ev.add_row(f"{(d.log_time_ns - s.start_ns) / 1e9:.3f} s", d.device, d.event, d.message)
        print_table(console, ev)

    ep = Table(title="episodes", title_justify="left", box=box.SIMPLE_HEAD, pad_edge=False)
    for col, just in (("#", "right"), ("task", "left"), ("start", "right"), ("duration s", "right"),
                      ("discarded", "left"), ("outcome", "left")):
        ep.add_column(col, justify=just)
    for e in s.episodes:
        ep.add_row(
            str(e.index), e.task, f"{(e.start_ns - s.start_ns) / 1e9:.3f} s" if s.start_ns is not None else "-",
            "[yellow]not stopped[/]" if e.duration_s is None else f"{e.duration_s:.3f}",
            "[yellow]yes[/]" if e.discarded else "no", e.outcome or "-",
        )
    if s.episodes:
        print_table(console, ep)
    else:
        console.print("episodes: none")


def recover(
    session: Path = SESSION_ARG,
    out: Path = typer.Option(
        None, "--out", "-o", help="Where to write the valid session (default: <name>.recovered.mcap)."),
) -> None:
    """Rewrite a session cut short by a crash or power loss into a valid file, and say how much was saved."""
    from rich.console import Console
    from rich.table import Table

    from teleprev.cli.outputs import check_output
    from teleprev.cli.signals import StopSignals
    from teleprev.session.reader import check_written_by_teleprev
    from teleprev.session.recover import default_destination
    from teleprev.session.recover import recover as do_recover

    check_written_by_teleprev(session)
    check_output(out if out is not None else default_destination(session), "--out", overwrite=False)

    with StopSignals() as signals:  # a signal removes the half-written output (the source is never touched)
        try:
            r = do_recover(session, out)
        except KeyboardInterrupt:
            Console(stderr=True).print(f"recover stopped by {signals.name or 'SIGINT'}; nothing was written",
                                       highlight=False, soft_wrap=True)
            raise typer.Exit(signals.exit_code or 130) from None
    console = Console()
    if r.complete:
        console.print(f"{r.src} was complete (it ends with its footer); rewrote it anyway.")
    elif r.stop != "footer":
        lost = r.source_bytes - r.valid_bytes
        console.print(f"read {r.src}: {r.valid_bytes} of {r.source_bytes} bytes make sense "
                      f"({lost} bytes at the end do not: {r.stop})", highlight=False)
    for d in r.damaged:
        console.print(f"[yellow]damaged[/] {d.describe(r.start_ns)}", highlight=False)
    if r.unknown_channel:
        console.print(f"[yellow]{r.unknown_channel} messages[/] whose channel was defined only in a damaged range "
                      "could not be kept", highlight=False)
    table = Table(title=f"saved into {r.dst}", title_justify="left")
    table.add_column("topic")
    table.add_column("messages", justify="right")
    for topic, n in r.messages.items():
        table.add_row(topic, str(n))
    print_table(console, table)
    span = f"{r.span_s:.3f} s ({_time(r.start_ns)} .. {_time(r.end_ns)})" if r.start_ns is not None else "no messages"
    extra = f", {r.salvaged} of them from a cut-off chunk" if r.salvaged else ""
    console.print(f"saved {r.total} messages{extra}, spanning {span}; metadata records: "
                  f"{', '.join(r.metadata) or 'none'}", highlight=False)
