"""A study as fast as its engine: ``campipe study`` end to end against the engine.

The developer's benchmark of campipe's own latencies and study layer (``campipe bench``, in
the package, is the user's speed against error). From the repository's root::

    python -m benchmarks.study -o docs/bench       # the full run: docs/bench/study.json
    python -m benchmarks.study --quick -o DIR      # sizes up to 256 cases, no first run nor
                                                   # bundled studies' estimates
    python -m benchmarks.pages                     # docs/bench.md's study blocks from the json

Everything a user waits for is timed as the user runs it, in a fresh ``python -m campipe``
process (imports, the compiled kernels' loading, the spec, the batches, the archive), best of
a few runs; the engine alone is timed on the same cases and the same number of worker
threads, in this process with its kernels loaded, in the study's own batches.

- :func:`latencies`: ``campipe --help``, a one-case study, a finished study run again.
- :func:`sizes`: 1 … 10000 cases: end-to-end wall, in-process study time, engine time, their
  ratio, archive bytes per case.
- :func:`ceiling`: the client's side of a cluster whose workers store their batches: the
  archive assembled from stored batch files (cases per second), against what compression
  and the disk allow.
- :func:`cluster`: a study on 1, 2, 4 local dask worker processes against the engine's
  throughput on the same workers.
- :func:`estimates`: each bundled study (``studies/*.yaml``): validate's run-time estimate
  beside the measured run.
- :func:`validate_at_scale`: ``campipe validate`` of a million-case spec, wall and memory.
- :func:`benchmarks.scaling.study_scaling`: the engine's scaling cases of ``campipe bench``
  through the study layer, archive included, on 1 and 2 threads.
- :func:`run`: all of it, with the machine's description; :func:`main` writes ``study.json``.

Specs and archives are written under the folder given (and nowhere else).
"""

from __future__ import annotations

import functools
import logging
import math
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import yaml

from benchmarks.scaling import scaling_spec, study_scaling
from campipe.engine import Case, RunSettings, run_batch
from campipe.engine.settings import sample_count
from campipe.study import load_study
from campipe.study.run.assembly import assemble, read_batch
from campipe.study.run.batches import parts_directory, plan_batches
from campipe.study.run.execute import run_study
from campipe.study.run.results import full_state
from campipe.study.run.resume import find_results
from campipe.study.run.sizing import default_batch_size, default_workers
from campipe.study.spec.expand import Study
from campipe.study.spec.fields import COMPRESSIONS
from campipe.study.spec.variables import data_variables

#: Case counts of the study section, and of --quick.
COUNTS = (1, 32, 1000, 10000)
QUICK_COUNTS = (1, 32, 256)
#: The size the study-layer goal is judged at: wall ≤ GOAL_FACTOR × engine + GOAL_OFFSET.
GOAL_CASES = 1000
GOAL_FACTOR = 1.5
GOAL_OFFSET = 0.5  # [s]
#: Start-up goals [s]: --help, a one-case study (warm), a finished study run again.
GOAL_HELP = 0.3
GOAL_ONE_CASE = 0.8
GOAL_FINISHED = 0.5
#: First run: the quickstart from a fresh install [s] (:func:`first_run`, with empty caches in
#: a fresh process; the full run only). Restated from 10 s when campipe gave up patching numba
#: (issue 33): through numba's public interface the quickstart's first run took 14.9–16.0 s
#: here where the patched numba took 12.9–14.5 s in the same conditions (2026-11-27, load
#: average 0.8–1.8 on 2 cores), and a new clone or venv compiles again (numba keys its cache
#: by the source files' paths and time stamps).
GOAL_FIRST_RUN = 20.0
#: validate at scale: cases, wall [s] and peak memory [bytes].
VALIDATE_CASES = 1_000_000
GOAL_VALIDATE_SECONDS = 3.0
GOAL_VALIDATE_BYTES = 300e6
#: Cases of the cluster runs (--quick: fewer), and the worker processes tried.
CLUSTER_CASES = 4000
QUICK_CLUSTER_CASES = 256
CLUSTER_WORKERS = (1, 2, 4)
#: Runs each figure is the best of: a fresh process's latencies, a size's end-to-end, in-process
#: and engine times; --quick times each once (its figures are not published: it shows the
#: benchmark runs).
LATENCY_REPEATS = 5
SIZE_REPEATS = 3
QUICK_REPEATS = 1


def _campipe(args: Sequence[str], cwd: Path) -> tuple[float, subprocess.CompletedProcess]:
    """Wall time of ``python -m campipe ARGS`` in a fresh process, as a user runs it: with
    Python's bytecode cache, which an installed campipe has (pip compiles it at install), so
    a ``PYTHONDONTWRITEBYTECODE`` of the bench's own environment is left out (with it, every
    process compiles campipe's modules from source again, about 0.1 s)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    t0 = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-m", "campipe", *args], cwd=cwd, env=env, capture_output=True, text=True
    )
    seconds = time.perf_counter() - t0
    if out.returncode != 0:
        raise RuntimeError(f"campipe {' '.join(args)} failed: {out.stderr.strip()[-500:]}")
    return seconds, out


def _best(run: Callable[[], float], repeats: int) -> float:
    return min(run() for _ in range(max(repeats, 1)))


def write_spec(directory: Path, n: int) -> Path:
    """The scaling spec of ``n`` cases (:func:`benchmarks.scaling.scaling_spec`) in
    ``directory``."""
    path = directory / f"study-{n}.yaml"
    path.write_text(yaml.safe_dump(scaling_spec(n), sort_keys=False))
    return path


def engine_seconds(study: Study, workers: int, repeats: int = 3) -> float:
    """The engine alone on the study's cases, in the batches the study runs (its default
    batch size for ``workers``) on ``workers`` threads, sampling what the study stores; best
    of ``repeats``. The study's batches, not one batch per worker: the ratio is then the
    study layer's cost alone, and a batch's work arrays stay the size the study uses."""
    jobs = _engine_jobs(study, _batch_size(study, workers))

    def once() -> float:
        t0 = time.perf_counter()
        with ThreadPoolExecutor(workers) as pool:
            list(pool.map(_engine_job, jobs))
        return time.perf_counter() - t0

    _engine_job((jobs[0][0][:1], *jobs[0][1:]))  # kernels loaded
    return _best(once, repeats)


def _batch_size(study: Study, workers: int) -> int:
    """The batch size the study runs with on ``workers`` by default."""
    samples = sample_count(study.revolutions, study.output_every)
    return default_batch_size(len(study.cases), workers, samples)


def _engine_jobs(study: Study, size: int) -> list[tuple[list[Case], RunSettings, bool]]:
    """The engine's part of each batch of ``size`` the study runs: (cases, settings,
    full_state) for :func:`_engine_job`."""
    full = full_state(study.record)
    return [
        ([c.case for c in p.cases], p.cases[0].settings, full)
        for p in plan_batches(study.cases, study.record, size)
    ]


def latencies(directory: Path, workers: int, repeats: int = LATENCY_REPEATS) -> dict:
    """``campipe --help``, a one-case study (a new archive each time) and a finished
    1000-case study run again, each in a fresh process, best of ``repeats``."""
    one = write_spec(directory, 1)
    _campipe(["study", one.name, "--no-progress"], directory)  # kernels compiled and cached

    def help_once() -> float:
        return _campipe(["--help"], directory)[0]

    def one_case() -> float:
        (directory / "bench-scaling-1.nc").unlink(missing_ok=True)
        return _campipe(["study", one.name, "--no-progress", "--workers", str(workers)], directory)[
            0
        ]

    finished = write_spec(directory, GOAL_CASES)
    archive = directory / f"bench-scaling-{GOAL_CASES}.nc"
    if not archive.exists():
        _campipe(["study", finished.name, "--no-progress", "--workers", str(workers)], directory)

    def finished_once() -> float:
        seconds, out = _campipe(["study", finished.name, "--no-progress"], directory)
        assert "up to date" in out.stderr, out.stderr
        return seconds

    return {
        "help": _best(help_once, repeats),
        "one_case": _best(one_case, repeats),
        "finished": _best(finished_once, repeats),
        "finished_cases": GOAL_CASES,
        "repeats": repeats,
        "bytecode": True,  # Python's bytecode cache on (``_campipe``)
    }


def _cli_study(spec: Path, archive: Path, workers: int) -> float:
    archive.unlink(missing_ok=True)
    args = ["study", spec.name, "--no-progress", "--workers", str(workers)]
    return _campipe(args, spec.parent)[0]


def _in_process(study: Study, archive: Path, workers: int) -> float:
    archive.unlink(missing_ok=True)
    t0 = time.perf_counter()
    run_study(study, archive, scheduler="threads", workers=workers)
    return time.perf_counter() - t0


def sizes(
    directory: Path, counts: Sequence[int], workers: int, repeats: int = SIZE_REPEATS
) -> list[dict]:
    """For each count: ``campipe study`` end to end (best of ``repeats``; one run above 1000
    cases), the study in this process (``run_study``, process start left out), the engine
    alone, and the archive's size."""
    out = []
    for n in counts:
        spec = write_spec(directory, n)
        study = load_study(spec)
        archive = directory / f"bench-scaling-{n}.nc"
        r = repeats if n <= GOAL_CASES else 1
        wall = _best(functools.partial(_cli_study, spec, archive, workers), r)
        study_seconds = _best(functools.partial(_in_process, study, archive, workers), r)
        engine = engine_seconds(study, workers, r)
        out.append(
            {
                "n_cases": len(study.cases),
                "workers": workers,
                "wall": wall,
                "study": study_seconds,
                "engine": engine,
                "ratio": wall / engine,
                "archive_bytes": archive.stat().st_size,
                "bytes_per_case": archive.stat().st_size / len(study.cases),
                "goal": GOAL_FACTOR * engine + GOAL_OFFSET,
                "repeats": r,
            }
        )
    return out


def _raw_histories(study: Study, found: dict) -> list[np.ndarray]:
    """The histories of a few stored batches, as the archive's assembly reads them."""
    names = [n for n, v in data_variables(study.record).items() if "cam_angle" in v.dims]
    arrays = []
    for path in list(dict.fromkeys(p for p, _, _ in found.values()))[:4]:
        stored = read_batch(path)
        arrays += [stored[n] for n in names]
    return arrays


def _netcdf_write(arrays: list[np.ndarray], compression: str, cases: int) -> tuple[float, int]:
    """Seconds netCDF-C takes to write ``arrays`` to a scratch file with ``compression``
    (``run.compression``) and chunks of ``cases`` cases, each array in one call, and the
    file's bytes."""
    import netCDF4

    scratch = Path(os.environ.get("TMPDIR", "/tmp")) / f".campipe-bench-{os.getpid()}.nc"
    filters = COMPRESSIONS[compression]
    cache = netCDF4.get_chunk_cache()
    netCDF4.set_chunk_cache(0, 0, 1.0)  # as the archive: each chunk compressed as written
    try:
        t0 = time.perf_counter()
        with netCDF4.Dataset(scratch, "w") as ds:
            for i, a in enumerate(arrays):
                dims = tuple(f"d{i}_{k}" for k in range(a.ndim))
                for d, n in zip(dims, a.shape, strict=True):
                    ds.createDimension(d, n)
                chunks = (min(cases, a.shape[0]), *a.shape[1:])
                ds.createVariable(f"v{i}", a.dtype, dims, chunksizes=chunks, **filters)[:] = a
        return time.perf_counter() - t0, scratch.stat().st_size
    finally:
        netCDF4.set_chunk_cache(*cache)
        scratch.unlink(missing_ok=True)


def compression_limit(arrays: list[np.ndarray], compression: str, cases: int) -> dict:
    """What the archive's compression and this disk allow, in raw bytes per second: netCDF-C
    writing ``arrays`` with the archive's ``compression`` (and, beside it, with each other
    one) in chunks of ``cases`` cases, each array in one call, on one core; and writing the
    same bytes uncompressed to a file and flushing it."""
    raw = sum(a.nbytes for a in arrays)
    written = {name: _netcdf_write(arrays, name, cases) for name in COMPRESSIONS}
    blob = b"".join(np.ascontiguousarray(a).tobytes() for a in arrays)
    scratch = Path(os.environ.get("TMPDIR", "/tmp")) / f".campipe-bench-{os.getpid()}"
    t0 = time.perf_counter()
    with open(scratch, "wb") as f:
        f.write(blob)
        f.flush()
        os.fsync(f.fileno())
    disk = time.perf_counter() - t0
    scratch.unlink(missing_ok=True)
    seconds, packed = written[compression]
    return {
        "compression": compression,
        "raw_bytes": raw,
        "compressed_bytes": packed,
        "compress_rate": raw / seconds,
        "disk_rate": raw / disk,
        "compressions": {
            name: {"rate": raw / t, "bytes": size} for name, (t, size) in written.items()
        },
    }


def ceiling(directory: Path, n: int, workers: int) -> dict:
    """The client's ceiling on a cluster whose workers store their own batches: the archive
    assembled from ``n`` cases' stored batch files (read, compressed, checksummed, written),
    in cases per second, against the compression and disk limits."""
    spec = write_spec(directory, n)
    study = load_study(spec)
    archive = directory / f"ceiling-{n}.nc"
    run_study(study, archive, scheduler="threads", workers=workers, keep_parts=True)
    found, _ = find_results(study, archive, archive_usable=False)
    arrays = _raw_histories(study, found)
    best = math.inf
    for _ in range(2):
        target = directory / f"ceiling-{n}-assembled.nc"
        target.unlink(missing_ok=True)
        t0 = time.perf_counter()
        assemble(study, target, found)
        best = min(best, time.perf_counter() - t0)
    names = [k for k, v in data_variables(study.record).items() if "cam_angle" in v.dims]
    raw_per_case = sum(
        np.dtype(data_variables(study.record)[k].dtype).itemsize for k in names
    ) * int(arrays[0].shape[1])
    import netCDF4

    with netCDF4.Dataset(target) as ds:  # the archive's own chunks
        cases = ds["valve_lift"].chunking()[0]
    limit = compression_limit(arrays, study.compression, cases)
    shutil.rmtree(parts_directory(archive), ignore_errors=True)
    return {
        "n_cases": n,
        "seconds": best,
        "cases_per_second": n / best,
        "raw_bytes_per_case": raw_per_case,
        "write_rate": n * raw_per_case / best,
        **limit,
    }


def cluster(directory: Path, n: int, worker_counts: Sequence[int] = CLUSTER_WORKERS) -> list[dict]:
    """A study of ``n`` cases on a local dask cluster of 1, 2, 4 single-threaded worker
    processes (they write their batch files; this process assembles), against the engine
    alone on the same workers, in cases per second (cluster start-up left out)."""
    from distributed import Client, LocalCluster

    spec = write_spec(directory, n)
    study = load_study(spec)
    out = []
    for k in worker_counts:
        with (
            LocalCluster(
                n_workers=k,
                threads_per_worker=1,
                processes=True,
                dashboard_address=":0",
                silence_logs=logging.ERROR,
            ) as lc,
            Client(lc) as client,
        ):
            size = _batch_size(study, k)
            jobs = _engine_jobs(study, size)
            client.gather(client.map(_engine_job, jobs[:k], pure=False))  # kernels loaded
            t0 = time.perf_counter()
            client.gather(client.map(_engine_job, jobs, pure=False))
            engine = time.perf_counter() - t0
            archive = directory / f"cluster-{n}-{k}.nc"
            archive.unlink(missing_ok=True)
            t0 = time.perf_counter()
            run_study(study, archive, scheduler=lc.scheduler_address, batch_size=size)
            wall = time.perf_counter() - t0
        out.append(
            {
                "workers": k,
                "n_cases": n,
                "study_seconds": wall,
                "engine_seconds": engine,
                "study_rate": n / wall,
                "engine_rate": n / engine,
            }
        )
    return out


def _engine_job(job: tuple[list[Case], RunSettings, bool]) -> int:
    """Run one batch's cases through the engine (:func:`_engine_jobs`); their number."""
    cases, settings, full = job
    run_batch(cases, settings, full_state=full, on_failure="record")
    return len(cases)


def _quickstart(directory: Path, env: dict) -> tuple[float, float, str]:
    """``campipe study quickstart.yaml`` in ``directory`` with ``env``, in a fresh process:
    wall time, the seconds before its first line on the terminal, and that line."""
    (directory / "quickstart.nc").unlink(missing_ok=True)
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-m", "campipe", "study", "quickstart.yaml"],
        cwd=directory,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stderr is not None
    first = proc.stderr.readline()
    first_seconds = time.perf_counter() - t0
    rest = proc.stderr.read()
    proc.wait()
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"the quickstart failed: {(first + rest).strip()[-500:]}")
    return seconds, first_seconds, first.strip()


def first_run(studies: Path, directory: Path) -> dict:
    """The quickstart as on a fresh install, twice, each in a fresh process:

    - on a machine that never ran campipe: numba's cache and the per-user caches (pint's
      definitions, campipe's kernels) empty. Wall time, the seconds before its first line on
      the terminal (a compile notice, or nothing until the end), and that line;
    - then from a second copy of campipe at another path (no ``__pycache__``, as a new clone
      or venv has), with the caches the first run left: ``reinstall_seconds``, what a fresh
      install of a campipe this machine has run before takes (``campipe.kernel_cache``)."""
    import tempfile

    import campipe

    shutil.copy(studies / "quickstart.yaml", directory / "quickstart.yaml")
    with tempfile.TemporaryDirectory(prefix="campipe-fresh-") as empty:
        env = {**os.environ, "NUMBA_CACHE_DIR": f"{empty}/numba", "XDG_CACHE_HOME": empty}
        seconds, first_seconds, first = _quickstart(directory, env)
        copy = Path(empty) / "install"
        shutil.copytree(
            Path(campipe.__file__).parent,
            copy / "campipe",
            ignore=shutil.ignore_patterns("__pycache__"),
        )
        path = os.pathsep.join([str(copy), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
        again_env = {**env, "PYTHONPATH": path}
        where = subprocess.run(
            [sys.executable, "-c", "import campipe; print(campipe.__file__)"],
            cwd=directory,
            env=again_env,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        if not Path(where).is_relative_to(copy):
            raise RuntimeError(f"the second install's run imported {where}, not its copy")
        again, _, _ = _quickstart(directory, again_env)
    return {
        "seconds": seconds,
        "first_line_seconds": first_seconds,
        "first_line": first,
        "notice": "compiling" in first,
        "reinstall_seconds": again,
    }


def estimates(studies: Path, directory: Path, workers: int) -> list[dict]:
    """Each bundled study: validate's estimate beside the study's measured run, each in a
    fresh process of its own that loads the engine as a user's does
    (:func:`benchmarks.fresh.estimate_and_run`)."""
    from benchmarks.fresh import estimate_and_run

    return [
        estimate_and_run(spec, directory / f"estimate-{spec.stem}.nc", workers)
        for spec in sorted(studies.glob("*.yaml"))
    ]


def validate_at_scale(directory: Path, n: int = VALIDATE_CASES) -> dict:
    """``campipe validate --no-estimate`` of an ``n``-case spec (speed × spring preload) in
    a fresh process: wall time and the process's peak memory (its own: Linux's ``ru_maxrss``
    keeps, across the exec, the peak of the forked benchmark process, so VmHWM is read where
    there is one)."""
    side = int(round(math.sqrt(n)))
    spec = directory / f"validate-{n}.yaml"
    spec.write_text(
        yaml.safe_dump(
            {
                "name": f"validate-{n}",
                "profile": {"kind": "harmonic", "lift": "1 in"},
                "run": {"revolutions": 2, "output_every": "10 deg"},
                "sweep": {
                    "speed": {"from": "1000 rpm", "to": "20000 rpm", "num": side},
                    "model.spring_preload": {"from": "100 lbf", "to": "200 lbf", "num": n // side},
                },
            },
            sort_keys=False,
        )
    )
    code = (
        "import resource, runpy, sys\n"
        f"sys.argv = ['campipe', 'validate', {spec.name!r}, '--no-estimate', "
        f"'--max-cases', '{n}', '--max-archive-gb', '1000']\n"
        "try:\n"
        "    runpy.run_module('campipe', run_name='__main__')\n"
        "except SystemExit:\n"
        "    pass\n"
        "try:\n"
        "    with open('/proc/self/status') as f:\n"
        "        kb = next(int(x.split()[1]) for x in f if x.startswith('VmHWM:'))\n"
        "except (OSError, StopIteration):\n"
        "    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
        "print('peak', kb, file=sys.stderr)\n"
    )
    t0 = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=directory, capture_output=True, text=True
    )
    seconds = time.perf_counter() - t0
    peak = [line for line in out.stderr.splitlines() if line.startswith("peak ")]
    if "valid;" not in out.stdout or not peak:
        raise RuntimeError(f"campipe validate failed: {out.stderr.strip()[-500:]}")
    return {"n_cases": n, "seconds": seconds, "peak_bytes": int(peak[-1].split()[1]) * 1024}


def measure(
    directory: str | Path,
    *,
    quick: bool = False,
    workers: int | None = None,
    studies: Path | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict:
    """The whole study section, in one run."""
    say = progress or (lambda text: None)
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    workers = workers or default_workers()
    started = time.perf_counter()
    out: dict = {
        "workers": workers,
        "load_average_at_start": os.getloadavg()[0],
        "date": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
        "goals": {
            "cases": GOAL_CASES,
            "factor": GOAL_FACTOR,
            "offset": GOAL_OFFSET,
            "help": GOAL_HELP,
            "one_case": GOAL_ONE_CASE,
            "finished": GOAL_FINISHED,
            "first_run": GOAL_FIRST_RUN,
            "validate_cases": VALIDATE_CASES,
            "validate_seconds": GOAL_VALIDATE_SECONDS,
            "validate_bytes": GOAL_VALIDATE_BYTES,
        },
    }
    say("study: --help, a one-case study, a finished study (fresh processes)")
    out["latencies"] = latencies(directory, workers, QUICK_REPEATS if quick else LATENCY_REPEATS)
    counts = QUICK_COUNTS if quick else COUNTS
    say(f"study: {', '.join(map(str, counts))} cases end to end against the engine")
    out["sizes"] = sizes(directory, counts, workers, QUICK_REPEATS if quick else SIZE_REPEATS)
    n = counts[-1]
    say(f"study: the client's ceiling, assembling {n} cases from stored batches")
    out["ceiling"] = ceiling(directory, n, workers)
    m = QUICK_CLUSTER_CASES if quick else CLUSTER_CASES
    say(f"study: {m} cases on 1, 2, 4 local worker processes")
    out["cluster"] = cluster(directory, m)
    if not quick and studies is not None and studies.is_dir():
        say("study: validate's estimates of the bundled studies against their runs")
        out["estimates"] = estimates(studies, directory, workers)
        out["estimates_fresh"] = True  # each figure in a fresh process (benchmarks.fresh)
    if not quick and studies is not None:
        say("study: the quickstart as on a fresh install (numba compiles)")
        out["first_run"] = first_run(studies, directory)
    if not quick:
        say(f"study: campipe validate of {VALIDATE_CASES} cases")
        try:
            out["validate"] = validate_at_scale(directory)
        except RuntimeError as exc:
            out["validate"] = {"n_cases": VALIDATE_CASES, "failed": str(exc)[:300]}
    out["seconds"] = time.perf_counter() - started
    out["load_average_at_end"] = os.getloadavg()[0]
    return out


#: The bundled studies (validate's estimates, the quickstart of the first run).
STUDIES = Path(__file__).resolve().parents[1] / "studies"
#: The file :func:`main` writes into its output folder.
STUDY_JSON = "study.json"


def _meta(quick: bool) -> dict:
    """The machine and versions a run measured on, as ``campipe bench`` records them."""
    from campipe.bench.run import machine

    return {**machine(), "quick": quick}


def run(
    *,
    quick: bool = False,
    workers: int | None = None,
    with_scaling: bool = True,
    progress: Callable[[str], None] | None = None,
) -> dict:
    """The whole developer benchmark: ``{"meta", "study", "scaling"}``, the machine, the study
    section (:func:`measure`) and the study layer's scaling points
    (:func:`benchmarks.scaling.study_scaling`, empty without ``with_scaling``); its specs
    and archives in a temporary folder, removed afterwards."""
    import tempfile
    from dataclasses import asdict

    from campipe.bench.run import QUICK_SCALING_COUNTS, SCALING_COUNTS

    say = progress or (lambda text: None)
    out: dict = {"meta": _meta(quick), "study": {}, "scaling": []}
    with tempfile.TemporaryDirectory(prefix="campipe-benchmarks-") as tmp:
        out["study"] = measure(tmp, quick=quick, workers=workers, studies=STUDIES, progress=say)
        if with_scaling:
            counts = QUICK_SCALING_COUNTS if quick else SCALING_COUNTS
            say(f"scaling: the study layer with its archive, {counts[0]}–{counts[-1]} cases")
            points = study_scaling(counts, Path(tmp) / "scaling")
            out["scaling"] = [{**asdict(p), "per_case": p.per_case} for p in points]
    out["meta"]["load_average_at_end"] = os.getloadavg()[0]
    return out


def _clean(obj: object) -> object:
    """JSON-safe: NaN and inf become null (as ``campipe bench`` writes its json)."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    return obj


def main(argv: Sequence[str] | None = None) -> int:
    import argparse
    import json

    from benchmarks import goals

    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.study",
        description="campipe's own latencies and study layer against the engine (a developer's "
        "benchmark; campipe bench is the user's speed against error). Writes study.json.",
    )
    parser.add_argument(
        "-o", "--output", type=Path, default=Path("bench-results"), help="default: bench-results"
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help=f"sizes {', '.join(map(str, QUICK_COUNTS))}, {QUICK_CLUSTER_CASES} cases on the "
        "worker processes, no first run, bundled studies' estimates nor validate at scale "
        "(a few minutes)",
    )
    parser.add_argument("--workers", type=int, help="worker threads (default: the study's)")
    parser.add_argument(
        "--no-scaling",
        dest="scaling",
        action="store_false",
        help="leave out the study layer's time against cases and workers",
    )
    args = parser.parse_args(argv)

    def say(text: str) -> None:
        sys.stderr.write(f"benchmarks: {text}\n")

    data = run(quick=args.quick, workers=args.workers, with_scaling=args.scaling, progress=say)
    args.output.mkdir(parents=True, exist_ok=True)
    path = args.output / STUDY_JSON
    path.write_text(json.dumps(_clean(data), indent=1))
    print(path)
    print(goals.text(data["study"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
