"""A study on a dask cluster: cases per second against the client's CPU per case.

:func:`cluster_scaling` runs one study with ``--parts`` (:func:`campipe.study.run.execute.run_study`
with ``parts=True``) on a local dask.distributed cluster of 1, 2 and more single-threaded
worker processes, at two sizes, and times the client (this process): its CPU time from
loading the spec to the index written. The scheduler and the workers run in a process of
their own (:func:`local_cluster`), so the client's CPU is its own alone, as on a real
cluster; more workers than cores simulate a larger cluster (they share the cores, so their
cases per second stop growing, while the client's CPU per case shows what it could feed).

The client's CPU *per extra case* is the difference of the two sizes' CPU over the
difference of their cases: what each further case costs the client, its fixed costs
(connecting, the kernels' fingerprint, the index) left out. Its inverse is the rate of cases
the client could keep up with: the cluster's ceiling.

Run it alone with ``python -m campipe.bench.cluster`` (a table on stdout, ``--json`` to keep
it); ``campipe bench`` runs it with its scaling measurements (``bench.cluster``).
"""

from __future__ import annotations

import argparse
import json
import logging
import multiprocessing
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path

import yaml

from campipe.bench.scaling import SCALING_REVOLUTIONS, SPEED_RANGE

#: Worker processes of the full and the quick run.
CLUSTER_WORKERS = (1, 2, 4)
QUICK_CLUSTER_WORKERS = (1, 2)
#: The two study sizes [cases] of the full and the quick run.
CLUSTER_COUNTS = (1000, 4000)
QUICK_CLUSTER_COUNTS = (256, 1024)
#: The issue's goal: the client's CPU per extra case on a two-worker cluster [s].
CLIENT_GOAL = 25e-6
#: How long to wait for the local cluster to start [s].
START_TIMEOUT = 180


@dataclass(frozen=True)
class ClusterPoint:
    """One study of ``n_cases`` with ``--parts`` on ``workers`` worker processes."""

    workers: int  # single-threaded worker processes
    n_cases: int  # cases
    seconds: float  # wall time, spec loaded to index written [s]
    client_cpu: float  # this process's CPU time over the same span [s]
    batches: int  # batches (parts) computed

    @property
    def rate(self) -> float:
        """Cases per second."""
        return self.n_cases / self.seconds


def cluster_spec(n: int) -> dict:
    """A spec of ``n`` (even) cases: the harmonic cam over ``SPEED_RANGE``, each speed
    without a seat and with one at 0.1 in, a fixed run of ``SCALING_REVOLUTIONS`` turns."""
    return {
        "name": f"bench-cluster-{n}",
        "description": "campipe bench: a study on a dask cluster",
        "model": {"preset": "thesis-1971"},
        "profile": {"kind": "harmonic", "lift": "1 in"},
        "closure": "force",
        "speed": "9000 rpm",
        "run": {"revolutions": SCALING_REVOLUTIONS, "output_every": "1 deg"},
        "sweep": {
            "speed": {
                "from": f"{SPEED_RANGE[0]:g} rpm",
                "to": f"{SPEED_RANGE[1]:g} rpm",
                "num": max(n // 2, 1),
            },
            "seat": ["none", "0.1 in"],
        },
    }


def _serve(workers: int, address, stop) -> None:
    """The cluster's process: a scheduler and ``workers`` worker processes until ``stop``."""
    from distributed import LocalCluster

    with LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",
        silence_logs=logging.ERROR,
    ) as cluster:
        address.put(cluster.scheduler_address)
        stop.wait()


@contextmanager
def local_cluster(workers: int) -> Iterator[str]:
    """The address of a dask scheduler with ``workers`` single-threaded worker processes,
    all started in a process of their own (this one only connects), stopped on exit."""
    context = multiprocessing.get_context("spawn")
    address, stop = context.Queue(), context.Event()
    process = context.Process(target=_serve, args=(workers, address, stop))
    process.start()
    try:
        yield address.get(timeout=START_TIMEOUT)
    finally:
        stop.set()
        process.join(60)
        if process.is_alive():
            process.terminate()
            process.join()


def _study(spec: Path, archive: Path, address: str, workers: int) -> tuple[float, float, int]:
    """(wall, client CPU, batches) of the study ``spec`` into the parts archive ``archive``."""
    from campipe.study import load_study
    from campipe.study.run.execute import run_study

    cpu, t0 = time.process_time(), time.perf_counter()
    report = run_study(load_study(spec), archive, scheduler=address, workers=workers, parts=True)
    return time.perf_counter() - t0, time.process_time() - cpu, report.batches


def cluster_scaling(
    directory: str | Path,
    counts: Sequence[int] = CLUSTER_COUNTS,
    workers: Sequence[int] = CLUSTER_WORKERS,
) -> list[ClusterPoint]:
    """The study of each of ``counts`` cases with ``--parts`` on each of ``workers`` worker
    processes (batches sized for that many workers); specs and archives under
    ``directory``."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    specs = {}
    for n in (4, *counts):
        specs[n] = directory / f"cluster-{n}.yaml"
        specs[n].write_text(yaml.safe_dump(cluster_spec(n), sort_keys=False))
    out = []
    for k in workers:
        with local_cluster(k) as address:
            _study(specs[4], directory / f"warm-{k}.parts", address, k)  # kernels loaded
            for n in counts:
                seconds, cpu, batches = _study(
                    specs[n], directory / f"cluster-{n}-{k}.parts", address, k
                )
                out.append(ClusterPoint(k, n, seconds, cpu, batches))
    return out


def per_extra_case(points: Sequence[dict]) -> dict[int, float]:
    """Workers → the client's CPU per extra case [s]: between the smallest and the largest
    study on that many workers."""
    out = {}
    for k in sorted({int(p["workers"]) for p in points}):
        mine = sorted((p for p in points if p["workers"] == k), key=lambda p: p["n_cases"])
        if len(mine) > 1 and mine[-1]["n_cases"] > mine[0]["n_cases"]:
            cpu = mine[-1]["client_cpu"] - mine[0]["client_cpu"]
            out[k] = cpu / (mine[-1]["n_cases"] - mine[0]["n_cases"])
    return out


def as_dicts(points: Sequence[ClusterPoint]) -> list[dict]:
    """The points as ``bench.json`` keeps them."""
    return [{**asdict(p), "rate": p.rate} for p in points]


HEADER = [
    "workers",
    "cases",
    "batches",
    "seconds",
    "cases/s",
    "client CPU [s]",
    "client CPU per case [µs]",
    "per extra case [µs]",
]


def table_rows(points: Sequence[dict]) -> list[list[str]]:
    """A row per point, the client's CPU per extra case on each worker count's largest."""
    extra = per_extra_case(points)
    rows = []
    for p in sorted(points, key=lambda p: (p["workers"], p["n_cases"])):
        k = int(p["workers"])
        largest = p["n_cases"] == max(q["n_cases"] for q in points if q["workers"] == k)
        rows.append(
            [
                str(k),
                str(p["n_cases"]),
                str(p["batches"]),
                f"{p['seconds']:.2f}",
                f"{p['rate']:.0f}",
                f"{p['client_cpu']:.3f}",
                f"{1e6 * p['client_cpu'] / p['n_cases']:.0f}",
                f"{1e6 * extra[k]:.1f}" if largest and k in extra else "",
            ]
        )
    return rows


def notes(points: Sequence[dict]) -> list[str]:
    """The figures in words: the goal on two workers, the client's ceiling."""
    extra = per_extra_case(points)
    if 2 not in extra:
        return ["Two workers not measured in this run."]
    cpu = extra[2]
    verdict = "reached" if cpu <= CLIENT_GOAL else "not reached"
    best = max(points, key=lambda p: p["rate"])
    return [
        f"The client's CPU per extra case on two workers: **{1e6 * cpu:.1f} µs** (goal: at "
        f"most {1e6 * CLIENT_GOAL:.0f} µs, {verdict}): it could feed about "
        f"{1 / cpu:,.0f} cases a second, the workers computed at most {best['rate']:.0f} "
        f"({best['workers']} workers, {best['n_cases']} cases)."
    ]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m campipe.bench.cluster",
        description="A study with --parts on a local dask cluster of 1, 2, 4 worker "
        "processes: cases per second against the client's CPU per case.",
    )
    parser.add_argument("--quick", action="store_true", help="256 and 1024 cases, 1 and 2 workers")
    parser.add_argument("--json", type=Path, help="write the points to this file")
    args = parser.parse_args(argv)
    counts = QUICK_CLUSTER_COUNTS if args.quick else CLUSTER_COUNTS
    workers = QUICK_CLUSTER_WORKERS if args.quick else CLUSTER_WORKERS
    with tempfile.TemporaryDirectory(prefix="campipe-cluster-") as folder:
        points = as_dicts(cluster_scaling(folder, counts, workers))
    if args.json:
        args.json.write_text(json.dumps(points, indent=1) + "\n")
    print(" | ".join(HEADER))
    for row in table_rows(points):
        print(" | ".join(row))
    print("\n".join(notes(points)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
