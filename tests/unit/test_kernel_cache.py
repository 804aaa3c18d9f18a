"""campipe's kernel cache (``campipe.kernel_cache``): a fresh copy of campipe at another path
loads the kernels an earlier copy compiled, and an edit to any file the kernels compile from
(not only the kernel's own) makes them compile again."""

import copy
import json
import os
import shutil
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np
import pytest

from campipe import kernel_cache
from campipe.engine import batch

#: Run in a copy of campipe: the lift at θ = 0 of a harmonic cam through ``batch.cam_at`` (a
#: small kernel, about a second to compile), then where its cache is and whether it was
#: compiled (a cache miss) or loaded (a hit), and whether campipe's inliner was set up.
PROBE = """
import json, campipe
from campipe.engine import batch
from campipe.profiles import harmonic
from campipe.profiles.packed import pack
lift = batch.cam_at(pack([harmonic(0.0254)]), 0.0)[0].tolist()
from numba.core.inline_closurecall import InlineWorker
print(json.dumps({
    "package": campipe.__file__,
    "inliner": hasattr(InlineWorker.inline_function, "__wrapped__"),
    "cache": batch.cam_at._cache._cache_path,
    "hits": sum(batch.cam_at.stats.cache_hits.values()),
    "misses": sum(batch.cam_at.stats.cache_misses.values()),
    "lift": lift,
}))
"""


def _copy(tmp_path: Path, name: str) -> Path:
    root = tmp_path / name
    shutil.copytree(
        kernel_cache.ROOT, root / "campipe", ignore=shutil.ignore_patterns("__pycache__")
    )
    return root


def _probe(copy: Path, cache: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(copy), "NUMBA_CACHE_DIR": str(cache)}
    out = subprocess.run(
        [sys.executable, "-c", PROBE], cwd=copy, env=env, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.splitlines()[-1])


def test_a_fresh_copy_loads_what_another_compiled_and_an_edit_recompiles(tmp_path):
    """Three copies of campipe at three paths share one cache folder. The first compiles
    ``cam_at``; the second, identical, loads it (numba's own cache, beside each copy's source,
    would compile again); the third has a comment added to ``engine/common.py``, a file
    ``cam_at``'s module imports but that does not define it, and compiles again (numba's
    per-file stamp would have loaded the first copy's). The second, loading only, marks the
    folder used.

    Broken copy: with :func:`kernel_cache.install` doing nothing, the second copy compiles
    (``misses`` 1); with :data:`kernel_cache.SOURCES` holding only the kernel's own file, the
    third loads (``hits`` 1)."""
    cache = tmp_path / "cache"
    first, second, edited = (_copy(tmp_path, n) for n in ("first", "second", "edited"))
    common = edited / "campipe" / "engine" / "common.py"
    common.write_text(common.read_text() + "\n# an edit\n")

    a = _probe(first, cache)
    folder = Path(a["cache"]).parent  # the kernel source's folder (cam_at's is its engine/)
    hours_ago = time.time() - 7200
    os.utime(folder, (hours_ago, hours_ago))
    b = _probe(second, cache)
    assert folder.stat().st_mtime > hours_ago + 3600  # marked used by a load (prune keeps it)
    c = _probe(edited, cache)
    assert a["package"].startswith(str(first)) and b["package"].startswith(str(second))
    assert (a["misses"], a["hits"]) == (1, 0)
    assert (b["misses"], b["hits"]) == (0, 1)
    assert (c["misses"], c["hits"]) == (1, 0)
    assert a["inliner"] and not b["inliner"]  # set up to compile only when compiling
    assert a["cache"] == b["cache"] != c["cache"]
    assert Path(a["cache"]).is_relative_to(cache / "campipe")
    assert a["lift"] == b["lift"] == c["lift"]
    assert a["lift"][0] == pytest.approx(0.0254 / 2, rel=1e-12)  # θ = 0 is mid-lift


def test_the_source_hash_covers_the_kernel_sources_and_nothing_else(tmp_path):
    """An edit to the engine, the profiles, the model or the vocabulary changes the hash;
    one to the study layer does not (it compiles nothing)."""
    root = _copy(tmp_path, "copy") / "campipe"
    base = kernel_cache.hash_sources(root)
    assert base == kernel_cache.source_hash()  # the copy is this campipe
    (root / "study" / "query.py").write_text("# edited\n")
    assert kernel_cache.hash_sources(root) == base
    for name in ("engine/steady.py", "profiles/packed.py", "model/spring.py", "vocabulary.py"):
        path = root / name
        text = path.read_text()
        path.write_text(text + "\n")
        assert kernel_cache.hash_sources(root) != base, name
        path.write_text(text)
    assert kernel_cache.hash_sources(root) == base


def test_prune_keeps_the_newest_and_those_in_use(tmp_path):
    """Of six kernel-source folders, the three newest stay; of the three older, the one
    touched within the last hour stays too; a folder not named like a kernel source is
    never touched."""
    now = time.time()
    ages = [10, 20, 30, 40, 5000, 9000]  # seconds since last change, newest first
    names = [f"{i:016x}" for i in range(len(ages))]
    for name, age in zip(names, ages, strict=True):
        (tmp_path / name).mkdir()
        os.utime(tmp_path / name, (now - age, now - age))
    (tmp_path / "not-a-source").mkdir()
    os.utime(tmp_path / "not-a-source", (now - 1e6, now - 1e6))
    removed = kernel_cache.prune(tmp_path, keep=3, now=now)
    assert sorted(p.name for p in removed) == names[4:]
    assert sorted(p.name for p in tmp_path.iterdir()) == [*names[:4], "not-a-source"]


def test_this_process_caches_its_kernels_in_the_kernel_cache():
    """The kernels of this very process (engine and profiles alike) cache under this
    source's folder, not in ``__pycache__``."""
    from campipe.profiles import packed

    folder = kernel_cache.cache_folder()
    assert Path(batch.cam_at._cache._cache_path) == folder / "engine"
    assert Path(packed.evaluate_packed._cache._cache_path) == folder / "profiles"


def test_compiling_ahead_compiles_the_signatures_a_run_calls(monkeypatch):
    """A first run compiles modal-exact's kernel ahead from the types ``batch.integrator_types``
    gives, found without running the start's kernels
    (``kernels.compile_kernels``); the quasi-static kernel is called from the batch's starts
    and from the trains' valve references. Each must be called with the types it was compiled
    for, or the run compiles it again (about 15 s for modal-exact). Checked here on the types
    of every call a run makes, over batches that differ in what could change a type: a seat,
    form closure, restitution, a refined train (more coordinates), both starts, both
    ``full_state``. Broken copies, run: ``integrator_types`` with float zeta (modal-exact's
    types differ); the quasi-static start's held mask broadcast, as it was (two signatures).
    """
    from numba.core.typing.typeof import Purpose, typeof

    from campipe.engine import contact, exact
    from campipe.engine.batch import Case, RunSettings, run_batch
    from campipe.model import thesis_train
    from campipe.profiles import harmonic

    calls: dict[str, list[tuple]] = {"exact": [], "quasi-static": []}

    def recording(name, kernel):
        def record(*args):
            calls[name].append(tuple(typeof(a, Purpose.argument) for a in args))
            return kernel(*args)

        return record

    monkeypatch.setattr(exact, "modal_exact_batch", recording("exact", exact.modal_exact_batch))
    monkeypatch.setattr(
        batch, "quasi_static_batch", recording("quasi-static", contact.quasi_static_batch)
    )
    monkeypatch.setattr(
        contact, "quasi_static_batch", recording("quasi-static", contact.quasi_static_batch)
    )
    batch.prepare.cache_clear()  # so that the valve references are computed again
    cam = harmonic(0.0254)
    speed = 9000 * 2 * 3.141592653589793 / 60
    train = thesis_train()
    batches = [
        [Case(train, cam, speed)],
        [Case(train, cam, speed, seat=0.00254), Case(train, cam, 1.2 * speed)],
        [Case(train, cam, speed, closure="form")],
        [Case(train.replace(seat_restitution=0.5), cam, speed, seat=0.00254)],
        [Case(train.replace(spring_elements=3), cam, speed), Case(train, cam, speed)],
    ]
    expected = []
    for cases in batches:
        for start in ("periodic", "quasi-static"):
            for full_state in (False, True):
                settings = RunSettings(revolutions=0.05, warmup=0, start=start)
                expected.append(batch.integrator_types(cases, settings, full_state))
                run_batch(cases, settings, full_state=full_state)
    assert calls["exact"] == expected
    assert len(calls["quasi-static"]) > len(batches) and len(set(calls["quasi-static"])) == 1


#: Run in a fresh process: the kernels of runs of each integrator and start, with and without a
#: seat, form closure and restitution, the helpers a first run compiles ahead, the steady state
#: and the onset's search; then every campipe kernel that holds more than one compiled
#: signature, with the arguments that differ.
ONE_SIGNATURE = """
import json, math
import numba
from campipe.engine import batch, contact, closed_form, common, exact, modal, newmark
from campipe.engine import periodic, steady
from campipe.engine.batch import Case, RunSettings, run_batch
from campipe.model import thesis_train
from campipe.profiles import harmonic, packed
train, cam, w = thesis_train(), harmonic(0.0254), 9000 * math.pi / 30
cases = [Case(train, cam, w), Case(train, cam, 1.3 * w, seat=0.00254),
         Case(train, cam, w, closure="form"),
         Case(train.replace(seat_restitution=0.5), cam, 1.3 * w, seat=0.00254)]
for integrator, dt, n in (("modal-exact", None, 4), ("newmark-linear", 1e-6, 3)):
    for start in ("periodic", "quasi-static"):  # (newmark-linear refuses restitution)
        run_batch(cases[:n], RunSettings(revolutions=1.5, warmup=0, start=start,
                                         integrator=integrator, dt=dt), on_failure="record")
ahead = batch.integrator_types(cases, RunSettings(revolutions=1.5, warmup=0), False)
for helper, signature in exact.ahead_signatures(ahead).items():  # as a first run compiles
    helper.compile(signature)
periodic.steady_state(cases[:1])
periodic.onset_speeds(cases[:1], 6000 * math.pi / 30, 14000 * math.pi / 30, 1.0)
many = {}
for module in (batch, contact, closed_form, common, exact, modal, newmark, steady, packed):
    for name, kernel in vars(module).items():
        if isinstance(kernel, numba.core.registry.CPUDispatcher) and len(kernel.signatures) > 1:
            sigs = kernel.signatures
            many[f"{kernel.py_func.__module__}.{name}"] = [
                [str(s[i]) for s in sigs] for i in range(len(sigs[0]))
                if len({str(s[i]) for s in sigs}) > 1
            ]
# A helper of its own (no CPython wrapper) that takes one of the batch's named tuples by
# value is compiled with a parameter for every scalar of its arrays (``common.by_ref``).
by_value = sorted(
    f"{kernel.py_func.__module__}.{name}"
    for module in (batch, contact, closed_form, common, exact, modal, newmark, steady, packed)
    for name, kernel in vars(module).items()
    if isinstance(kernel, numba.core.registry.CPUDispatcher)
    and kernel.targetoptions.get("no_cpython_wrapper")
    and any(isinstance(t, numba.types.BaseNamedTuple) for s in kernel.signatures for t in s)
)
print(json.dumps({"more than one signature": many, "named tuples by value": by_value}))
"""


@pytest.mark.slow
def test_no_kernel_is_compiled_once_per_constant_it_is_called_with(tmp_path):
    """A kernel of its own that another calls with a Python int or bool constant is compiled
    once per value (numba types the constant as a literal), each compile a second or more of
    a first run: ``steady._turn_minimum`` was compiled three times, ``record_event`` three.
    Runs of both integrators and starts, the steady state and the onset's search must leave
    each kernel with one signature; so must the helpers a first run compiles ahead for
    modal-exact's types (``exact.ahead_signatures``), or the kernel compiles them again.
    Only a compile shows it (a kernel loaded from the cache brings its callees along, their
    dispatchers untouched), so this compiles every kernel on an empty cache, about a minute:
    ``slow``. The same compiles show every helper of its own taking no named tuple by value
    (``common.by_ref``). Broken copies, run: ``exact._drop_decayed`` counting from the
    constant 0 again (``_keep_column`` gets two signatures); ``ahead_signatures`` giving
    ``first`` as int32 (``_apply_event`` gets two); ``closed_form.held_inputs`` taking the
    packed profiles' tuple again (listed)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    out = subprocess.run(
        [sys.executable, "-c", ONE_SIGNATURE], capture_output=True, text=True, check=True, env=env
    )
    found = json.loads(out.stdout.splitlines()[-1])
    assert found == {"more than one signature": {}, "named tuples by value": []}


#: A helper inlined twice into a kernel, with branches (several blocks of IR) and a loop.
INLINED = """
import numba

@numba.njit(inline="always")
def clip(x, lo, hi):
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x

@numba.njit
def kernel(a):
    total = 0.0
    for x in a:
        total += clip(x, -1.0, 1.0) * clip(2.0 * x, 0.0, 3.0) + x
    return total
"""


def _inlining_module(name: str):
    module = types.ModuleType(name)
    exec(compile(INLINED, f"<{name}>", "exec"), module.__dict__)  # test code, not input
    return module


def test_campipe_helpers_are_inlined_without_copying_their_ir(monkeypatch):
    """Once campipe compiles, numba inlines campipe's ``inline="always"`` helpers from their
    fresh IR without deep-copying it (``kernel_cache._inline_without_copies``), and still
    copies any other package's: counted here by a deep copy of an IR block that records
    itself. The blocks spliced in are plain blocks again, and both kernels give what the same
    Python code gives.

    Broken copy: with the helper's blocks copied (the method not replaced), the campipe
    module's count is above zero; with the replacement applied to every package, the other
    module's count is zero."""
    from numba.core import inline_closurecall, ir

    kernel_cache._inline_without_copies()
    assert hasattr(inline_closurecall.InlineWorker.inline_function, "__wrapped__")
    copied: list[object] = []

    def deepcopy(block, memo):  # numba's default deep copy of a block, counted
        copied.append(block)
        new = copy.copy(block)
        memo[id(block)] = new
        new.__dict__.update(copy.deepcopy(block.__dict__, memo))
        return new

    monkeypatch.setattr(ir.Block, "__deepcopy__", deepcopy, raising=False)
    spliced: list[object] = []
    inline_ir = inline_closurecall.InlineWorker.inline_ir

    def spy(self, caller_ir, block, i, callee_ir, *args, **kwargs):
        spliced.extend(callee_ir.blocks.values())
        return inline_ir(self, caller_ir, block, i, callee_ir, *args, **kwargs)

    monkeypatch.setattr(inline_closurecall.InlineWorker, "inline_ir", spy)
    a = np.linspace(-2.0, 3.0, 23)
    counts = {}
    for name in ("campipe._inlining_probe", "elsewhere._inlining_probe"):
        module = _inlining_module(name)
        copied.clear()
        assert module.kernel(a) == module.kernel.py_func(a)
        counts[name] = len(copied)
    assert spliced and all(type(b) is ir.Block for b in spliced)  # plain blocks once spliced
    assert counts["campipe._inlining_probe"] == 0
    assert counts["elsewhere._inlining_probe"] > 4  # two sites, each of several blocks, twice


def test_the_second_process_reports_and_ends_at_once(monkeypatch):
    """The second process of a first run compiles with the types it is sent, reports (None,
    or why it failed) and ends with ``os._exit``, skipping a compiled numba's teardown (a few
    tenths of a second that the first process would wait for). Broken copies, run: a failure
    not reported (the first would wait on a closed pipe for nothing it can log); the exit
    left out."""
    from campipe.engine import kernels

    class Ended(Exception):
        pass

    class Pipe:
        def __init__(self):
            self.sent, self.closed = [], False

        def recv(self):
            return "types"

        def send(self, value):
            self.sent.append(value)

        def close(self):
            self.closed = True

    def exit_now(code):
        raise Ended(code)

    compiled = []
    monkeypatch.setattr(os, "_exit", exit_now)
    monkeypatch.setattr(kernels, "_start_kernels", lambda *args: compiled.append(args))
    pipe = Pipe()
    with pytest.raises(Ended):
        kernels._second_process(pipe, "case", "settings", False)
    assert compiled == [("case", "settings", False, "types")]
    assert pipe.sent == [None] and pipe.closed

    def fails(*args):
        raise RuntimeError("no LLVM today")

    monkeypatch.setattr(kernels, "_start_kernels", fails)
    pipe = Pipe()
    with pytest.raises(Ended):
        kernels._second_process(pipe, "case", "settings", False)
    assert pipe.sent == ["RuntimeError: no LLVM today"] and pipe.closed


def test_a_first_run_finds_modal_exacts_types_once_and_compiles_its_helpers_ahead(monkeypatch):
    """``kernels.compile_kernels`` finds modal-exact's argument types once (running the
    quasi-static kernel) and hands them to the start's side (the second process of a first
    run, here run in this one), which compiles each helper ``exact.ahead_signatures`` names
    for them before the start's kernels, so that compiling the kernel finds them cached; a
    newmark-linear run has none. A second process gone before it read the types leaves its
    share to this one. Whether those are the types the kernel calls the helper with is the
    ``slow`` one-signature test's."""
    import multiprocessing
    from types import SimpleNamespace

    from campipe.engine import exact, kernels
    from campipe.engine.batch import Case, RunSettings
    from campipe.model import thesis_train
    from campipe.profiles import harmonic

    done: list[object] = []

    class Recorder:
        def compile(self, signature):
            done.append(("helper", signature))

    def no_process(method):
        raise OSError("no second process here")

    found = batch.integrator_types
    monkeypatch.setattr(multiprocessing, "get_context", no_process)
    monkeypatch.setattr(exact, "ahead_signatures", lambda types: {Recorder(): types[:2]})
    monkeypatch.setattr(exact, "modal_exact_batch", Recorder())  # records ("helper", types)
    monkeypatch.setattr(batch, "start_states", lambda cases, settings: done.append("start"))
    monkeypatch.setattr(batch, "run_batch", lambda *args, **kwargs: done.append("newmark"))
    monkeypatch.setattr(
        batch, "integrator_types", lambda *args: done.append("types") or found(*args)
    )
    case = Case(thesis_train(), harmonic(0.0254), 900.0)
    settings = RunSettings(revolutions=0.05, warmup=0)
    kernels.compile_kernels(case, settings)
    types = found([case], settings, False)
    assert done == ["types", ("helper", types[:2]), "start", ("helper", types)]
    done.clear()

    class Gone:  # a second process that died before it read the types
        def __init__(self, target, args, daemon):
            self.theirs = args[0]

        def start(self):
            pass

        def join(self):
            pass

    monkeypatch.setattr(
        multiprocessing,
        "get_context",
        lambda method: SimpleNamespace(Pipe=multiprocessing.Pipe, Process=Gone),
    )
    kernels.compile_kernels(case, settings)  # its share is compiled here instead
    assert done == ["types", ("helper", types[:2]), "start", ("helper", types)]
    done.clear()
    newmark = RunSettings(revolutions=0.05, warmup=0, integrator="newmark-linear", dt=1e-6)
    kernels.compile_kernels(case, newmark)
    assert done == ["start", "newmark"]
