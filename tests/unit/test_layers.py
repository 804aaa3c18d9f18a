"""The import layers: model → profiles → engine → study → replay → cli, bench beside cli, the
base modules below everything and io at the edges, with no import cycle anywhere; the
developer's benchmark (``benchmarks/`` at the repository's root, not installed) above them
all, imported by none.

Inside study, its packages along the user's path: the where language, then spec, archive, run
and query (run and query each above the archive, neither importing the other), the package's
face and ``campipe onset`` above them all.

Every import of every module counts, at module level and inside functions (and under
``TYPE_CHECKING``): a function-level import hides a cycle from Python, not from this test.
"""

import ast
from pathlib import Path

import pytest

import campipe

ROOT = Path(campipe.__file__).parent
#: Below everything, importing no other layer (kernel_cache: where numba caches the kernels;
#: disk_cache: what else a process keeps for the next, beside them; memory: a command's
#: allocator).
BASE = {
    "campipe.memory",
    "campipe",
    "campipe.units",
    "campipe.constants",
    "campipe.vocabulary",
    "campipe.errors",
    "campipe.kernel_cache",
    "campipe.disk_cache",
    "campipe.sources",
}
#: The study's layers, lowest first (``study``: the package itself and ``campipe onset``).
STUDY = ("study.where", "study.spec", "study.archive", "study.run", "study.query", "study")
BELOW_STUDY = {"base", "io", "model", "profiles", "engine"}
#: Layer → the layers its modules may import (their own included).
MAY_IMPORT: dict[str, set[str]] = {
    "base": {"base"},
    "io": {"base", "io"},  # file formats only: it takes and returns plain data
    "model": {"base", "model"},
    "profiles": {"base", "model", "profiles"},
    "engine": {"base", "model", "profiles", "engine"},
    # the --where language: a spec's replay.where and plots are written in it
    "study.where": {"base", "study.where"},
    # checking and expanding a spec: nothing of the archive, the run or the queries
    "study.spec": BELOW_STUDY | {"study.where", "study.spec"},
    "study.archive": BELOW_STUDY | {"study.spec", "study.archive"},
    "study.run": BELOW_STUDY | {"study.spec", "study.archive", "study.run"},
    "study.query": BELOW_STUDY | {"study.where", "study.spec", "study.archive", "study.query"},
    "study": BELOW_STUDY | set(STUDY),
    "replay": BELOW_STUDY | set(STUDY) | {"replay"},
    "bench": BELOW_STUDY - {"io"} | set(STUDY) | {"bench"},
    "plot": BELOW_STUDY | set(STUDY) | {"plot"},
    "cli": BELOW_STUDY | set(STUDY) | {"replay", "bench", "plot", "cli"},
}


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in sorted(ROOT.rglob("*.py"))}


def layer(module: str) -> str:
    if module in BASE:
        return "base"
    parts = module.split(".")
    if parts[1] == "study" and len(parts) > 2 and f"study.{parts[2]}" in STUDY:
        return f"study.{parts[2]}"
    return {"__main__": "cli"}.get(parts[1], parts[1])


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
    assert "campipe.study.run.execute" in GRAPH["campipe.cli.study"]


def test_the_package_exports_open_study_lazily():
    """``campipe.open_study`` resolves on first use; ``import campipe`` imports no layer."""
    import subprocess
    import sys

    code = (
        "import sys, campipe; assert not [m for m in sys.modules if m.startswith('campipe.')]; "
        "f = campipe.open_study; assert f.__module__ == 'campipe.study.archive.open'"
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
    assert {t for t in used if t in MODULES} >= {"campipe.bench.pages", "campipe.study.run.execute"}
    # an imported name, if not a module, belongs to a module that exists
    assert all(t in MODULES or t.rpartition(".")[0] in MODULES for t in used)
    assert "campipe.bench.study" not in MODULES


def reached(start: set[str]) -> set[str]:
    """The modules ``start`` imports, directly or through others (themselves included)."""
    seen, todo = set(start), list(start)
    while todo:
        for target in GRAPH[todo.pop()] - seen:
            seen.add(target)
            todo.append(target)
    return seen


def in_layers(*layers: str) -> set[str]:
    return {m for m in MODULES if layer(m) in layers}


#: Modules that read or write archive files, or hold the queries over them.
ARCHIVE_FILES = {"campipe.io.archive", "campipe.io.batch_file"}


def test_the_study_packages_point_one_way():
    """Along the user's path: the spec imports nothing of the archive, the run or the
    queries, not even through another module; the archive's layout nothing of the run or
    the queries; the queries nothing of the run, the run nothing of the queries. Broken
    copy, run: a `from campipe.study.archive.layout import CASE_ID` in spec/expand.py fails
    the first assertion (and the layer test above)."""
    later = {"study.archive", "study.run", "study.query", "study"}
    from_spec = reached(in_layers("study.spec", "study.where"))
    assert not {m for m in from_spec if layer(m) in later} | (from_spec & ARCHIVE_FILES)
    from_archive = reached(in_layers("study.archive"))
    assert not {m for m in from_archive if layer(m) in {"study.run", "study.query", "study"}}
    assert not {m for m in reached(in_layers("study.query")) if layer(m) == "study.run"}
    assert not {m for m in reached(in_layers("study.run")) if layer(m) == "study.query"}
    # and the table says so: a later package never among those an earlier one may import
    for earlier, forbidden in [
        ("study.spec", later),
        ("study.archive", {"study.run", "study.query", "study"}),
        ("study.query", {"study.run", "study"}),
        ("study.run", {"study.query", "study"}),
    ]:
        assert not MAY_IMPORT[earlier] & forbidden, earlier


SPEC = Path(__file__).parents[2] / "studies" / "separation-map.yaml"
#: What checking a spec must not load: the archive's and the run's modules, the queries over
#: an archive, the libraries that read one, and the compiler (pint may load dask's config).
NOT_FOR_A_SPEC = (
    "campipe.study.archive",
    "campipe.study.query",
    "campipe.study.run.",  # the run's own modules (its batch sizes, run.sizing, are counted)
    "campipe.io.archive",
    "campipe.io.batch_file",
    "xarray",
    "netCDF4",
    "numba",
)


def _loaded(code: str) -> tuple[list[str], list[str]]:
    """Run ``code`` in a fresh interpreter: (the campipe modules it loaded, those of them and
    the libraries in NOT_FOR_A_SPEC)."""
    import subprocess
    import sys

    code += (
        "\nimport sys; print(' '.join(sorted(m for m in sys.modules if m.startswith('campipe'))))"
        "\nprint(' '.join(sorted(sys.modules)))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    ours, every = done.stdout.splitlines()[-2:]
    wrong = [
        m
        for m in every.split()
        if m.startswith(NOT_FOR_A_SPEC)
        and m != "campipe.study.run.sizing"
        or m.split(".")[0] in NOT_FOR_A_SPEC
    ]
    return ours.split(), wrong


def test_checking_a_spec_loads_neither_the_archive_nor_the_run_nor_the_queries():
    """``load_study`` (check and expand) and ``campipe validate --no-estimate``, on a spec
    with a replay selection and plots (their ``where`` is parsed and checked against the
    columns to come, in the where language, campipe.study.where), in a fresh interpreter.
    Broken copy, run: validate importing run.batches for its batch count fails it."""
    assert "replay:" in SPEC.read_text() and "plots:" in SPEC.read_text()
    ours, wrong = _loaded(f"from campipe.study import load_study; load_study({str(SPEC)!r})")
    assert "campipe.study.spec.expand" in ours and "campipe.study.where" in ours
    assert wrong == []
    ours, wrong = _loaded(
        "from campipe.cli import main\n"
        f"main(['validate', '--no-estimate', {str(SPEC)!r}], standalone_mode=False)"
    )
    assert "campipe.study.spec.check" in ours and "campipe.study.run.sizing" in ours
    assert wrong == []


#: The house's size limit of a module (issue 33): past it a module holds more than one idea.
MAX_MODULE_LINES = 800


def test_no_module_is_longer_than_the_house_limit():
    """Every module of campipe and of the developer's benchmark stays under 800 lines (the
    function limit, McCabe 25, is ruff's C901 in pyproject.toml). Broken copy: the engine's
    modal-exact kernel as the one 1169-line module it was."""
    paths = [*MODULES.values(), *sorted(BENCHMARKS.glob("*.py"))]
    lines = {str(p.relative_to(ROOT.parent)): len(p.read_text("utf-8").splitlines()) for p in paths}
    assert not {name: n for name, n in lines.items() if n > MAX_MODULE_LINES}
    assert len(lines) > 100  # every module was read
