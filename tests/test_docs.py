"""The README, docs/ and the model cards cannot drift from the code: every relative link (and its #anchor)
leads somewhere; every `teleprev ...` line in a shell code block is a command the CLI has, with options it
has, values it accepts and the arguments it needs; a command named in a sentence exists with the options it
is given; and a source file named in inline code exists. The commands come from the CLI itself (typer's
click command tree, read as teleprev's entry point reads its arguments), not from a list kept here."""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from pathlib import Path

import pytest
import typer

from teleprev.cli.app import app, foxglove_port_default, ray_address_default

ROOT = Path(__file__).resolve().parents[1]
DOCS = sorted((ROOT / "docs").glob("*.md"))
MODEL_CARDS = sorted((ROOT / "models").glob("*.md"))  # written by training; their commands retrain the models
PAGES = [ROOT / "README.md", *DOCS, *MODEL_CARDS]
SHELL_LANGUAGES = {"bash", "sh", "shell", "console"}
HELP = {"--help", "-h"}
# where the repository's sources and shipped data live (what teleprev writes, sessions/ or datasets/out/, is not)
SOURCE_PATH = r"(teleprev|devices|bench|tests|scripts|rigs|urdf|models|datasets/recipes|datasets/imports)/"


@dataclass(frozen=True)
class Block:
    language: str
    line: int  # of the first line of code, 1-based
    code: str


@dataclass(frozen=True)
class Link:
    line: int
    target: str


def fenced_blocks(text: str) -> list[Block]:
    blocks, lines = [], text.splitlines()
    k = 0
    while k < len(lines):
        opening = re.match(r"^(\s*)(```+|~~~+)\s*([\w+-]*)", lines[k])
        if opening:
            fence, start = opening.group(2), k + 1
            k += 1
            while k < len(lines) and not lines[k].strip().startswith(fence):
                k += 1
            blocks.append(Block(opening.group(3).lower(), start + 1, "\n".join(lines[start:k])))
        k += 1
    return blocks


def prose_lines(text: str, keep_code: bool = False) -> list[tuple[int, str]]:
    """(1-based number, line) of the lines outside fenced blocks, inline code spans blanked out unless kept."""
    inside, out = None, []
    for number, line in enumerate(text.splitlines(), 1):
        fence = re.match(r"^\s*(```+|~~~+)", line)
        if inside is None and fence:
            inside = fence.group(1)
        elif inside is not None and line.strip().startswith(inside):
            inside = None
        elif inside is None:
            out.append((number, line if keep_code else re.sub(r"`[^`]*`", "``", line)))
    return out


def links(text: str) -> list[Link]:
    found = []
    for number, line in prose_lines(text):
        for match in re.finditer(r"\]\(([^()\s]+)(?:\s+\"[^\"]*\")?\)", line):
            found.append(Link(number, match.group(1)))
    return found


def heading_anchors(text: str) -> set[str]:
    """The anchors GitHub gives a page's headings: lower case, punctuation dropped, spaces as hyphens,
    a repeated one numbered."""
    anchors: set[str] = set()
    count: dict[str, int] = {}
    for _, line in prose_lines(text.replace("`", "")):
        heading = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if heading:
            slug = re.sub(r"[^\w\- ]", "", heading.group(1).lower()).replace(" ", "-")
            anchors.add(f"{slug}-{count[slug]}" if slug in count else slug)
            count[slug] = count.get(slug, 0) + 1
    return anchors


def link_problem(page: Path, link: Link) -> str | None:
    """What is wrong with a link on a page, or None."""
    target = link.target
    if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # https:, mailto:: not a file here
        return None
    path_part, _, anchor = target.partition("#")
    path = (page.parent / path_part).resolve() if path_part else page
    where = f"{page.relative_to(ROOT)}:{link.line}: link {target!r}"
    if not path.exists():
        return f"{where}: no such file"
    if ROOT not in path.parents and path != ROOT:
        return f"{where}: leads out of the repository"
    if anchor and path.suffix == ".md" and anchor not in heading_anchors(path.read_text()):
        return f"{where}: {path.relative_to(ROOT)} has no heading with anchor #{anchor}"
    return None


def command_lines(code: str) -> list[str]:
    """The `teleprev ...` lines of a shell block (continuations joined; a prompt or sudo before it left out)."""
    joined = re.sub(r"\s*\\\n\s*", " ", code)
    out = []
    for line in joined.splitlines():
        line = re.sub(r"^\s*(\$\s+)?(sudo\s+)?", "", line)
        if line.split(" ", 1)[0] == "teleprev":
            out.append(line)
    return out


def inline_code(text: str) -> list[tuple[int, str]]:
    """(line, code) of the inline code spans outside fenced blocks."""
    return [(number, span) for number, line in prose_lines(text, keep_code=True)
            for span in re.findall(r"`([^`]+)`", line)]


def command_problem(line: str, whole: bool = True) -> str | None:
    """What the CLI would refuse in a documented command line (an unknown command or option; when the line
    is a whole command, also a value it does not accept, a missing or extra argument), or None. Nothing is
    run. A command named in a sentence (`teleprev info`'s table) is not whole: only its names are checked."""
    words = shlex.split(re.sub(r"<[^<>]*>", "PLACEHOLDER", line), comments=True)
    args = foxglove_port_default(ray_address_default(words[1:]))  # as teleprev's entry point reads them
    command = typer.main.get_command(app)
    context = command.context_class(command, info_name="teleprev")
    try:
        while hasattr(command, "list_commands"):  # a group: its own options, then a subcommand
            _, rest, _ = command.make_parser(context).parse_args(list(args))
            if not rest:
                return None  # `teleprev`, `teleprev devices --help`
            name, args = rest[0], rest[1:]
            sub = command.get_command(context, name)
            if sub is None:
                known = ", ".join(command.list_commands(context))
                return f"{context.command_path} has no command {name!r} (it has: {known})"
            command, context = sub, sub.context_class(sub, info_name=name, parent=context)
        if HELP & set(args) or not whole:
            command.make_parser(context).parse_args(list(args))  # options known; --help asks for nothing else
        else:
            command.make_context(context.info_name, list(args), parent=context.parent)
    except typer.TyperException as exc:
        return f"{context.command_path}: {exc.format_message()}"
    return None


def documented_commands() -> list[tuple[str, str]]:
    """(where, line) of every `teleprev` line in a shell block of the pages."""
    out = []
    for page in PAGES:
        for block in fenced_blocks(page.read_text()):
            if block.language in SHELL_LANGUAGES:
                for line in command_lines(block.code):
                    out.append((f"{page.relative_to(ROOT)}, the block at line {block.line}", line))
    return out


def documented_paths() -> list[tuple[str, str]]:
    """(where, path) of the inline code spans that name a file or folder of the repository (not one that
    teleprev writes, a glob or a placeholder)."""
    out = []
    for page in PAGES:
        for number, span in inline_code(page.read_text()):
            path = span.split()[0]  # `bench/pipeline.py --busy 2`
            if re.match(SOURCE_PATH, path) and not re.search(r"[*<>]|\.\.\.", path):
                out.append((f"{page.relative_to(ROOT)}:{number}", path))
    return out


def test_every_relative_link_leads_to_a_file_and_heading():
    problems = [p for page in PAGES for link in links(page.read_text()) if (p := link_problem(page, link))]
    assert not problems, "\n".join(problems)


def test_every_documented_command_is_one_the_cli_accepts():
    commands = documented_commands()
    assert len(commands) > 50  # the pages were found and their blocks read
    problems = [f"{where}: {line}\n    {p}" for where, line in commands if (p := command_problem(line))]
    assert not problems, "\n".join(problems)


def test_every_command_named_in_a_sentence_exists_with_its_options():
    named = [(f"{page.relative_to(ROOT)}:{number}", span) for page in PAGES
             for number, span in inline_code(page.read_text()) if re.match(r"teleprev( |$)", span)]
    assert len(named) > 20
    problems = [f"{where}: `{span}`: {p}" for where, span in named if (p := command_problem(span, whole=False))]
    assert not problems, "\n".join(problems)


def test_every_source_file_named_exists():
    paths = documented_paths()
    assert len(paths) > 30
    missing = [f"{where}: `{path}`" for where, path in paths if not (ROOT / path).exists()]
    assert not missing, "no such file or folder in the repository:\n" + "\n".join(missing)


def test_the_readme_is_a_front_door():
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 220
    assert "bash scripts/demo.sh" in readme and "bash scripts/test.sh" in readme
    linked = {(ROOT / link.target.partition("#")[0]).resolve() for link in links(readme)}
    assert not [page for page in DOCS if page not in linked], "a docs/ page the README does not lead to"


# The checkers themselves: each must catch what it is there to catch.

@pytest.mark.parametrize("line, complaint", [
    ("teleprev recrod sessions/x.mcap", "has no command 'recrod'"),
    ("teleprev devices lst", "teleprev devices has no command 'lst'"),
    ("teleprev record --duraton 60", "No such option: --duraton"),
    ("teleprev record --view diagonal", "'diagonal' is not one of"),
    ("teleprev replay x.mcap --to simulator", "'simulator' is not one of"),
    ("teleprev replay --speed 2", "Missing argument"),
    ("teleprev info a.mcap b.mcap", "unexpected extra argument"),
    ("teleprev robot check leap_hand_right -n many", "valid integer"),
    ("teleprev --verbose record", "No such option: --verbose"),
    ("teleprev eval x.mcap --help --bogus", "No such option: --bogus"),
])
def test_the_command_checker_refuses_what_the_cli_would(line, complaint):
    problem = command_problem(line)
    assert problem is not None and complaint in problem, problem


@pytest.mark.parametrize("line", [
    "teleprev record my_rig.toml --task pour --duration 60 --episodes 4 --engage-after 3 --no-preview",
    "teleprev eval 'sessions/*.mcap' -j 2 --ray",  # --ray alone: a local Ray instance
    "teleprev export sessions/ --repo-id lab/all --ray 10.0.0.5:6379",
    "teleprev record --foxglove",
    "teleprev survey sessions/<that session>.mcap  # a placeholder is one word",
    "teleprev devices check --help",
    "teleprev --version",
])
def test_the_command_checker_accepts_what_the_cli_accepts(line):
    assert command_problem(line) is None


def test_a_command_in_a_sentence_is_checked_for_its_names_and_options_only():
    assert command_problem("teleprev info", whole=False) is None  # `teleprev info`'s devices table
    assert "Missing argument" in command_problem("teleprev info")
    assert "has no command 'inf'" in command_problem("teleprev inf", whole=False)
    assert "No such option: --smoth" in command_problem("teleprev replay --to arm --smoth", whole=False)
    spans = inline_code("`teleprev info` and `teleprev/live/run.py`\n```bash\nteleprev x\n```\n`bench/*.py`\n")
    assert spans == [(1, "teleprev info"), (1, "teleprev/live/run.py"), (5, "bench/*.py")]


def test_command_lines_are_found_in_shell_blocks_only_as_commands():
    code = ("teleprev export a.mcap \\\n    --repo-id lab/a\n$ teleprev info a.mcap\n"
            "sudo teleprev devices emulate xarm\nadb reverse tcp:8443 tcp:8443   # teleprev is not the first word\n")
    assert command_lines(code) == ["teleprev export a.mcap --repo-id lab/a", "teleprev info a.mcap",
                                   "teleprev devices emulate xarm"]
    page = "# A\n```bash\nteleprev info a.mcap\n```\n```toml\n# teleprev info\n```\n"
    assert [(b.language, b.line) for b in fenced_blocks(page)] == [("bash", 3), ("toml", 6)]


def test_the_link_checker_finds_missing_files_and_headings(tmp_path, monkeypatch):
    monkeypatch.setattr(f"{__name__}.ROOT", tmp_path)
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "b.md").write_text("# Rigs and devices\n## Motion limits: commands\n## Rigs and devices\n")
    page = tmp_path / "README.md"
    page.write_text("[b](docs/b.md#rigs-and-devices) [c](docs/b.md#motion-limits-commands) "
                    "[d](docs/b.md#rigs-and-devices-1) [e](https://example.org/x)\n"
                    "[gone](docs/gone.md) [no heading](docs/b.md#rigs) [out](../x.md) `[code](nowhere.md)`\n"
                    "```\n[block](nowhere.md)\n```\n")
    problems = [link_problem(page, link) for link in links(page.read_text())]
    assert problems[:4] == [None] * 4
    assert "docs/gone.md" in problems[4] and "no such file" in problems[4]
    assert "no heading with anchor #rigs" in problems[5]
    assert problems[6] is not None  # ../x.md: not here, and outside the repository
    assert len(problems) == 7  # inline code and code blocks hold no links
