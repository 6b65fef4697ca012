"""Every value option of every teleprev command, read from the CLI's own command tree, with the values it must
refuse: below its minimum or above its maximum (declared or, where the tree cannot say, in OUT_OF_RANGE),
negative, NaN and infinity for a number, an unknown name for an option that takes one of a set. A new option
is swept as soon as it exists; a new string option, or a new command, that these tables do not classify is
reported as unclassified (the sweep cannot judge what it has not been told), so it cannot go unswept.

Each bad value must be refused before the work: exit 2, one line naming the option, nothing written
(`refused_before_work`). bench/faults.py runs the sweep as a family; tests/cli/test_option_sweep.py checks
that the tables classify every option.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FIXTURE = ROOT / "tests" / "fixtures" / "sim_v2.mcap"
CPN = str(ROOT / "models" / "cpn_leap_hand.safetensors")  # the trained CPN the CCN trainers read

# What each command runs with, in an empty folder (its outputs land there), so that an accepted bad value would
# do the work and write there. "{session}" is FIXTURE, "{collision}" a small collision dataset
# (`collision dataset`), "{copy}" a copy of FIXTURE made in the folder (survey writes beside its session).
BASES: dict[tuple[str, ...], list[str]] = {
    ("record",): ["--duration", "1", "--no-preview"],
    ("calibrate",): ["--hold", "0.1"],
    ("rollout",): ["--policy", "nowhere"],  # options are checked before the policy is looked for
    ("export",): ["{session}", "--repo-id", "lab/x", "--root", "ds"],
    ("import",): ["{session}", "--recipe", "foxglove_arm", "--repo-id", "lab/x", "--root", "ds"],
    ("replay",): ["{session}", "--to", "sim", "--engage-after", "0", "--out", "replayed.mcap"],
    ("eval",): ["{session}", "--out", "report.json"],
    ("survey",): ["{copy}"],
    ("study",): ["{session}", "--out", "study"],
    ("devices", "check"): ["--seconds", "0.5"],
    ("devices", "emulate"): ["xarm", "--seconds", "1"],
    ("robot", "check"): ["leap_hand_right", "--samples", "100"],
    ("robot", "exclusions"): ["leap_hand_right", "--samples", "100"],
    ("collision", "dataset"): ["made", "--uniform", "100", "--boundary", "100", "--shard-size", "100",
                               "--workers", "1"],
    ("collision", "train-cpn"): ["{collision}", "--out", "cpn.safetensors", "--epochs", "1", "--device", "cpu",
                                 "--heldout-uniform", "0", "--heldout-boundary", "0"],
    ("collision", "train-ccn"): ["{collision}", "--cpn", CPN, "--out", "ccn.safetensors", "--epochs", "1",
                                 "--device", "cpu",
                                 "--heldout-uniform", "0", "--heldout-trajectory", "0", "--val-exact", "10"],
    ("collision", "grid-search"): ["{collision}", "--cpn", CPN, "--out", "grid", "--epochs", "1", "--device", "cpu",
                                   "--alphas", "1", "--betas", "1", "--max-train", "100", "--val-exact", "10"],
}

# String options: "text" (anything goes: names, labels, addresses, a filter that may match nothing), "name" (one
# of a set: an unknown name is refused), "numbers" (comma-separated numbers). Keyed by option, or by
# (command, option) where one name means different things.
STRINGS: dict[str | tuple[str, str], str] = {
    "--task-text": "text", "--operator": "text", "--participant": "text", "--condition": "text",
    "--webxr-host": "text", "--repo-id": "text", "--ray": "text", "--with-preview": "text",
    "--without-preview": "text", "--host": "text",
    ("export", "--task"): "text", ("study", "--task"): "text",  # filters: a task with no episodes selects none
    ("record", "--task"): "name", ("rollout", "--task"): "name",
    "--recipe": "name", "--preset": "name", "--encoder": "name", "--on-gap": "name", "--only": "name",
    "--split-by": "name", "--marks": "name", "--robot": "name", "--architecture": "name", "--activation": "name",
    "--device": "name",
    "--answers": "numbers", "--hidden": "numbers", "--alphas": "numbers", "--betas": "numbers",
}

# Values the tree cannot show are out of range (a range its type does not declare), by (command, option).
OUT_OF_RANGE: dict[tuple[str, str], tuple[str, ...]] = {
    ("record", "--fps"): ("0", "1e9"),
    ("record", "--duration"): ("0",),
    ("record", "--episode-time"): ("0",),
    ("record", "--connect-timeout"): ("0",),
    ("rollout", "--episode-time"): ("0",),
    ("calibrate", "--seconds"): ("0",),
    ("export", "--crf"): ("52",),
    ("export", "--gop"): ("0", "100000000"),
    ("export", "--workers"): ("0",),
    ("export", "--holdout"): ("1", "1.5"),
    ("export", "--max-gap-ms"): ("0",),
    ("devices emulate", "--dof"): ("5", "8"),
    ("collision train-cpn", "--lr"): ("0",),
    ("collision train-ccn", "--lr"): ("0",),
}

NEGATIVE_OK: set[tuple[str, str]] = set()  # (command, option) of numbers that may be negative: none yet
NAME_BAD = "bogus"


@dataclass(frozen=True)
class BadValue:
    command: tuple[str, ...]
    option: str  # its first name, e.g. "--fps"
    names: tuple[str, ...]  # every name it has (e.g. "--workers", "-j")
    value: str
    why: str  # e.g. "below its minimum 1", "NaN", "an unknown name"

    @property
    def args(self) -> list[str]:
        """The command's base invocation, this option last (click keeps the last of an option given twice)."""
        return [*self.command, *BASES[self.command], self.option, self.value]

    @property
    def where(self) -> str:
        return f"{' '.join(self.command)} {self.option} {self.value}"


@dataclass(frozen=True)
class Sweep:
    bad: list[BadValue]
    unclassified: list[str]  # options and commands the tables do not say how to sweep


def leaf_commands() -> dict[tuple[str, ...], object]:
    import typer

    from teleprev.cli.app import app

    out = {}

    def walk(cmd, path):
        subs = getattr(cmd, "commands", None)
        if subs:
            for name, sub in subs.items():
                walk(sub, (*path, name))
        else:
            out[path] = cmd

    walk(typer.main.get_command(app), ())
    return out


def value_options(cmd) -> list:
    return [p for p in cmd.params
            if p.param_type_name == "option" and not p.is_flag and p.name != "help" and not p.hidden]


def sweep() -> Sweep:
    bad: list[BadValue] = []
    unclassified: list[str] = []
    for path, cmd in leaf_commands().items():
        options = value_options(cmd)
        swept = [(p, values) for p in options if (values := bad_values_of(" ".join(path), p)) is not None]
        unclassified += [f"{' '.join(path)} {p.opts[0]}" for p in options
                         if all(p is not q for q, _ in swept)]
        if any(values for _, values in swept) and path not in BASES:
            unclassified.append(f"{' '.join(path)} (no base invocation in BASES)")
            continue
        for p, values in swept:
            bad += [BadValue(path, p.opts[0], tuple(p.opts), v, why) for v, why in values]
    return Sweep(bad, unclassified)


def bad_values_of(command: str, p) -> list[tuple[str, str]] | None:
    """(value, why) for each value the option must refuse; None: the tables do not say how to sweep it."""
    import typing

    kind = p.type_descriptor.annotation
    if typing.get_origin(kind) is typing.Literal:
        return [(NAME_BAD, "not one of its choices")]
    if kind is Path or kind is bool:
        return []  # paths: the output-path family; --x/--no-x pairs take no value
    if kind in (int, float):
        return number_bad_values(command, p, kind)
    if kind is str or typing.get_origin(kind) is list:
        what = STRINGS.get((command, p.opts[0]), STRINGS.get(p.opts[0]))
        if what is None:
            return None
        return {"text": [], "name": [(NAME_BAD, "an unknown name")],
                "numbers": [(NAME_BAD, "not numbers"), ("-1", "a negative number")]}[what]
    return None


def number_bad_values(command: str, p, kind) -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []
    low, high = p.min, p.max
    if low is not None:
        below = low - 1 if kind is int or low <= 0 else low / 2
        out.append((fmt(below), f"below its minimum {fmt(low)}"))
    if (command, p.opts[0]) not in NEGATIVE_OK and (low is None or low >= 0):
        out.append(("-1", "negative"))
    if high is not None:
        out.append((fmt(high + 1), f"above its maximum {fmt(high)}"))
    if kind is float:
        out += [("nan", "NaN"), ("inf", "infinity")]
    out += [(v, "out of its range") for v in OUT_OF_RANGE.get((command, p.opts[0]), ())]
    seen: set[str] = set()
    return [(v, why) for v, why in out if not (v in seen or seen.add(v))]


def fmt(x: float) -> str:
    return str(int(x)) if float(x).is_integer() and math.isfinite(x) else repr(float(x))


def names_option(line: str, names: tuple[str, ...]) -> bool:
    """Whether a refusal's line names the option: by any of its names, with or without its dashes (a setting
    an encoder or recipe shares, e.g. "crf must be 0..51", is named as the recipe names it)."""
    words = {n for n in names if n.startswith("--")}
    words |= {n.lstrip("-") for n in words} | {n.lstrip("-").replace("-", "_") for n in words}
    return any(w in line for w in words)
