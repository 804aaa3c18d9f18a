"""The import layers: model → profiles → engine → study → replay → cli, bench beside cli, the
base modules below everything and io at the edges, with no import cycle anywhere; the
developer's benchmark (``benchmarks/`` at the repository's root, not installed) above them
all, imported by none.

Every import of every module counts, at module level and inside functions (and under
``TYPE_CHECKING``): a function-level import hides a cycle from Python, not from this test.
"""

import ast
from pathlib import Path

import pytest

import campipe

ROOT = Path(campipe.__file__).parent
#: Below everything, importing no other layer (kernel_cache: where numba caches the kernels;
#: disk_cache: what else a process keeps for the next, beside them).
BASE = {
    "campipe",
    "campipe.units",
    "campipe.constants",
    "campipe.vocabulary",
    "campipe.errors",
    "campipe.kernel_cache",
    "campipe.disk_cache",
    "campipe.sources",
}
#: Layer → the layers its modules may import (their own included).
MAY_IMPORT: dict[str, set[str]] = {
    "base": {"base"},
    "io": {"base", "io"},  # file formats only: it takes and returns plain data
    "model": {"base", "model"},
    "profiles": {"base", "model", "profiles"},
    "engine": {"base", "model", "profiles", "engine"},
    "study": {"base", "io", "model", "profiles", "engine", "study"},
    "replay": {"base", "io", "model", "profiles", "engine", "study", "replay"},
    "bench": {"base", "model", "profiles", "engine", "study", "bench"},
    "plot": {"base", "io", "model", "profiles", "engine", "study", "plot"},
    "cli": {"base", "io", "model", "profiles", "engine", "study", "replay", "bench", "plot", "cli"},
}


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in sorted(ROOT.rglob("*.py"))}


def layer(module: str) -> str:
    if module in BASE:
        return "base"
    top = module.split(".")[1]
    return {"__main__": "cli"}.get(top, top)


def _lazy_exports(tree: ast.Module) -> set[int]:
    """Ids of the nodes inside the top package's module-level ``__getattr__`` (PEP 562): the
    public names it resolves on first use (``campipe.open_study``) are the package's face,
    not an import of its base layer."""
    return {
        id(inner)
        for node in tree.body
        if isinstance(node, ast.FunctionDef) and node.name == "__getattr__"
        for inner in ast.walk(node)
    }


def imports(module: str) -> set[str]:
    """The campipe modules ``module`` imports, anywhere in its text (the top package's lazy
    exports aside, see :func:`_lazy_exports`)."""
    path = MODULES[module]
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skip = _lazy_exports(tree) if module == "campipe" else set()
    out = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            for a in node.names:
                # `from package import submodule` imports the submodule
                out.add(f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base)
    return {m for m in out if m == "campipe" or m.startswith("campipe.")}


GRAPH = {m: imports(m) for m in MODULES}


def test_every_module_has_a_layer():
    assert {layer(m) for m in MODULES} <= set(MAY_IMPORT)
    assert all(target in MODULES for targets in GRAPH.values() for target in targets)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_module_imports_a_higher_layer(module):
    allowed = MAY_IMPORT[layer(module)]
    wrong = sorted(t for t in GRAPH[module] if layer(t) not in allowed)
    assert not wrong, f"{module} ({layer(module)}) imports {wrong}"


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module, or a module importing
    itself (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1 or v in graph[v]:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle():
    assert cycles(GRAPH) == []
    # nor between layers: the permitted imports themselves form no cycle
    assert cycles({name: may - {name} for name, may in MAY_IMPORT.items()}) == []


def test_the_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"e"}}
    assert sorted(cycles(graph)) == [["a", "b", "c"], ["e"]]


def test_function_level_imports_count():
    """The CLI imports the study layer inside its commands; the graph has those edges."""
    assert "campipe.study.execute" in GRAPH["campipe.cli"]


def test_the_package_exports_open_study_lazily():
    """``campipe.open_study`` resolves on first use; ``import campipe`` imports no layer."""
    import subprocess
    import sys

    code = (
        "import sys, campipe; assert not [m for m in sys.modules if m.startswith('campipe.')]; "
        "f = campipe.open_study; assert f.__module__ == 'campipe.study.open'"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


#: The developer's benchmark of campipe's own latencies and study layer, beside the package.
BENCHMARKS = ROOT.parent / "benchmarks"


def _top_imports(path: Path) -> set[str]:
    """Every module ``path`` imports, absolute, anywhere in its text."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            out.update(f"{node.module}.{a.name}" for a in node.names)
            out.add(node.module)
    return out


def test_nothing_in_campipe_imports_the_developer_benchmark():
    """campipe (campipe.bench included) runs without benchmarks/: an installed campipe has
    none."""
    wrong = {
        m: sorted(t for t in _top_imports(p) if t.split(".")[0] == "benchmarks")
        for m, p in MODULES.items()
    }
    assert not {m: t for m, t in wrong.items() if t}


def test_the_developer_benchmark_imports_campipe_from_above():
    """benchmarks/ may import any of campipe (it sits above the cli), and only modules that
    exist; it holds the study section's measurements, which campipe.bench no longer has."""
    files = sorted(BENCHMARKS.glob("*.py"))
    assert {p.stem for p in files} >= {"__init__", "study", "scaling", "goals", "pages"}
    used = set()
    for path in files:
        for target in _top_imports(path):
            if target.split(".")[0] == "campipe":
                used.add(target)
    assert {t for t in used if t in MODULES} >= {"campipe.bench.pages", "campipe.study.execute"}
    # an imported name, if not a module, belongs to a module that exists
    assert all(t in MODULES or t.rpartition(".")[0] in MODULES for t in used)
    assert "campipe.bench.study" not in MODULES
