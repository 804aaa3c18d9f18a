"""The drive: a speed given as the engine's, and the crank angle (issue 37).

Every speed campipe computes with is the camshaft's, every angle the cam's. A spec may give
the engine's (crankshaft's) speed instead, with the drive's ratio::

    drive: {cam_per_crank: 0.5}        # a four-stroke engine: the cam turns once per two
    engine_speed: 6000 rpm             # the cam's speed is 3000 rpm
    sweep: {engine_speed: [4000 rpm, 6000 rpm]}

``engine_speed`` may go wherever ``speed`` may (the base, ``sweep``, ``zip``,
``sample.ranges``, ``cases``); before anything else is checked it is written as the cam's
``speed``, each value times ``cam_per_crank`` in the units it was written in (so a speed
sweep stays a speed sweep: the onset search and the cases' ids are the cam speed's). With a
drive, the archive carries beside ``speed_rpm`` (the cam's) the engine's speed
``engine_speed_rpm`` and, beside ``cam_angle``, the ``crank_angle`` (cam angle divided by the
ratio) (:mod:`campipe.study.archive.layout`). A spec without ``drive`` is unchanged.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

from campipe.study.spec.blocks import Problems, show
from campipe.study.spec.fields import ENGINE_SPEED, Field, SpecProblem
from campipe.units import QuantityError, parse_angular

#: The drive's keys.
DRIVE_FIELDS: dict[str, Field] = {
    "cam_per_crank": Field(
        "drive.cam_per_crank",
        "number",
        "camshaft turns per crankshaft turn (0.5 for a four-stroke engine): the cam's speed "
        "is the engine's times it, the crank angle the cam's divided by it",
        minimum=0.0,
        maximum=16.0,
    ),
}
#: The archive's names for the engine's speed and the crank angle.
ENGINE_SPEED_NAME = str(ENGINE_SPEED.archive_name)
CRANK_ANGLE_NAME = "crank_angle"
#: The key of a resolved case's values holding the drive's ratio.
RATIO_KEY = "drive.cam_per_crank"
_QUANTITY = re.compile(
    r"^\s*(?P<number>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(?P<units>.*)$"
)


def check_drive(value: object) -> float:
    """``drive: {cam_per_crank: 0.5}`` → 0.5; a SpecProblem naming the key otherwise."""
    if not isinstance(value, Mapping):
        raise SpecProblem(
            "drive", f"found {show(value)}, expected a mapping {{cam_per_crank: 0.5}}"
        )
    for k in value:
        if k not in DRIVE_FIELDS:
            raise SpecProblem(
                f"drive.{k}", f"not a key of drive; its keys: {', '.join(DRIVE_FIELDS)}"
            )
    if "cam_per_crank" not in value:
        raise SpecProblem("drive.cam_per_crank", "missing: camshaft turns per crankshaft turn")
    field = DRIVE_FIELDS["cam_per_crank"]
    return float(field.parse(value["cam_per_crank"], field.key))


def apply_drive(raw: Mapping, problems: Problems) -> tuple[Mapping, float | None]:
    """``raw`` with every ``engine_speed`` written as the cam's ``speed``, and the drive's
    ratio (None for a spec without ``drive``); each problem kept in ``problems``, at its key."""
    places = _places(raw)
    ratio = None
    if "drive" in raw:
        ratio = problems.check(check_drive, raw["drive"])
    if not any(ENGINE_SPEED.key in block for _, block in places):
        return raw, ratio
    out = _copy(raw)
    for path, block in _places(out):
        if ENGINE_SPEED.key not in block:
            continue
        at = f"{path}.{ENGINE_SPEED.key}" if path else ENGINE_SPEED.key
        value = block[ENGINE_SPEED.key]
        speed = None
        if "drive" not in raw:
            problems.add(at, "an engine speed needs the drive's ratio: drive: {cam_per_crank: 0.5}")
        elif "speed" in block:
            also = f"{path}.speed" if path else "speed"
            problems.add(at, f"give the cam's speed or the engine's, not both (also {also})")
        elif ratio is not None:
            speed = problems.check(_scaled, value, ratio, at)
        # in the engine speed's place: a sweep's first key stays outermost
        items = list(block.items())
        block.clear()
        for k, v in items:
            if k != ENGINE_SPEED.key:
                block[k] = v
            elif speed is not None:
                block["speed"] = speed
    return out, ratio


def _places(raw: Mapping) -> list[tuple[str, Any]]:
    """(path, mapping) of each place a speed may be written: the base, the axes, the cases."""
    out: list[tuple[str, Any]] = [("", raw)]
    for block in ("sweep", "zip"):
        if isinstance(raw.get(block), Mapping):
            out.append((block, raw[block]))
    sample = raw.get("sample")
    if isinstance(sample, Mapping) and isinstance(sample.get("ranges"), Mapping):
        out.append(("sample.ranges", sample["ranges"]))
    cases = raw.get("cases")
    if isinstance(cases, list):
        out += [(f"cases[{i}]", c) for i, c in enumerate(cases) if isinstance(c, Mapping)]
    return out


def _copy(raw: Mapping) -> dict:
    """A copy of ``raw`` whose places (:func:`_places`) are new dicts (the values shared)."""
    out = dict(raw)
    for block in ("sweep", "zip"):
        if isinstance(out.get(block), Mapping):
            out[block] = dict(out[block])
    if isinstance(out.get("sample"), Mapping):
        out["sample"] = dict(out["sample"])
        if isinstance(out["sample"].get("ranges"), Mapping):
            out["sample"]["ranges"] = dict(out["sample"]["ranges"])
    if isinstance(out.get("cases"), list):
        out["cases"] = [dict(c) if isinstance(c, Mapping) else c for c in out["cases"]]
    return out


def _scaled(value: object, ratio: float, path: str) -> object:
    """An engine speed as the cam's: each quantity's number times ``ratio``, in the units it
    was written in (a list, each; a range ``{from, to, num}``, its ends)."""
    if isinstance(value, list):
        return [_scaled(v, ratio, f"{path}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, Mapping):
        return {
            k: _scaled(v, ratio, f"{path}.{k}") if k in ("from", "to") else v
            for k, v in value.items()
        }
    try:
        parse_angular(value, "rad/s", path, "rpm")  # refused here, at the engine's key
    except QuantityError as exc:
        raise SpecProblem.from_error(exc, path) from None
    m = _QUANTITY.match(str(value))
    assert m is not None  # parse_angular read it
    return f"{float(m['number']) * ratio!r} {m['units'].strip()}"


def with_drive(values: dict[str, object], ratio: float) -> None:
    """A resolved case's values (``ResolvedCase.values``) with the drive's ratio
    (:data:`RATIO_KEY`): the same for every case, so nothing groups cases by it, and a
    speed sweep's cases (``SpeedSweep``) copy it with the rest."""
    values[RATIO_KEY] = ratio


def engine_speed(values: Mapping[str, object]) -> float:
    """A resolved case's engine speed [rad/s]: its cam's over the drive's ratio."""
    return float(values["speed"]) / float(values[RATIO_KEY])  # type: ignore[arg-type]
