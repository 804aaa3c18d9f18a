"""A study's peak memory against the bound ``campipe validate`` states (issue 39, item 4).

:func:`study_memory` runs one study on the default scheduler (threads) in a process of its
own and reads that process's peak resident memory (``resource.getrusage``'s ``ru_maxrss``)
twice: once the study is loaded and the kernels warmed up on a small run (the *baseline*: the
imports, the kernels, the study's cases), and once the study has run. Their difference, the
run's *growth*, is compared with :func:`campipe.study.run.sizing.in_flight_memory`, the bound
``campipe validate`` prints: at most two batches a worker in flight, whatever the study's size
(the archive is assembled as the batches finish, a block of rows at a time). Before the
in-flight bound, 10000 cases × 1081 samples peaked at 1.03 GB and 20000 at 1.88 GB: memory
grew with the study.

Run it alone with ``python -m campipe.bench.memory`` (``--cases``, ``--json``); ``campipe
bench`` runs it with its scaling measurements (``bench.memory``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import yaml

from campipe.bench.cluster import cluster_spec

#: The issue's study [cases] (× 1081 samples: 3 turns at 1 degree) and the quick run's.
MEMORY_CASES = 10000
QUICK_MEMORY_CASES = 1000
#: Turns of the study: 3 turns at 1 degree, 1081 samples a case (the issue's).
MEMORY_REVOLUTIONS = 3
#: Workers of the run (threads): those ``campipe validate`` states the bound for.
MEMORY_WORKERS = 2


@dataclass(frozen=True)
class MemoryPoint:
    """One study's memory on ``workers`` threads."""

    n_cases: int  # cases
    samples: int  # samples a case
    workers: int  # threads
    baseline: int  # peak RSS once loaded and warmed up [bytes]
    peak: int  # peak RSS once run [bytes]
    bound: int  # what the batches in flight take at most, as validate states it [bytes]
    in_flight: int  # batches in flight at most
    batch_size: int  # cases a batch

    @property
    def growth(self) -> int:
        """The run's growth of the peak [bytes]."""
        return self.peak - self.baseline

    @property
    def within(self) -> bool:
        """The growth within the stated bound."""
        return self.growth <= self.bound


def memory_spec(n: int) -> dict:
    """A spec of ``n`` (even) cases of 1081 samples each (:func:`cluster_spec`'s, 3 turns)."""
    spec = cluster_spec(n)
    spec["name"] = f"bench-memory-{n}"
    spec["description"] = "campipe bench: a study's peak memory"
    spec["run"] = {"revolutions": MEMORY_REVOLUTIONS, "output_every": "1 deg"}
    return spec


def _max_rss() -> int:
    """This process's peak resident memory [bytes]: Linux's ``VmHWM`` (the high-water mark of
    the process's own memory), else ``ru_maxrss``. On Linux ``ru_maxrss`` starts a child at
    its parent's resident memory when it was started (the kernel keeps the larger across
    ``exec``): under ``campipe bench``, at 3.1 GB, which hid the study's growth."""
    status = Path("/proc/self/status")
    if status.exists():
        for line in status.read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024  # kB
    import resource

    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(kb) * (1 if sys.platform == "darwin" else 1024)


def _child(spec: Path, warm: Path, archive: Path, workers: int) -> dict:
    """In the measuring process: the study loaded and a small one run (the kernels), the
    baseline read; the study run, the peak read."""
    from campipe.engine.settings import sample_count
    from campipe.study import load_study
    from campipe.study.run.execute import run_study
    from campipe.study.run.sizing import in_flight_memory

    run_study(load_study(warm), archive.with_suffix(".warm.nc"), workers=workers)
    study = load_study(spec)
    baseline = _max_rss()
    run_study(study, archive, workers=workers)
    peak = _max_rss()
    samples = sample_count(study.revolutions, study.output_every)
    bound, batches, size = in_flight_memory(len(study.cases), workers, samples)
    return {
        "n_cases": len(study.cases),
        "samples": samples,
        "workers": workers,
        "baseline": baseline,
        "peak": peak,
        "bound": bound,
        "in_flight": batches,
        "batch_size": size,
    }


def study_memory(n_cases: int, directory: str | Path, workers: int = MEMORY_WORKERS) -> MemoryPoint:
    """The peak memory of a study of ``n_cases`` cases on ``workers`` threads, measured in a
    process of its own (see the module); specs and archives under ``directory``."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    spec, warm = directory / f"memory-{n_cases}.yaml", directory / "memory-warm.yaml"
    spec.write_text(yaml.safe_dump(memory_spec(n_cases), sort_keys=False))
    warm.write_text(yaml.safe_dump(memory_spec(4), sort_keys=False))
    archive = directory / f"memory-{n_cases}.nc"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [_root(), _path()]))}
    done = subprocess.run(
        [sys.executable, "-m", "campipe.bench.memory", "--child", str(spec), str(warm),
         str(archive), str(workers)],
        capture_output=True, text=True, check=False, env=env,
    )  # fmt: skip
    if done.returncode != 0:
        raise RuntimeError(f"the memory study failed: {done.stderr.strip()[-500:]}")
    return MemoryPoint(**json.loads(done.stdout.strip().splitlines()[-1]))


def _root() -> str:
    """The folder this campipe is imported from (the child imports the same one)."""
    return str(Path(__file__).resolve().parents[2])


def _path() -> str:
    return os.environ.get("PYTHONPATH", "")


def as_dict(point: MemoryPoint) -> dict:
    """The point as ``bench.json`` keeps it."""
    return {**asdict(point), "growth": point.growth, "within": point.within}


HEADER = [
    "cases",
    "samples",
    "workers",
    "batches in flight × cases",
    "baseline [MB]",
    "peak [MB]",
    "growth [MB]",
    "stated bound [MB]",
]


def table_rows(point: dict) -> list[list[str]]:
    """The measured study as a table row."""
    return [
        [
            str(point["n_cases"]),
            str(point["samples"]),
            str(point["workers"]),
            f"{point['in_flight']} × {point['batch_size']}",
            f"{point['baseline'] / 1e6:.0f}",
            f"{point['peak'] / 1e6:.0f}",
            f"{point['growth'] / 1e6:.0f}",
            f"{point['bound'] / 1e6:.0f}",
        ]
    ]


def notes(point: dict) -> list[str]:
    """The figure in words: the growth against the bound."""
    verdict = "within" if point["within"] else "**beyond**"
    return [
        f"A study of {point['n_cases']} cases × {point['samples']} samples on "
        f"{point['workers']} threads (the default scheduler) grew the process's peak memory by "
        f"**{point['growth'] / 1e6:.0f} MB** over its {point['baseline'] / 1e6:.0f} MB once "
        f"loaded and warmed up: {verdict} the {point['bound'] / 1e6:.0f} MB `campipe validate` "
        f"states for the batches in flight ({point['in_flight']} of {point['batch_size']} "
        "cases; before that bound, 10000 cases peaked at 1.03 GB and 20000 at 1.88 GB)."
    ]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m campipe.bench.memory",
        description="A study's peak memory against the bound campipe validate states.",
    )
    parser.add_argument("--cases", type=int, default=MEMORY_CASES)
    parser.add_argument("--json", type=Path, help="write the point to this file")
    parser.add_argument("--child", nargs=4, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        spec, warm, archive, workers = args.child
        print(json.dumps(_child(Path(spec), Path(warm), Path(archive), int(workers))))
        return 0
    with tempfile.TemporaryDirectory(prefix="campipe-memory-") as folder:
        point = as_dict(study_memory(args.cases, folder))
    if args.json:
        args.json.write_text(json.dumps(point, indent=1) + "\n")
    print(" | ".join(HEADER))
    for row in table_rows(point):
        print(" | ".join(row))
    print("\n".join(notes(point)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
