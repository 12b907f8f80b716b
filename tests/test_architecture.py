"""The package's shape, checked: imports flow one way and private names stay home.

Read from the source with :mod:`ast` (nothing is imported), so a cycle made by an
import inside a function counts as much as one at the top of a module: both make
a stage depend on a later one.

The stage order (issue 30) is one table, ``STAGE_RANK``: every top-level module or package
of servoscope has a rank, and imports go only down it.

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


# The stage order (issue 30): each top-level module or package of servoscope (its *unit*) and its
# rank. A unit imports only units of a lower rank; units of one rank are peers and import neither
# each other nor anything above. From the bottom: the foundation every stage shares; the stages in
# the order a video flows through them (video → markers → camera → angle → sysid: markers gives
# pixel centroids and LED levels, the camera stage undistorts, times and maps them into the blade's
# plane, the angle stage makes angles of them, sysid fits them); the pipeline, which runs stages
# together for one video (track_video, a track's plane view, the overlay video); then what drives
# whole campaigns (its manifest too); the twin and the rig, which write campaigns, and the report,
# which shows one; the command line and the benchmarks on top.
# A new top-level module gets a row here (the test below fails until it has one). No exemptions.
STAGE_RANK: dict[str, int] = {
    # foundation
    "servoscope": 0,  # the package itself: __version__ and a lazy table of names; it imports nothing
    "errors": 0,
    "results": 1,
    "defaults": 1,
    "numbers": 1,  # a value shown to its uncertainty's precision: every view's numbers
    "_io": 2,
    "parameters": 2,  # above numbers: a parameter written as text
    # the stages
    "video": 3,
    "markers": 4,
    "camera": 5,
    "angle": 6,
    "sysid": 7,
    # the stages run together
    "pipeline": 8,
    # above the pipeline
    "campaign": 9,
    "simulate": 10,
    "rig": 10,
    "report": 10,
    # the command line and the benchmarks
    "cli_options": 11,
    "cli_plane": 11,
    "cli_tables": 11,
    "cli_track_checks": 11,
    "bench_process": 11,
    "bench_mono": 12,
    "bench": 13,
    "cli": 13,
    "__main__": 14,
}


def _unit(module: str) -> str:
    """The top-level module or package a servoscope module belongs to (``servoscope`` for the package)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def _against_the_order(edges: dict[str, set[str]], rank: dict[str, int]) -> tuple[set[str], list[tuple[str, str]]]:
    """Units missing from ``rank``, and each import (importer, imported) to a unit of the same or a higher rank."""
    unranked = {_unit(m) for m in edges} - set(rank)
    wrong = sorted((m, t) for m, targets in edges.items() for t in targets
                   if _unit(m) != _unit(t) and _unit(m) in rank and _unit(t) in rank
                   and rank[_unit(t)] >= rank[_unit(m)])
    return unranked, wrong


def _imports_between(edges: dict[str, set[str]], a: str, b: str) -> list[tuple[str, str]]:
    """Every import from unit ``a`` into unit ``b``."""
    return sorted((m, t) for m, targets in edges.items() for t in targets if _unit(m) == a and _unit(t) == b)


def test_the_order_checker_sees_an_import_up_and_a_missing_rank():
    edges = {
        "servoscope.video.reader": {"servoscope.errors", "servoscope.video.frames"},
        "servoscope.video.frames": set(),
        "servoscope.video.overlay": {"servoscope.camera.model"},  # up: video draws with the camera
        "servoscope.camera.model": {"servoscope.video.reader", "servoscope.errors"},
        "servoscope.camera.lens": {"servoscope.camera.model"},
        "servoscope.simulate.render": {"servoscope.rig.plan"},  # a peer: the same rank
        "servoscope.rig.plan": set(),
        "servoscope.errors": set(),
        "servoscope.extra": {"servoscope.errors"},  # not in the table
    }
    rank = {"errors": 0, "video": 1, "camera": 2, "simulate": 3, "rig": 3}
    unranked, wrong = _against_the_order(edges, rank)
    assert unranked == {"extra"}
    assert wrong == [("servoscope.simulate.render", "servoscope.rig.plan"),
                     ("servoscope.video.overlay", "servoscope.camera.model")]
    assert _imports_between(edges, "video", "camera") == [("servoscope.video.overlay", "servoscope.camera.model")]
    assert _imports_between(edges, "camera", "video") == [("servoscope.camera.model", "servoscope.video.reader")]
    assert _unit("servoscope") == "servoscope" and _unit("servoscope.cli") == "cli"
    del edges["servoscope.video.overlay"], edges["servoscope.simulate.render"], edges["servoscope.extra"]
    assert _against_the_order(edges, rank) == (set(), [])


def test_imports_follow_the_stage_order(graph):
    edges, _ = graph
    unranked, wrong = _against_the_order(edges, STAGE_RANK)
    assert not unranked, f"give these a row in STAGE_RANK (tests/test_architecture.py): {sorted(unranked)}"
    assert not wrong, ("imports against the stage order (a stage importing a later one or a peer: move the code "
                       f"to the layer that needs both, e.g. servoscope.pipeline): {wrong}")


def test_the_stages_before_the_camera_do_not_import_it(graph):
    """video and camera do not import each other (only camera reads video); markers imports neither camera nor angle."""
    edges, _ = graph
    video_to_camera = _imports_between(edges, "video", "camera")
    camera_to_video = _imports_between(edges, "camera", "video")
    assert not (video_to_camera and camera_to_video), (
        f"video and camera import each other: {video_to_camera}, {camera_to_video}")
    assert not video_to_camera, f"video imports camera (the camera stage comes after video): {video_to_camera}"
    for later in ("camera", "angle"):
        found = _imports_between(edges, "markers", later)
        assert not found, f"markers imports {later} (markers gives pixel centroids; servoscope.pipeline combines): {found}"


# No module over 600 lines (issue 30): split by meaning before that.
MAX_LINES = 600
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
