"""Where numba caches campipe's kernels (``campipe.kernel_cache``): numba's own ``cache=True``
in the folder campipe gives it through ``NUMBA_CACHE_DIR``, one per version of the kernels'
source (an edit to any file the kernels compile from, not only the kernel's own, makes them
compile again), and campipe's record of which kernels it compiled there (the first run's
notice, ``campipe.engine.kernels``)."""

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from campipe import kernel_cache
from campipe.engine import batch

#: Run in a copy of campipe: the lift at θ = 0 of a harmonic cam through ``batch.cam_at`` (a
#: small kernel, about a second to compile), then numba's cache folder and how many
#: functions numba compiled for it (numba's event API: none when all were loaded from its
#: cache).
PROBE = """
import json, os
import campipe
from campipe.engine import batch  # before numba: campipe sets its cache folder first
from campipe.profiles import harmonic
from campipe.profiles.packed import pack
from numba.core import event

class Count(event.Listener):
    compiled = 0
    def on_start(self, ev):
        Count.compiled += 1
    def on_end(self, ev):
        pass

with event.install_listener("numba:compile", Count()):
    lift = batch.cam_at(pack([harmonic(0.0254)]), 0.0)[0].tolist()
print(json.dumps({
    "package": campipe.__file__,
    "cache": os.environ.get("NUMBA_CACHE_DIR"),
    "compiled": Count.compiled,
    "lift": lift,
}))
"""


def _copy(tmp_path: Path, name: str) -> Path:
    root = tmp_path / name
    shutil.copytree(
        kernel_cache.ROOT, root / "campipe", ignore=shutil.ignore_patterns("__pycache__")
    )
    return root


def _probe(copy: Path, home: Path) -> dict:
    """The probe in a fresh process of ``copy``, its user cache folder under ``home``
    (``XDG_CACHE_HOME``) and no ``NUMBA_CACHE_DIR`` of its own."""
    env = {**os.environ, "PYTHONPATH": str(copy), "XDG_CACHE_HOME": str(home)}
    env.pop("NUMBA_CACHE_DIR", None)
    out = subprocess.run(
        [sys.executable, "-c", PROBE], cwd=copy, env=env, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.splitlines()[-1])


def test_numba_caches_in_the_source_folder_and_an_edit_elsewhere_recompiles(tmp_path):
    """A copy of campipe run twice compiles ``cam_at`` (and the profile evaluators it calls)
    once: numba caches them in ``<user cache>/campipe/kernels/<source hash>/numba``, where the
    second run loads them. A copy with a comment added to ``engine/common.py``, a file
    ``cam_at``'s module imports but that does not define it, gets another folder and
    compiles again (numba's per-file stamp alone would have loaded the first copy's, were it
    at the same path). The lift is the same in all three.

    Broken copies: ``kernel_cache.configure`` not setting ``NUMBA_CACHE_DIR`` (cache None);
    :data:`kernel_cache.SOURCES` holding only the kernel's own file (one folder for both)."""
    home = tmp_path / "home"
    first, edited = _copy(tmp_path, "first"), _copy(tmp_path, "edited")
    common = edited / "campipe" / "engine" / "common.py"
    common.write_text(common.read_text() + "\n# an edit\n")

    a = _probe(first, home)
    b = _probe(first, home)
    c = _probe(edited, home)
    assert a["package"].startswith(str(first)) and c["package"].startswith(str(edited))
    source = kernel_cache.hash_sources(first / "campipe")[:16]
    assert a["cache"] == str(home / "campipe" / "kernels" / source / "numba")
    assert a["compiled"] >= 2 and b["compiled"] == 0 and c["compiled"] >= 2
    assert list(Path(a["cache"]).rglob("*.nbi"))  # numba's index files, under that folder
    assert a["cache"] == b["cache"] != c["cache"]
    assert Path(c["cache"]).parent.parent == Path(a["cache"]).parent.parent
    assert a["lift"] == b["lift"] == c["lift"]
    assert a["lift"][0] == pytest.approx(0.0254 / 2, rel=1e-12)  # θ = 0 is mid-lift


def test_configure_sets_numbas_folder_only_where_numba_would_read_it(tmp_path, monkeypatch):
    """``configure`` sets ``NUMBA_CACHE_DIR`` to this source's folder when neither the
    environment sets it nor numba is imported (numba reads it once, at import); it leaves a
    user's setting alone, sets nothing once numba is imported, and nothing where the
    folder cannot be made (numba's own default then)."""
    source = tmp_path / "0123456789abcdef"
    monkeypatch.setattr(kernel_cache, "cache_root", lambda: tmp_path)
    monkeypatch.setattr(kernel_cache, "cache_folder", lambda: source)
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    assert kernel_cache.configure() is None  # numba is imported in this process
    assert "NUMBA_CACHE_DIR" not in os.environ and not source.exists()
    monkeypatch.delitem(sys.modules, "numba")  # as a process that has not imported it
    assert kernel_cache.configure() == str(source / "numba")
    assert os.environ["NUMBA_CACHE_DIR"] == str(source / "numba") and (source / "numba").is_dir()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "mine"))
    assert kernel_cache.configure() == str(tmp_path / "mine")
    assert os.environ["NUMBA_CACHE_DIR"] == str(tmp_path / "mine")
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    blocked = tmp_path / "a file"
    blocked.write_text("")
    monkeypatch.setattr(kernel_cache, "cache_folder", lambda: blocked / "0123456789abcdef")
    assert kernel_cache.configure() is None and "NUMBA_CACHE_DIR" not in os.environ


def test_the_compiled_record_follows_what_numba_checks(tmp_path, monkeypatch):
    """A kernel recorded as compiled (``mark_compiled``) is recorded for numba's cache
    folder, and for this copy's source files as they are: another ``NUMBA_CACHE_DIR``, a
    copy at another path or a source file written again (its time stamp) each has no
    record, as numba would compile again for each."""
    source = tmp_path / "0123456789abcdef"
    monkeypatch.setattr(kernel_cache, "cache_root", lambda: tmp_path)
    monkeypatch.setattr(kernel_cache, "cache_folder", lambda: source)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    kernel_cache.numba_stamp.cache_clear()
    marker = kernel_cache.compiled_marker("modal-exact")
    assert not marker.exists()
    kernel_cache.mark_compiled(["modal-exact"])
    assert marker.exists() and not kernel_cache.compiled_marker("periodic start").exists()
    stamp = kernel_cache.numba_stamp()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "other"))
    kernel_cache.numba_stamp.cache_clear()
    assert kernel_cache.numba_stamp() != stamp
    assert not kernel_cache.compiled_marker("modal-exact").exists()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    root = _copy(tmp_path, "copy") / "campipe"
    assert kernel_cache.stamp_of(root, str(tmp_path / "numba")) != stamp  # another path
    same = kernel_cache.stamp_of(kernel_cache.ROOT, str(tmp_path / "numba"))
    assert same == stamp
    copied = root / "engine" / "steady.py"
    before = kernel_cache.stamp_of(root, str(tmp_path / "numba"))
    os.utime(copied, ns=(time.time_ns(), copied.stat().st_mtime_ns + 10**9))
    assert kernel_cache.stamp_of(root, str(tmp_path / "numba")) != before  # written again
    kernel_cache.numba_stamp.cache_clear()


def test_the_first_run_says_it_compiles_and_the_next_does_not(tmp_path, monkeypatch):
    """``compile_first`` says which kernels it compiles when none is recorded, compiles
    them (here recorded, not run) and records them; the next run says nothing and compiles
    nothing. A compile that failed records nothing: the next run says it again. Broken
    copies, run: no ``mark_compiled`` (the second says it again); marking after a failure
    (the third says nothing)."""
    from campipe.engine import kernels
    from campipe.engine.batch import Case, RunSettings
    from campipe.model import thesis_train
    from campipe.profiles import harmonic

    source = tmp_path / "0123456789abcdef"
    monkeypatch.setattr(kernel_cache, "cache_root", lambda: tmp_path)
    monkeypatch.setattr(kernel_cache, "cache_folder", lambda: source)
    unloaded = SimpleNamespace(signatures=[])  # as a process that has loaded no kernel
    named = {"periodic start": unloaded, "modal-exact": unloaded}
    monkeypatch.setattr(kernels, "kernels", lambda settings: dict(named))
    compiled: list[object] = []
    ok = [True]
    monkeypatch.setattr(
        kernels, "compile_kernels", lambda case, settings, search: compiled.append(case) or ok[0]
    )
    settings = RunSettings(revolutions=0.05, warmup=0)
    case = Case(thesis_train(), harmonic(0.0254), 900.0)
    said: list[str] = []
    kernels.compile_first({settings: case}, said.append)
    assert len(said) == 1 and compiled == [case]
    assert said[0].startswith("compiling periodic start, modal-exact with numba")
    kernels.compile_first({settings: case}, said.append)
    assert len(said) == 1 and compiled == [case]
    named["newmark-linear"] = unloaded
    ok[0] = False
    kernels.compile_first({settings: case}, said.append)
    kernels.compile_first({settings: case}, said.append)
    assert said[1] == said[2] and said[1].startswith("compiling newmark-linear with numba,")
    assert len(compiled) == 3


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


def test_compiling_ahead_compiles_the_signatures_a_run_calls(monkeypatch):
    """A first run compiles modal-exact's kernel ahead from the types ``batch.integrator_types``
    gives, found without running the start's kernels (``kernels.compile_kernels``); the
    quasi-static kernel is called from the quasi-static start (``quasi_static.initial_states``)
    and from the trains' valve references. Each must be called with the types it was compiled
    for, or the run compiles it again (about 15 s for modal-exact). Checked here on the types
    of every call a run makes, over batches that differ in what could change a type: a seat,
    form closure, restitution, a refined train (more coordinates), both starts, both
    ``full_state``. Broken copies, run: ``integrator_types`` with float zeta (modal-exact's
    types differ); the quasi-static start's held mask broadcast, as it was (two signatures).
    """
    from numba import typeof

    from campipe.engine import contact, exact, quasi_static
    from campipe.engine.batch import Case, RunSettings, run_batch
    from campipe.model import thesis_train
    from campipe.profiles import harmonic

    calls: dict[str, list[tuple]] = {"exact": [], "quasi-static": []}

    def recording(name, kernel):
        def record(*args):
            calls[name].append(tuple(typeof(a) for a in args))
            return kernel(*args)

        return record

    monkeypatch.setattr(exact, "modal_exact_batch", recording("exact", exact.modal_exact_batch))
    monkeypatch.setattr(
        quasi_static, "quasi_static_batch", recording("quasi-static", contact.quasi_static_batch)
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
from campipe.engine import onset, periodic, steady
from campipe.engine.exact import kernel as exact_kernel, peaks as exact_peaks
from campipe.engine.exact import segment as exact_segment, state as exact_state
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
onset.onset_speeds(cases[:1], 6000 * math.pi / 30, 14000 * math.pi / 30, 1.0)
# A chain's lash adjuster carried in modal-exact: the kernel with the plunger's code, its last
# argument the plunger coordinates where the others' is None (a second signature by design).
from campipe.model import valve_train
from campipe.profiles import Ramp, polydyne
bucket = valve_train("thesis-1971", {
    "layout": "direct-acting", "tappet_mass": "0.045 kg", "valve_mass": "0.065 kg",
    "stem_stiffness": "30000 N/mm", "tappet_contact_stiffness": "60000 N/mm",
    "spring_rate": "35 N/mm", "spring_preload": "220 N", "damping_ratios": [0.05],
    "lash": "0.2 mm", "hla_stiffness": "20000 N/mm", "hla_leak_down": "2000 N*s/mm",
    "hla_check_force": "25 N", "hla_pump_up": "20 N*s/mm", "hla_travel": "1 mm"})
lobe = polydyne("4567", 9e-3, *[math.radians(d) for d in (110, 20, 110)], ramp=Ramp(0.3e-3, 0.27))
run_batch([Case(bucket, lobe, 3000 * math.pi / 30)], RunSettings(revolutions=2))
PLUNGER_ARG = {"none", "array(int64, 1d, C)"}
many = {}
for module in (batch, contact, closed_form, common, exact, modal, newmark, steady, packed,
               exact_kernel, exact_peaks, exact_segment, exact_state):
    for name, kernel in vars(module).items():
        if hasattr(kernel, "signatures") and len(kernel.signatures) > 1:
            sigs = kernel.signatures
            differ = [
                [str(s[i]) for s in sigs] for i in range(len(sigs[0]))
                if len({str(s[i]) for s in sigs}) > 1
            ]
            differ = [d for d in differ if not set(d) <= PLUNGER_ARG]
            if differ:
                many[f"{kernel.py_func.__module__}.{name}"] = differ
# A helper of its own (no CPython wrapper) that takes one of the batch's named tuples by
# value is compiled with a parameter for every scalar of its arrays (``common.by_ref``).
by_value = sorted(
    f"{kernel.py_func.__module__}.{name}"
    for module in (batch, contact, closed_form, common, exact, modal, newmark, steady, packed)
    for name, kernel in vars(module).items()
    if hasattr(kernel, "signatures")
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
    constant 0 again (``_keep_column`` gets two signatures); ``_walk`` calling
    ``peaks._force_peaks`` with the constants True and False (two, a second of a first run:
    modal-exact's own modules are scanned too); ``ahead_signatures`` giving
    ``first`` as int32 (``_apply_event`` gets two); ``closed_form.held_inputs`` taking the
    packed profiles' tuple again (listed). A chain's carried plunger runs too: its kernel
    differs only in the last argument (the plunger coordinates, None for every other batch),
    and its helpers take no named tuple by value either (``plunger_switch`` by reference)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    out = subprocess.run(
        [sys.executable, "-c", ONE_SIGNATURE], capture_output=True, text=True, check=True, env=env
    )
    found = json.loads(out.stdout.splitlines()[-1])
    assert found == {"more than one signature": {}, "named tuples by value": []}


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
    assert kernels.compile_kernels(case, settings)
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
    assert kernels.compile_kernels(case, settings)  # its share is compiled here instead
    assert done == ["types", ("helper", types[:2]), "start", ("helper", types)]
    done.clear()
    newmark = RunSettings(revolutions=0.05, warmup=0, integrator="newmark-linear", dt=1e-6)
    assert kernels.compile_kernels(case, newmark)
    assert done == ["start", "newmark"]
