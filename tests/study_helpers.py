"""Helpers shared by the study tests: writing specs, opening archives for comparison."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import xarray as xr

from campipe.study.spec.variables import VOLATILE_ATTRS

ROOT = Path(__file__).parents[1]
STUDIES = ROOT / "studies"
INCH = 0.0254
LBF = 4.4482216152605


def write_spec(directory: Path, text: str, name: str = "spec.yaml") -> Path:
    path = directory / name
    path.write_text(textwrap.dedent(text))
    return path


def load(path: Path) -> xr.Dataset:
    """An archive read into memory, without the provenance attributes that legitimately
    differ between two runs (host, UTC time, history)."""
    ds = xr.load_dataset(path)
    for name in VOLATILE_ATTRS:
        ds.attrs.pop(name, None)
    return ds


def die(plan):
    """A batch whose worker process dies (tests of a killed worker)."""
    import os

    os._exit(9)


def changed(base: dict, **changes: object) -> dict:
    """A deep copy of a raw spec with ``a__b=value`` setting ``raw["a"]["b"]``."""
    raw = json.loads(json.dumps(base))
    for key, value in changes.items():
        node = raw
        *parents, last = key.split("__")
        for p in parents:
            node = node.setdefault(p, {})
        node[last] = value
    return raw
