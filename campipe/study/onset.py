"""``campipe onset``: the no-follow onset speed of every combination of a spec's other axes,
found on the steady state by ``campipe.engine.onset``'s search and checked by the time-domain
engine either side of it.

Orchestration: a study in, an :class:`OnsetStudy` out; the netCDF file is written by
``campipe.io.archive``.
"""

from __future__ import annotations

import concurrent.futures
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from campipe.constants import RPM
from campipe.engine import onset as engine_onset
from campipe.engine.kernels import compile_first, record_loaded, search_kernels
from campipe.errors import CampipeError
from campipe.io.archive import VariableSpec
from campipe.study.query.tables import CaseTable
from campipe.study.spec.coordinates import key_columns, padded
from campipe.study.spec.expand import Study
from campipe.study.spec.variables import case_coordinates

#: The columns every onset table has after the varied parameters.
ONSET_COLUMNS = ("onset_speed_rpm", "onset_status", "leaves_cam_at_deg", "confirmed")


class OnsetError(CampipeError, ValueError):
    """A spec ``campipe onset`` cannot search (``key`` the spec key)."""


@dataclass(frozen=True)
class OnsetStudy:
    """The onset of each combination of a spec's other varied keys."""

    name: str  # the study's name
    keys: tuple[str, ...]  # the varied spec keys, speed left out
    table: CaseTable  # one row per combination: the keys' archive columns, then ONSET_COLUMNS
    onset: engine_onset.Onset  # the search's result (SI)
    #: (n,) the engine's no-follow per turn at onset·(1 − offset) [rad] (the mean over the
    #: check's measured turns); NaN: unchecked
    below: np.ndarray
    #: (n,) likewise at onset·(1 + offset), or nearer where that did not reach the level
    #: (``engine_onset.confirm_onsets``)
    above: np.ndarray
    #: (n,) the cam angle [rad] where the engine's no-follow first starts in the check above
    #: (``engine_onset.first_separation``); NaN: unchecked, or it did not
    where: np.ndarray
    above_speed: np.ndarray  # (n,) the speed the check above ran at [rad/s]; NaN: unchecked
    low: float  # the spec's speed range [rad/s]
    high: float
    search_seconds: float  # wall time of the search
    check_seconds: float  # wall time of the time-domain check
    spec_text: str = ""  # the spec as written (its units are the table's display units)
    spec_overrides: dict = field(default_factory=dict)  # its --set values

    @property
    def levels(self) -> np.ndarray:
        """(n,) the level each row's onset reaches [rad of no-follow a turn]; 0 without a
        seat (the first separation)."""
        level = self.onset.level
        return np.zeros(self.table.n) if level is None else level

    @property
    def disagreements(self) -> np.ndarray:
        """Rows whose time-domain check does not bracket the onset (``engine_onset.confirmed``):
        below it the engine reaches the level, or above it does not, or a run of the check
        failed (:attr:`failed_checks`)."""
        checked = np.isfinite(self.above_speed)
        return np.flatnonzero(
            checked & ~engine_onset.confirmed(self.below, self.above, self.levels)
        )

    @property
    def failed_checks(self) -> np.ndarray:
        """Rows whose check ran and could not tell: a run either side failed (its status not
        ok: unbounded, a step limit, …), its no-follow NaN."""
        return np.flatnonzero(_failed(self.above_speed, self.below, self.above))


def _failed(above_speed: np.ndarray, below: np.ndarray, above: np.ndarray) -> np.ndarray:
    """(n,) bool: the check ran (the speed above is set wherever it did) and a run of it
    failed (its no-follow NaN)."""
    return np.isfinite(above_speed) & ~(np.isfinite(below) & np.isfinite(above))


def _frozen(value: object) -> object:
    return tuple(value) if isinstance(value, list | tuple | np.ndarray) else value


def _combinations(study: Study) -> tuple[tuple[str, ...], list[int]]:
    """The varied keys other than the speed, and the first case of each combination of
    their values (in study order)."""
    values = [c.values for c in study.cases]
    keys = tuple(
        k
        for k in dict.fromkeys(k for v in values for k in v)
        if k != "speed" and len({repr(_frozen(v.get(k))) for v in values}) > 1
    )
    first: dict[tuple, int] = {}
    for i, v in enumerate(values):
        first.setdefault(tuple(repr(_frozen(v.get(k))) for k in keys), i)
    return keys, list(first.values())


def search_designs(
    designs, low, high, tolerance, workers, level=engine_onset.DEFAULT_ONSET_LEVEL
) -> engine_onset.Onset:
    """``engine_onset.onset_speeds`` on ``workers`` threads (the kernels release the GIL)."""
    n = len(designs)
    parts = [p for p in np.array_split(np.arange(n), min(max(1, workers), n)) if p.size]

    def search(part):
        return engine_onset.onset_speeds([designs[i] for i in part], low, high, tolerance,
                                     level=level)  # fmt: skip

    if len(parts) == 1:
        return search(parts[0])
    with concurrent.futures.ThreadPoolExecutor(len(parts)) as pool:
        done = list(pool.map(search, parts))
    first = done[0]
    return engine_onset.Onset(
        speed=np.concatenate([d.speed for d in done]),
        status=np.concatenate([d.status for d in done]),
        scan_speed=first.scan_speed,
        scan_margin=np.concatenate([d.scan_margin for d in done]),
        scan_no_follow=np.concatenate([d.scan_no_follow for d in done]),
        seated=np.concatenate([d.seated for d in done]),
        tolerance=first.tolerance,
        evaluations=np.concatenate([d.evaluations for d in done]),
        level=np.concatenate([d.level for d in done if d.level is not None]),
        proven=np.concatenate([d.proven for d in done if d.proven is not None]),
    )


def onset_study(
    study: Study,
    tolerance: float = engine_onset.DEFAULT_ONSET_TOLERANCE_RPM * RPM,
    *,
    level: float = engine_onset.DEFAULT_ONSET_LEVEL,
    confirm: bool = True,
    workers: int = 1,
    notice: Callable[[str], None] | None = None,
) -> OnsetStudy:
    """The no-follow onset of each combination of the study's varied keys but the speed,
    within the range of its speeds.

    Parameters
    ----------
    study : Study
        An expanded spec whose speeds span a range.
    tolerance : float
        The onset's tolerance [rad/s] (the width of its final bracket).
    level : float
        With a seat, the no-follow a turn [rad] the onset reaches (``engine_onset.onset_speeds``;
        0: the first separation). Without a seat the onset is the first separation.
    confirm : bool
        Check each onset with the time-domain engine at ±``engine_onset.CONFIRM_OFFSET``
        (``engine_onset.confirm_onsets``): below it must stay under the level, above reach it.
    workers : int
        Threads the search runs on.
    notice : callable, optional
        Given a line to show before numba compiles the search's kernels and the check's
        (not called when they are cached). Either way the check's are compiled first,
        beside the search's, in two processes (``campipe.engine.kernels.compile_kernels``).

    Raises
    ------
    OnsetError
        (key ``speed``) when the spec's speeds do not span a range; (key
        ``model.hla_leak_down``) for a train with a lash adjuster (``adjuster_refusal``).
    """
    speeds = np.array([c.case.speed for c in study.cases])
    low, high = float(speeds.min()), float(speeds.max())
    if not high > low:
        raise OnsetError.at(
            "speed",
            f"the spec runs one speed ({low / RPM:g} rpm); campipe onset searches a "
            "range: sweep it, e.g. sweep: {speed: {from: 6000 rpm, to: 14000 rpm, num: 2}}",
            found=low,
            expected="a speed range",
        )
    keys, firsts = _combinations(study)
    designs = [study.cases[i].case for i in firsts]
    refusal = engine_onset.adjuster_refusal(designs, "combination")
    if refusal:
        raise OnsetError.at(engine_onset.ADJUSTER_KEY, refusal, found="an adjuster")
    compile_first(
        {engine_onset.confirm_settings(): designs[0]} if confirm else {}, notice, search=True
    )
    t0 = time.perf_counter()
    onset = search_designs(designs, low, high, tolerance, workers, level)
    record_loaded(search_kernels())  # the search's kernels, compiled ahead or not
    t1 = time.perf_counter()
    nan = np.full(len(designs), np.nan)
    levels = onset.level if onset.level is not None else 0.0
    below, above, where, above_speed = (
        engine_onset.confirm_onsets(designs, onset.speed, level=levels)
        if confirm
        else (nan, nan, nan, nan)
    )
    t2 = time.perf_counter()
    table = _table(study, keys, firsts, onset, below, above, where, above_speed)
    spec = study.spec
    return OnsetStudy(
        study.name, keys, table, onset, below, above, where, above_speed, low, high, t1 - t0,
        t2 - t1,
        spec.text, dict(spec.overrides),
    )  # fmt: skip


def _table(study, keys, firsts, onset, below, above, where, above_speed) -> CaseTable:
    coords = case_coordinates(keys)
    columns = key_columns([study.cases[i] for i in firsts], {k: coords[k] for k in keys})
    units: dict[str, str] = {}
    for key in keys:
        name, var, _ = coords[key]
        units[name] = var.units if var.units and var.units != "1" else ""
    checked = np.isfinite(above_speed)
    failed = _failed(above_speed, below, above)
    agrees = engine_onset.confirmed(below, above, onset.level if onset.level is not None else 0.0)
    columns["onset_speed_rpm"] = onset.speed / RPM
    units["onset_speed_rpm"] = "rpm"
    columns["onset_status"] = onset.status.astype(object)
    units["onset_status"] = ""
    columns["leaves_cam_at_deg"] = np.degrees(where)
    units["leaves_cam_at_deg"] = "deg"
    confirmed = np.where(failed, "failed", np.where(agrees, "yes", "NO"))
    columns["confirmed"] = np.where(checked, confirmed, "-").astype(object)
    units["confirmed"] = ""
    return CaseTable(columns, units, list(columns), len(firsts), study.name)


# --------------------------------------------------------------------------- the file

#: How the check above the onset comes nearer (its long name's words).
_NEARER = (
    ", or where that does not reach the level the first of onset × (1 + "
    f"{', '.join(f'{f:g}' for f in engine_onset.CONFIRM_NEARER)}) that does (check_above_rpm)"
)


def file_contents(result: OnsetStudy) -> tuple[dict, list[VariableSpec], dict, dict]:
    """(sizes, variables, arrays, attributes) of the onset's netCDF file: one row per
    combination along ``combination``, the search's margins along ``scan``; SI but the
    speeds, in rpm as the study archive's ``speed_rpm``."""
    t = result.table
    on = result.onset
    n = t.n
    variables: list[VariableSpec] = []
    arrays: dict[str, np.ndarray] = {}

    def add(name, dims, dtype, values, **attrs):
        variables.append(VariableSpec(name, dims, dtype, attrs))
        arrays[name] = values

    sizes = {"combination": n, "scan": on.scan_speed.size}
    # a list per combination (masses, damping_ratios): one width for all, NaN beyond a list
    width = max((c.shape[1] for c in t.columns.values() if c.ndim == 2), default=0)
    for name in t.columns:
        if name in ONSET_COLUMNS:
            continue
        col = t.columns[name]
        units = {"units": t.units[name]} if t.units[name] else {}
        dims: tuple[str, ...] = ("combination",)
        if col.ndim == 2:
            col, dims, sizes["mode"] = padded(col, width), ("combination", "mode"), width
        add(name, dims, "str" if col.dtype == object else "f8", col, **units)
    add("onset_speed_rpm", ("combination",), "f8", t.columns["onset_speed_rpm"], units="rpm",
        long_name="no-follow onset speed of the cam (steady state; cam rpm; NaN: none inside "
        "the speed range)",
        tolerance_rpm=on.tolerance / RPM)  # fmt: skip
    add("onset_status", ("combination",), "str", t.columns["onset_status"],
        long_name="found; below: no-follow at the range's lowest speed; none: follows across "
        "the range")  # fmt: skip
    proven = on.proven if on.proven is not None else np.zeros(n, np.bool_)
    add("onset_proven", ("combination",), "i1", proven.astype(np.int8),
        long_name="1: every speed interval below the onset (or across the range) proven free "
        "of no-follow to the tolerance (configuration I's steady state, a profile without "
        "steps); 0: some certified on the chords' estimate (a seated steady state, a profile "
        "with steps)")  # fmt: skip
    add("onset_level_deg", ("combination",), "f8", np.degrees(result.levels), units="degree",
        long_name="no-follow a turn the onset reaches (0: the first separation; a level "
        "only with a seat)")  # fmt: skip
    for name, values, side in (
        ("check_below_deg", result.below, "1 −"),
        ("check_above_deg", result.above, "1 +"),
    ):
        add(name, ("combination",), "f8", np.degrees(values), units="degree",
            long_name=f"no-follow per turn, the mean over turns {engine_onset.CONFIRM_WARMUP + 1}"
            f"–{engine_onset.CONFIRM_TURNS} of the time-domain engine from the periodic start at "
            f"onset × ({side} {engine_onset.CONFIRM_OFFSET:g})"
            f"{_NEARER if side == '1 +' else ''}; NaN: not checked")  # fmt: skip
    add("check_above_rpm", ("combination",), "f8", result.above_speed / RPM, units="rpm",
        long_name="the speed the check above the onset ran at (check_above_deg, "
        "leaves_cam_at_deg); NaN: not checked")  # fmt: skip
    add("leaves_cam_at_deg", ("combination",), "f8", np.degrees(result.where), units="degree",
        long_name=f"cam angle where the time-domain engine's no-follow first starts (follower "
        "off the cam, valve off its seat) in the check above the onset (check_above_rpm), in "
        f"turns {engine_onset.CONFIRM_WARMUP + 1}–{engine_onset.CONFIRM_TURNS} (the events' "
        "angle within the turn); NaN: not checked, or it did not leave")  # fmt: skip
    add("confirmed", ("combination",), "str", t.columns["confirmed"],
        long_name="the time-domain check agrees: yes (under the level below the onset, at "
        "or over it above), NO (it disagrees), - (not checked)")  # fmt: skip
    add("scan_speed_rpm", ("scan",), "f8", on.scan_speed / RPM, units="rpm",
        long_name="speeds the search looked at first")  # fmt: skip
    add("margin", ("combination", "scan"), "f8", on.scan_margin, units="N",
        long_name="least cam compression over the steady turn (NaN: the valve seats on part "
        "of the turn)")  # fmt: skip
    add("no_follow", ("combination", "scan"), "i1", on.scan_no_follow.astype(np.int8),
        long_name="the steady state leaves the cam with the valve off its seat (with a seat: "
        "for at least the level a turn)")  # fmt: skip
    attrs: dict[str, object] = {
        "title": f"{result.name}: no-follow onset speeds",
        "study_name": result.name,
        "speed_range_rpm": [result.low / RPM, result.high / RPM],
        "varied_keys": ", ".join(result.keys),
        # each varied key's column, so that a reader shows it in the units the spec wrote
        "study_axes": json.dumps(
            [
                {"name": name, "key": key}
                for key, (name, *_) in case_coordinates(result.keys).items()
            ]
        ),
        "spec": result.spec_text,
        "spec_overrides": json.dumps(result.spec_overrides, default=str),
    }
    return sizes, variables, arrays, attrs


def summary_lines(result: OnsetStudy) -> list[str]:
    """What the command says after the table: the range, the cost, the check."""
    on = result.onset
    n = result.table.n
    lines = [
        f"{result.name}: {n} combination{'s' if n != 1 else ''}, speeds "
        f"{result.low / RPM:g} … {result.high / RPM:g} rpm, tolerance "
        f"{on.tolerance / RPM:g} rpm; search {result.search_seconds:.3g} s "
        f"({int(on.evaluations.sum())} steady states), time-domain check "
        f"{result.check_seconds:.3g} s",
    ]
    status = np.asarray(on.status)
    if on.proven is not None:
        estimated = int(np.count_nonzero(~on.proven))
        where = [w for w, there in (("below each onset found", "found"), ("in a range that "
                 "follows throughout", "none")) if (status == there).any()]  # fmt: skip
        if estimated:
            lines.append(
                f"{estimated} combination{'s' if estimated != 1 else ''} searched past "
                "speeds on the chords' estimate, not proven (a seated steady state or a profile "
                "with steps): a window of no-follow narrower than the scan may be missed"
            )
        elif where:
            lines.append(
                f"no window of no-follow wider than the tolerance {' and '.join(where)}: proven"
            )
    below = int(np.count_nonzero(status == "below"))
    if below:
        lines.append(
            f"{below} combination{'s leave' if below != 1 else ' leaves'} the cam already"
            f" at the range's lowest speed, {result.low / RPM:g} rpm: start the range "
            "lower to find the onset"
        )
    levels = np.degrees(result.levels)
    if (levels > 0).any():
        lines.append(
            f"with a seat the onset is where no-follow reaches {levels.max():g}° a turn "
            "(--level); without one, the first separation"
        )
    failed = result.failed_checks
    if failed.size:
        lines.append(
            f"the time-domain check failed on {failed.size} combination"
            f"{'s' if failed.size != 1 else ''} (rows {', '.join(map(str, failed[:10].tolist()))}):"
            " a run either side of the onset did not finish (unbounded, a step limit, …), so "
            "nothing confirms it; run those speeds with campipe study to see its status"
        )
    bad = np.setdiff1d(result.disagreements, failed)
    if bad.size:
        lines.append(
            f"the time-domain check disagrees on {bad.size} combination"
            f"{'s' if bad.size != 1 else ''} (rows {', '.join(map(str, bad[:10].tolist()))}): "
            "just below the onset it leaves the cam (reaches the level), or just above it "
            "does not"
        )
    return lines
