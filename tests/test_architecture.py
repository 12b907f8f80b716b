"""The package's shape, checked: imports flow one way and private names stay home.

Read from the source with :mod:`ast` (nothing is imported), so a cycle made by an
import inside a function counts as much as one at the top of a module: both make
a stage depend on a later one.

``KNOWN_CYCLES`` and ``KNOWN_PRIVATE`` list what issue 15 is still taking apart.
The tests fail on anything new *and* on an entry that no longer happens, so the
lists only shrink, and must be emptied by whoever fixes an entry.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"

# Strongly connected components of the import graph (sorted module names).
KNOWN_CYCLES: set[tuple[str, ...]] = set()

# (importing module, imported module, private name)
KNOWN_PRIVATE: set[tuple[str, str, str]] = set()


def _modules() -> dict[str, Path]:
    root = SRC / "servoscope"
    mods = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    return mods


def _target(mods: dict[str, Path], current: str, node: ast.ImportFrom) -> str | None:
    if not node.level:
        return node.module
    base = current.split(".")
    if mods[current].name != "__init__.py":
        base = base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _graph() -> tuple[dict[str, set[str]], set[tuple[str, str, str]]]:
    """Import edges between servoscope's modules, and private names crossing them."""
    mods = _modules()
    edges: dict[str, set[str]] = {m: set() for m in mods}
    private: set[tuple[str, str, str]] = set()
    for mod, path in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        aliases: dict[str, str] = {}  # local name -> servoscope module it is bound to
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                target = _target(mods, mod, node)
                if not target or not target.startswith("servoscope"):
                    continue
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    if sub in mods:  # `from package import module`
                        edges[mod].add(sub)
                        aliases[alias.asname or alias.name] = sub
                    elif target in mods:
                        edges[mod].add(target)
                        name = alias.name
                        if name.startswith("_") and not name.startswith("__") and target != mod:
                            private.add((mod, target, name))
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name in mods:
                        edges[mod].add(alias.name)
                        if alias.asname:
                            aliases[alias.asname] = alias.name
        # `module._name` on a module bound above (e.g. `tracker._bt601`).
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Attribute)
                and isinstance(node.value, ast.Name)
                and node.value.id in aliases
                and node.attr.startswith("_")
                and not node.attr.startswith("__")
            ):
                private.add((mod, aliases[node.value.id], node.attr))
    return edges, private


def _cycles(edges: dict[str, set[str]]) -> set[tuple[str, ...]]:
    """Tarjan's strongly connected components with more than one module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: set[tuple[str, ...]] = set()
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges[v]):
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
                found.add(tuple(sorted(component)))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def _without_packages(edges: dict[str, set[str]]) -> dict[str, set[str]]:
    # A package's __init__ re-exports its modules (the public surface); a module importing a
    # sibling through the package is not a cycle of stages, so edges into __init__ files count
    # only from outside the package.
    mods = set(edges)
    out: dict[str, set[str]] = {}
    for mod, targets in edges.items():
        keep = set()
        for t in targets:
            if t in mods and _modules()[t].name == "__init__.py" and mod.startswith(t + "."):
                continue
            keep.add(t)
        out[mod] = keep
    return out


@pytest.fixture(scope="module")
def graph():
    return _graph()


def test_the_checker_sees_a_cycle_and_a_private_name():
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(edges) == {("a", "b", "c")}
    assert _cycles({"a": {"b"}, "b": set()}) == set()


def test_no_new_import_cycle(graph):
    edges, _ = graph
    cycles = _cycles(_without_packages(edges))
    new = cycles - KNOWN_CYCLES
    gone = KNOWN_CYCLES - cycles
    assert not new, f"import cycles inside servoscope (an import pointing up the pipeline): {sorted(new)}"
    assert not gone, f"fixed, remove from KNOWN_CYCLES: {sorted(gone)}"


def test_no_new_private_name_across_modules(graph):
    _, private = graph
    new = private - KNOWN_PRIVATE
    gone = KNOWN_PRIVATE - private
    assert not new, f"private names imported across modules (make them public or move them): {sorted(new)}"
    assert not gone, f"fixed, remove from KNOWN_PRIVATE: {sorted(gone)}"


# Modules may grow to about 500 lines; a few were far larger when this was written.
MAX_LINES = 650
KNOWN_LARGE: set[str] = set()


def test_no_module_grows_past_the_limit():
    sizes = {m: len(p.read_text(encoding="utf-8").splitlines()) for m, p in _modules().items()}
    large = {m for m, n in sizes.items() if n > MAX_LINES}
    assert not (large - KNOWN_LARGE), f"split these (> {MAX_LINES} lines): {sorted(large - KNOWN_LARGE)}"
    assert not (KNOWN_LARGE - large), f"small enough now, remove from KNOWN_LARGE: {sorted(KNOWN_LARGE - large)}"


# A function may be long when it says why: its docstring has a line "Long because …".
MAX_FUNCTION_LINES = 80


def _long_functions_without_a_reason(source: str) -> list[tuple[str, int]]:
    """(name, code lines) of each function over MAX_FUNCTION_LINES lines of code (docstring not counted) with no reason."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        doc = ast.get_docstring(node)
        first = node.body[0]
        start = first.end_lineno + 1 if doc is not None else first.lineno
        length = node.end_lineno - start + 1
        if length > MAX_FUNCTION_LINES and "Long because" not in (doc or ""):
            found.append((node.name, length))
    return found


def test_the_length_checker_counts_code_not_docstrings():
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES + 1))
    assert _long_functions_without_a_reason(f"def f():\n{body}\n") == [("f", MAX_FUNCTION_LINES + 1)]
    assert _long_functions_without_a_reason(f'def f():\n    """Long because it must."""\n{body}\n') == []
    doc = "\n".join("    text" for _ in range(MAX_FUNCTION_LINES))
    assert _long_functions_without_a_reason(f'def f():\n    """Short.\n{doc}\n    """\n    return 1\n') == []


def test_long_functions_say_why():
    unexplained = {m: found for m, p in _modules().items()
                   if (found := _long_functions_without_a_reason(p.read_text(encoding="utf-8")))}
    assert not unexplained, (f"functions over {MAX_FUNCTION_LINES} lines of code without 'Long because …' in their "
                             f"docstring (split them, or say why not): {unexplained}")


# Defaults with one home (servoscope/defaults.py, issue 30): the timestamp choices are spelled out
# nowhere else, and no function, command-line option or file reader gives the settling time or a
# dwell's shortest input a number of its own (they disagreed: 0.5, 1.0 and 0.0 against 3.0).
_TIMESTAMP_WORDS = {"middle", "start", "end"}
_ONE_HOME = {"settle_s", "min_seconds", "--settle", "--min-seconds"}


def _defaults_spelled_out(source: str) -> list[str]:
    """Where `source` spells out a default that lives in servoscope.defaults."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if (isinstance(node, (ast.Tuple, ast.List, ast.Set)) and node.elts
                and all(isinstance(e, ast.Constant) and isinstance(e.value, str) for e in node.elts)
                and {e.value for e in node.elts} == _TIMESTAMP_WORDS):
            found.append(f"line {node.lineno}: the timestamp choices (defaults.TIMESTAMPS)")
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            a = node.args
            positional = a.posonlyargs + a.args
            pairs = list(zip(positional[len(positional) - len(a.defaults):], a.defaults))
            pairs += [(arg, d) for arg, d in zip(a.kwonlyargs, a.kw_defaults) if d is not None]
            found += [f"line {node.lineno}: {node.name}({arg.arg}={d.value!r})" for arg, d in pairs
                      if arg.arg in _ONE_HOME and isinstance(d, ast.Constant)]
        if isinstance(node, ast.Call) and any(isinstance(x, ast.Constant) and x.value in _ONE_HOME for x in node.args):
            # .get("settle_s", 0.5), @click.option("--settle", "settle_s", default=1.0)
            values = [x for x in node.args[1:] if not (isinstance(x, ast.Constant) and isinstance(x.value, str))]
            values += [k.value for k in node.keywords if k.arg == "default"]
            found += [f"line {node.lineno}: default {v.value!r}" for v in values
                      if isinstance(v, ast.Constant) and isinstance(v.value, (int, float))]
    return found


def test_the_defaults_checker_sees_them():
    assert _defaults_spelled_out('T = ("start", "middle", "end")\nx = ["middle", "start"]\n') == [
        "line 1: the timestamp choices (defaults.TIMESTAMPS)"]
    assert _defaults_spelled_out("def f(a, settle_s=1.0, *, min_seconds=3.0): pass\n") == [
        "line 1: f(settle_s=1.0)", "line 1: f(min_seconds=3.0)"]
    assert _defaults_spelled_out('s = d.get("settle_s", 0.5)\n@option("--settle", "settle_s", default=1.0)\ndef g(): pass\n') == [
        "line 1: default 0.5", "line 2: default 1.0"]
    assert _defaults_spelled_out('s = d.get("settle_s", SETTLE_S)\ndef f(settle_s=SETTLE_S): pass\n') == []


def test_defaults_have_one_home():
    spelled = {m: found for m, p in _modules().items()
               if m != "servoscope.defaults" and (found := _defaults_spelled_out(p.read_text(encoding="utf-8")))}
    assert not spelled, f"defaults spelled out outside servoscope/defaults.py (use its names): {spelled}"
