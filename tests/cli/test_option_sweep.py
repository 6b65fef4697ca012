"""The option sweep (tests/helpers/option_sweep.py, run by bench/faults.py) reads every value option from the
CLI's command tree: each is classified, and one added tomorrow is swept (or reported) without a table edit."""

from __future__ import annotations

import typer

from tests.helpers.option_sweep import BASES, bad_values_of, leaf_commands, names_option, sweep


def test_every_value_option_of_every_command_is_swept():
    found = sweep()
    assert found.unclassified == []
    swept = {(b.command, b.option) for b in found.bad}
    assert ("record", "--fps") in {(" ".join(c), o) for c, o in swept}
    assert {c for c, _ in swept} <= set(BASES)
    assert len(found.bad) > 150


def _option(annotation, **kw):
    app = typer.Typer()

    def new(value=typer.Option(None, "--new-value", **kw)) -> None:
        """A command with one new option."""

    new.__annotations__ = {"value": annotation, "return": None}  # a real type, not this module's strings
    app.command()(new)
    return next(p for p in typer.main.get_command(app).params if p.name == "value")


def test_a_new_number_option_gets_its_bad_values_from_its_type_and_range():
    assert [v for v, _ in bad_values_of("new", _option(float))] == ["-1", "nan", "inf"]
    assert [v for v, _ in bad_values_of("new", _option(int, min=1, max=9))] == ["0", "-1", "10"]


def test_a_new_string_option_is_reported_until_it_is_classified():
    assert bad_values_of("new", _option(str)) is None
    assert leaf_commands()[("export",)] is not None


def test_a_refusal_names_the_option_with_or_without_its_dashes():
    names = ("--max-gap-ms",)
    assert names_option("error: max_gap_ms must be a finite number > 0, got nan", names)
    assert names_option("error: Invalid value for '--max-gap-ms'", names)
    assert not names_option("error: nowhere: no such policy folder", names)
