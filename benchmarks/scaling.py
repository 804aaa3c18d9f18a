"""The study layer's scaling: the engine's scaling cases (``campipe.bench.scaling``) as a study.

- :func:`scaling_spec`: a spec of ``n`` cases, the speeds and seats of
  :func:`campipe.bench.scaling.scaling_cases` as a sweep.
- :func:`study_scaling`: that study through the study layer's executor
  (:func:`campipe.study.run.execute.run_study`), archive included, on 1 and 2 worker threads; the
  archive's size per case. Its points sit beside ``campipe bench``'s engine points (the same
  :class:`~campipe.bench.scaling.ScalingPoint`, layer ``"study"``).

Specs and archives are written under the directory given (and nowhere else).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

import yaml

from campipe.bench.scaling import SCALING_REVOLUTIONS, SPEED_RANGE, ScalingPoint
from campipe.study import load_study
from campipe.study.run.execute import run_study


def scaling_spec(n: int) -> dict:
    """A study spec of ``n`` cases like ``campipe.bench.scaling.scaling_cases`` (the speeds of a
    sweep)."""
    spec = {
        "name": f"bench-scaling-{n}",
        "description": "campipe bench: time against number of cases",
        "model": {"preset": "thesis-1971"},
        "profile": {"kind": "harmonic", "lift": "1 in"},
        "closure": "force",
        "seat": "none",
        "speed": "9000 rpm",
        "run": {"revolutions": SCALING_REVOLUTIONS, "output_every": "1 deg"},
    }
    if n > 1:
        half = n // 2
        spec["sweep"] = (
            {
                "speed": {
                    "from": f"{SPEED_RANGE[0]:g} rpm",
                    "to": f"{SPEED_RANGE[1]:g} rpm",
                    "num": max(half, 1),
                },
                "seat": ["none", "0.1 in"],
            }
            if n % 2 == 0
            else {
                "speed": {
                    "from": f"{SPEED_RANGE[0]:g} rpm",
                    "to": f"{SPEED_RANGE[1]:g} rpm",
                    "num": n,
                }
            }
        )
    return spec


def study_scaling(
    counts: Sequence[int], directory: str | Path, workers: Sequence[int] = (1, 2)
) -> list[ScalingPoint]:
    """Wall time of ``campipe study`` on n cases (spec check, batches, archive) and the
    archive's size; spec and archives are written under ``directory``."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    out = []
    for n in counts:
        path = directory / f"bench-scaling-{n}.yaml"
        path.write_text(yaml.safe_dump(scaling_spec(n), sort_keys=False))
        for w in workers:
            archive = directory / f"bench-scaling-{n}-w{w}.nc"
            archive.unlink(missing_ok=True)
            t0 = time.perf_counter()
            study = load_study(path)
            run_study(study, archive, scheduler="threads", workers=w)
            seconds = time.perf_counter() - t0
            out.append(ScalingPoint("study", len(study.cases), w, seconds, archive.stat().st_size))
    return out
