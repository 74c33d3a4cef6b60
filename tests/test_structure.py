"""The package's import graph (STYLE.md, "Shape of the code"): read from the source with ast, not by importing.

- no cycle among the imports made when a module is loaded;
- an import inside a function of another gnerun module is allowed only where it is listed below, with its reason,
  and none of them closes a cycle that the module-level imports leave open, except the listed ones;
- the layers: language <- game <- solvers <- runs, language <- log <- runs, and view reads log (and the solvers'
  failure statuses), never runs or game; only cli, at the top, imports everything.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "gnerun"
SHARED = {"gnerun", "gnerun.errors", "gnerun.files", "gnerun.threads"}  # importable from every layer

# layer -> the layers it may import (besides itself and SHARED)
LAYERS = {
    "language": set(),
    "game": {"language"},
    "solvers": {"game", "language"},
    "log": {"language"},
    "runs": {"solvers", "game", "language", "log"},
    "view": {"log", "solvers", "language"},  # solvers: the failure statuses of a logged sampling time
}

# (importer, imported) -> why the import is made inside a function
DEFERRED = {
    ("gnerun.cli", "*"): "the CLI loads a command's modules when it runs, so that `gnerun --help` is fast",
    ("gnerun.runs.sweep", "gnerun.runs.closed_loop"): "a sweep worker loads the run it makes",
    ("gnerun.runs.sweep", "gnerun.runs.solving"): "a sweep worker loads the run it makes",
    ("gnerun.runs.sweep", "gnerun.game.compile"): "a sweep worker loads the compiler of the game it shares",
    ("gnerun.runs.sweep", "gnerun.runs.interrupt"): "a worker process's signal handling, set up in the worker",
    ("gnerun.runs.solving", "*"): "the certificate and phase 1 load when a solve ends, and only where they are used",
    ("gnerun.solvers.certificate", "*"): "the best responses load their solvers when a player is checked",
}
# cycles closed by a deferred import, each as its sorted modules -> why it is still there
CYCLES: dict[tuple[str, ...], str] = {}


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


MODULES = _modules()


def _targets(module: str, node: ast.ImportFrom | ast.Import) -> list[str]:
    """The gnerun modules an import statement loads."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name.split(".")[0] == "gnerun"]
    if node.level:
        package = module if MODULES[module].name == "__init__.py" else module.rpartition(".")[0]
        base = package.split(".")[: len(package.split(".")) - node.level + 1]
        source = ".".join(base + ([node.module] if node.module else []))
    else:
        source = node.module or ""
    if source.split(".")[0] != "gnerun":
        return []
    return [f"{source}.{a.name}" if f"{source}.{a.name}" in MODULES else source for a in node.names]


def _type_checking(node: ast.AST) -> bool:
    return isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)


def _imports() -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    """Per module: the gnerun modules imported when it is loaded, and those imported inside its functions."""
    loaded: dict[str, set[str]] = {m: set() for m in MODULES}
    deferred: dict[str, set[str]] = {m: set() for m in MODULES}

    def visit(module: str, node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if _type_checking(child):
                continue  # annotations only: nothing is loaded
            if isinstance(child, ast.Import | ast.ImportFrom):
                (deferred if in_function else loaded)[module].update(_targets(module, child))
            visit(module, child, in_function or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda))

    for module, path in MODULES.items():
        visit(module, ast.parse(path.read_text()), False)
    return loaded, deferred


LOADED, DEFERRED_FOUND = _imports()


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w == v or w not in MODULES:
                continue
            if w not in index:
                connect(w)
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
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return out


def _layer(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 2 else None


def test_no_import_cycle_when_modules_load() -> None:
    assert _cycles(LOADED) == []


def test_imports_inside_functions_are_listed_with_their_reason() -> None:
    unlisted = sorted(f"{m} -> {t}" for m, targets in DEFERRED_FOUND.items() for t in targets
                      if t != m and (m, t) not in DEFERRED and (m, "*") not in DEFERRED)
    assert unlisted == [], "an import inside a function needs a reason in DEFERRED (or belongs at the top)"
    stale = sorted(f"{m} -> {t}" for m, t in DEFERRED if t != "*" and t not in DEFERRED_FOUND.get(m, set()))
    assert stale == [], "DEFERRED lists imports that are no longer made"


def test_no_import_inside_a_function_hides_a_cycle() -> None:
    graph = {m: LOADED[m] | DEFERRED_FOUND[m] for m in MODULES}
    assert {tuple(c) for c in _cycles(graph)} == set(CYCLES)


def test_layers_import_only_downwards() -> None:
    wrong = []
    for module in MODULES:
        layer = _layer(module)
        if layer is None:
            continue  # cli (the top) and the shared modules
        for target in LOADED[module] | DEFERRED_FOUND[module]:
            if target in SHARED or _layer(target) == layer:
                continue
            if _layer(target) not in LAYERS[layer]:
                wrong.append(f"{module} -> {target}")
    assert sorted(wrong) == []


def test_shared_modules_import_no_layer() -> None:
    for module in SHARED - {"gnerun"}:  # the package's __init__ loads its API lazily, by name
        assert {t for t in LOADED[module] | DEFERRED_FOUND[module] if t not in SHARED} == set(), module
