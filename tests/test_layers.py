"""The import graph follows the layer order written in docs/architecture.md ("How the code is laid out").

A module may import modules of its own layer or of lower ones, never of a higher one; imports inside
functions count (they are dependencies too), and so do imports under `if TYPE_CHECKING:` (a type named
from a higher layer is one too: the preview draws the live session's snapshot from teleprev/status.py,
never from live), though not for the cycle checks. That device
plugins import nothing of teleprev but `teleprev.devices` is checked in tests/devices/test_plugin_api.py.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Lowest first. A package is placed whole, a ground-floor module alone; a subpackage placed on its own
# (live's rooms) belongs to its own entry, not to its parent's.
LAYERS: list[tuple[str, ...]] = [
    ("teleprev.errors", "teleprev.paths", "teleprev.config", "teleprev.numeric_platform", "teleprev.transforms",
     "teleprev.clock", "teleprev.topics", "teleprev.messages", "teleprev.status", "teleprev.corpus", "teleprev.kernels",
     "teleprev.thread_priority"),
    ("teleprev.robot", "teleprev.human", "teleprev.session", "teleprev.world"),
    ("teleprev.devices", "teleprev.retarget", "teleprev.noncollision", "teleprev.emulators"),
    ("teleprev.pipeline",),
    ("teleprev.rig", "teleprev.sides", "teleprev.assembly", "teleprev.bimanual"),
    ("teleprev.preview", "teleprev.export", "teleprev.study"),
    ("teleprev.live", "teleprev.live.core", "teleprev.live.view"),
    ("teleprev.live.record",),
    ("teleprev.live.replay", "teleprev.live.rollout"),
    ("teleprev.evaluation",),
    ("teleprev.cli",),
]
TOP = ("teleprev",)  # teleprev/__init__.py: the version and the numeric platform, importable from anywhere


def unit(module: str) -> str | None:
    """The layer entry a module belongs to (the most specific: its package, or itself on the ground floor)."""
    found = [entry for layer in LAYERS for entry in layer if module == entry or module.startswith(entry + ".")]
    return max(found, key=len, default=None)


def level(entry: str) -> int:
    return next(i for i, layer in enumerate(LAYERS) if entry in layer)


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    if parts[0] == "devices":
        parts = parts[1:]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _type_checking_blocks(tree: ast.AST) -> set[int]:
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for child in node.body:
                skip.update(id(n) for n in ast.walk(child))
    return skip


def imports(path: Path, type_checking: bool = False) -> list[tuple[int, str]]:
    """(line, imported module) for every import of teleprev code in a file (`type_checking`: those under
    `if TYPE_CHECKING:` too)."""
    tree = ast.parse(path.read_text(), str(path))
    skip = set() if type_checking else _type_checking_blocks(tree)
    me = module_name(path).split(".")
    package = me if path.name == "__init__.py" else me[:-1]
    found = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[: len(package) - node.level + 1] + ([base] if base else []))
            # `from teleprev import topics` imports the module teleprev.topics
            found += [(node.lineno, f"{base}.{a.name}" if unit(f"{base}.{a.name}") else base) for a in node.names]
    return [(line, m) for line, m in found if m.split(".")[0] in ("teleprev", "teleprev_devices")]


def files(folder: str) -> list[Path]:
    return sorted((ROOT / folder).rglob("*.py"))


def test_every_teleprev_module_has_a_layer():
    missing = [module_name(p) for p in files("teleprev") if module_name(p) not in TOP and unit(module_name(p)) is None]
    assert not missing, f"modules outside the layer table (add them to LAYERS and docs/architecture.md): {missing}"


def test_no_import_goes_up_a_layer():
    upward = []
    for path in files("teleprev"):
        me = unit(module_name(path))
        if me is None:
            continue
        for line, target in imports(path, type_checking=True):
            there = unit(target)
            if target in TOP or there is None or there == me:
                continue
            if level(there) > level(me):
                upward.append(f"{path.relative_to(ROOT)}:{line} ({me}) imports {target} ({there})")
    assert not upward, "imports that go up a layer:\n" + "\n".join(upward)


def unit_graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for path in files("teleprev"):
        me = unit(module_name(path))
        if me is not None:
            graph.setdefault(me, set()).update(
                u for _, t in imports(path) if (u := unit(t)) is not None and u != me and t not in TOP)
    return graph


def test_no_cycles_between_packages():
    """Within a layer, packages may use each other in one direction only."""
    graph = unit_graph()
    cycles = []
    for a, targets in graph.items():
        for b in targets:
            # a -> b, and b reaches a again
            seen, todo = set(), [b]
            while todo:
                n = todo.pop()
                if n == a:
                    cycles.append(f"{a} -> {b} -> ... -> {a}")
                    break
                if n not in seen:
                    seen.add(n)
                    todo.extend(graph.get(n, ()))
    assert not cycles, "package cycles:\n" + "\n".join(sorted(cycles))


@pytest.mark.parametrize("entry", [e for layer in LAYERS for e in layer])
def test_layer_entries_exist(entry):
    as_path = ROOT / Path(*entry.split("."))
    assert as_path.is_dir() or as_path.with_suffix(".py").is_file(), f"{entry} is in LAYERS but not in the tree"


def as_module(target: str) -> str | None:
    """The module an import names (`teleprev.errors.ConfigError` -> `teleprev.errors`), None outside the tree."""
    parts = target.split(".")
    while parts:
        base = ROOT / ("devices" if parts[0] == "teleprev_devices" else "") / Path(*parts)
        if base.with_suffix(".py").is_file() or (base / "__init__.py").is_file():
            return ".".join(parts)
        parts.pop()
    return None


def test_no_module_import_cycles():
    """No two modules need each other, not even through a function-local import."""
    graph: dict[str, set[str]] = {}
    for path in files("teleprev") + files("devices/teleprev_devices"):
        me = module_name(path)
        # a package's __init__ re-exporting its modules is not a cycle with them
        graph[me] = {m for _, t in imports(path) if (m := as_module(t)) and m != me and not m.startswith(me + ".")}
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    assert not cycles, "modules that import each other: " + "; ".join(" <-> ".join(c) for c in cycles)
