"""A batch's results: histories at the output angles and the metrics of
:mod:`campipe.engine.metrics` per turn, SI; and the merge of the results of a batch's parts.

No numba here: results are plain arrays.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from campipe.constants import TWO_PI
from campipe.engine import metrics
from campipe.engine.loads import member_loads, spring_histories
from campipe.model import ValveTrain
from campipe.vocabulary import CAM, FAILURES, N_EVENT_FIELDS, SEAT


def _none(dtype) -> np.ndarray:
    empty = np.zeros(0, dtype)
    empty.flags.writeable = False
    return empty


#: The empty fields of a run of fixed length (those of a run of automatic length or with a
#: lash adjuster), shared by every result: read-only, with no element to write (five
#: allocations a call fewer; ``merge_results`` shares a part's empty fields likewise).
_NONE_INT, _NONE_FLOAT = _none(np.int64), _none(np.float64)
#: A run's ``lash_adjuster`` without one (shared: its size 0 says so, nothing writes to it).
NO_TABLE = _NONE_FLOAT


@dataclass
class BatchResult:
    """Histories at the output angles and metrics at full internal resolution, SI.

    Every metric of :data:`campipe.engine.metrics.METRICS` reads per turn as
    ``<key>_per_rev`` ((n_cases, n_rev)) and as ``<key>``, its summary over the measured
    turns (those after ``warmup``: the largest of a maximum, the mean per turn of a count or
    an angle): ``result.separation_per_rev``, ``result.max_cam_force``. The engine's metrics
    come from the integrators (``per_rev``); a derived one is computed when first read.
    """

    cam_angle: np.ndarray  # (n_out,) cam angle of each sample [rad]
    time: np.ndarray  # (n_cases, n_out) [s]
    #: (n_cases, n_out, n) coordinates [m, rad]: q1 … q7, then the internal coordinates of
    #: refined members (``campipe.model.coordinates``); n is the batch's most coordinates, a
    #: train with fewer has NaN beyond its own
    q: np.ndarray
    v: np.ndarray  # (n_cases, n_out, n) velocities [m/s, rad/s]
    acc: np.ndarray  # (n_cases, n_out, 2) accelerations of q1 and q7 [m/s²]
    cam_lift: np.ndarray  # (n_cases, n_out) [m]
    cam_force: np.ndarray  # (n_cases, n_out) cam contact force, compressive positive [N]
    seat_force: np.ndarray  # (n_cases, n_out) seat contact force, compressive positive [N]
    contact_state: np.ndarray  # (n_cases, n_out) int8, 1–4 = configurations I–IV
    #: (n_cases,) q7 at zero valve lift [m]: the valve's static position on the base circle
    #: with no seat, or its seated one in a train with lash (``Case.lift_zero``)
    valve_reference: np.ndarray
    #: (n_rev,) bool: the turn counts in the summaries (after warm-up); (n_cases, n_rev) for
    #: a run of automatic length (``engine.settle``): each case's settled window
    measured: np.ndarray
    #: (n_cases, n_rev, metrics.N_ENGINE) the engine's metrics per turn, in the columns of
    #: ``metrics.ENGINE`` (NaN for a failed case)
    per_rev: np.ndarray
    trains: list[ValveTrain]  # each case's train (for the derived metrics)
    #: per case (n_ev, 6): columns vocabulary.EV_*
    events: list[np.ndarray] = field(default_factory=list)
    steps: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (n_cases,)
    #: (n_cases,) int64 vocabulary status: OK, EVENTS_TRUNCATED, or (``on_failure="record"``)
    #: a failure (``vocabulary.FAILURES``) whose histories and metrics are NaN
    status: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    start_time: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n_cases,) t0 ≤ 0 [s]
    # A run of automatic length (``engine.settle``) says how each case settled (empty else):
    #: (n_cases,) the period its response repeats with [turns]; 0: it did not within the cap
    period_turns: np.ndarray = field(default_factory=lambda: _NONE_INT)
    #: (n_cases,) the first turn (from 0) of its metrics' window
    settled_turn: np.ndarray = field(default_factory=lambda: _NONE_INT)
    turns_run: np.ndarray = field(default_factory=lambda: _NONE_INT)  # (n_cases,)
    #: (n_cases,) the turn (from 0) its histories and events start at
    recorded_from: np.ndarray = field(default_factory=lambda: _NONE_INT)
    #: (n_cases, n_rev, 3) a run with a hydraulic lash adjuster (``engine.lash_adjuster``):
    #: each turn's plunger extension at its start, leak-down and pump-up [m]; empty else
    lash_adjuster: np.ndarray = field(default_factory=lambda: _NONE_FLOAT)
    #: (n_cases, n_out) a run with a hydraulic lash adjuster: its plunger's extension at each
    #: sample [m] where it lengthens a chain's link (which its member loads need: the link's
    #: force is k·(x₁ − x₂ + e)), NaN where it raises a finger's pivot or there is none;
    #: empty else
    extension: np.ndarray = field(default_factory=lambda: _NONE_FLOAT)
    #: (n_cases, n_out) the cam contact's relative radius of curvature R' at each sample [m]
    #: where the cam's shape is known (a line contact on a cam of given ``cam_base_radius``:
    #: ``engine.levers.at_the_cam``), NaN else; empty before that (the Hertz pressure then
    #: takes ``cam_curvature_radius``)
    cam_contact_radius: np.ndarray = field(default_factory=lambda: _NONE_FLOAT)
    _derived: dict[str, object] = field(default_factory=dict, repr=False, compare=False)

    @property
    def n_turns(self) -> int:
        """Turns of the run, a partial last one included."""
        return int(self.per_rev.shape[1])

    def metric_per_rev(self, key: str) -> np.ndarray:
        """(n_cases, n_rev) a metric per turn, SI (``metrics.METRICS``' key)."""
        metric = metrics.by_key()[key]
        if metric.source == "engine":
            return self.per_rev[:, :, metrics.column(key)]
        cached = self._derived.get(key)
        if cached is None:
            assert metric.derive is not None
            if self.recorded_from.size:
                cached = self._derived[key] = self._derived_in_window(metric)
            else:
                cached = self._derived[key] = np.asarray(metric.derive(self, self.trains), float)
        return cached  # type: ignore[return-value]

    def _derived_in_window(self, metric) -> np.ndarray:
        """A derived metric of a run of automatic length: its histories hold each case's last
        recorded turns only, so it is derived on those turns and placed at theirs (NaN at the
        others, which its summary then leaves out)."""
        if metric.record == "lash_adjuster":  # a table of every turn run, not histories
            return np.asarray(metric.derive(self, self.trains), float)
        recorded = int(round(self.cam_angle[-1] / TWO_PI))
        turns = self.recorded_from[:, None] + np.arange(recorded)
        window = dataclasses.replace(
            self,
            per_rev=np.take_along_axis(self.per_rev, turns[:, :, None], axis=1),
            measured=np.ones(recorded, np.bool_),
            recorded_from=np.zeros(0, np.int64),
            _derived={},
        )
        values = np.asarray(metric.derive(window, self.trains), float)
        out = np.full(self.per_rev.shape[:2], np.nan)
        np.put_along_axis(out, turns, values, axis=1)
        return out

    def metric(self, key: str) -> np.ndarray:
        """(n_cases,) a metric's summary over the measured turns, SI."""
        return metrics.by_key()[key].summarise(self.metric_per_rev(key), self.measured)

    def spring_histories(self) -> dict[str, np.ndarray]:
        """The spring's histories (``engine.loads.SPRING_HISTORIES``) of each case's train,
        (n_cases, n_out) each, computed once from q."""
        return self._histories("spring_histories", spring_histories)

    def member_loads(self) -> dict[str, np.ndarray]:
        """The member loads (``engine.loads.MEMBER_LOADS``) of each case's train,
        (n_cases, n_out) each, computed once from q (and a chain's adjuster's extension)."""
        return self._histories("member_loads", member_loads, self.extension_of)

    def extension_of(self, i: int) -> np.ndarray | None:
        """Case ``i``'s adjuster's extension at each sample [m] where it lengthens a chain's
        link (:attr:`extension`), else None."""
        if not self.extension.size or not np.isfinite(self.extension[i]).any():
            return None
        return self.extension[i]

    def _histories(self, key: str, of, extension=None) -> dict[str, np.ndarray]:
        cached = self._derived.get(key)
        if cached is None:
            per_case = [
                of(t, self.q[i]) if extension is None else of(t, self.q[i], extension(i))
                for i, t in enumerate(self.trains)
            ]
            cached = self._derived[key] = {
                name: np.stack([p[name] for p in per_case]) for name in per_case[0]
            }
        return cached  # type: ignore[return-value]

    def __getattr__(self, name: str) -> np.ndarray:
        # Only names not found otherwise: a metric's ``<key>_per_rev`` or ``<key>``.
        if not name.startswith("_"):
            table = metrics.by_key()
            if name.endswith("_per_rev") and name[: -len("_per_rev")] in table:
                return self.metric_per_rev(name[: -len("_per_rev")])
            if name in table:
                return self.metric(name)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @property
    def follower_lift(self) -> np.ndarray:
        """(n_cases, n_out) pushrod foot height in the cam's lift coordinate [m]."""
        return -self.q[:, :, CAM]

    @property
    def valve_lift(self) -> np.ndarray:
        """(n_cases, n_out) valve opening from its base-circle static position, or from its
        seat in a train with lash [m]."""
        return self.q[:, :, SEAT] - self.valve_reference[:, None]

    @property
    def valve_velocity(self) -> np.ndarray:
        """(n_cases, n_out) valve opening velocity [m/s]."""
        return self.v[:, :, SEAT]

    @property
    def valve_acceleration(self) -> np.ndarray:
        """(n_cases, n_out) valve opening acceleration [m/s²]."""
        return self.acc[:, :, 1]

    @property
    def follower_acceleration(self) -> np.ndarray:
        """(n_cases, n_out) pushrod foot acceleration in the cam's lift coordinate [m/s²]."""
        return -self.acc[:, :, 0]


#: What a failed case (``vocabulary.FAILURES``) of a result shows as NaN: its histories and
#: its per-turn metrics.
BLANKED = ("q", "v", "acc", "cam_lift", "cam_force", "seat_force", "per_rev")


def blank_failures(result: BatchResult) -> BatchResult:
    """``result`` with its failed cases' histories and per-turn metrics NaN (in place)."""
    failed = np.isin(result.status, FAILURES)
    for name in BLANKED:
        getattr(result, name)[failed] = np.nan
    if result.extension.size:
        result.extension[failed] = np.nan
    return result


#: A result's histories: one value per output sample (``cam_angle`` and these, per case).
HISTORIES = ("time", "q", "v", "acc", "cam_lift", "cam_force", "seat_force", "contact_state")


def thinned(result: BatchResult, every: int) -> BatchResult:
    """``result`` with every ``every``-th of its output samples, from the first: the
    histories of a run sampled ``every`` times finer than its output."""
    if every == 1:
        return result
    kept = {name: getattr(result, name)[:, ::every] for name in HISTORIES}
    if result.extension.size:
        kept["extension"] = result.extension[:, ::every]
    return dataclasses.replace(result, cam_angle=result.cam_angle[::every], **kept, _derived={})


#: Fields of a result shared by its parts (not per case).
_SHARED = ("cam_angle",)
#: Per-case fields held in lists.
_LISTS = ("events", "trains")


def merge_results(n: int, parts: Sequence[tuple[np.ndarray, BatchResult]]) -> BatchResult:
    """One batch's result from the results of its parts, each with the indices of its cases
    (in order, covering 0 … n − 1 once); q and v padded with NaN to the most coordinates."""
    if len(parts) == 1:
        return parts[0][1]
    merged: dict[str, object] = {}
    first = parts[0][1]
    n_q = max(part.q.shape[2] for _, part in parts)
    for f in dataclasses.fields(BatchResult):
        if f.name == "_derived":
            continue
        if f.name in ("lash_adjuster", "extension"):  # a part without an adjuster: NaN
            merged[f.name] = _merged_adjusters(n, parts, f.name)
            continue
        value = getattr(first, f.name)
        if f.name in _SHARED:
            merged[f.name] = value
        elif (f.name == "measured" and value.ndim == 1) or (
            f.name not in _LISTS and value.size == 0  # a field of automatic length's
        ):
            merged[f.name] = value
        elif f.name in _LISTS:
            empty = np.zeros((0, N_EVENT_FIELDS)) if f.name == "events" else None
            items: list[object] = [empty] * n
            for index, part in parts:
                for j, i in enumerate(index):
                    items[i] = getattr(part, f.name)[j]
            merged[f.name] = items
        else:
            shape = (n, *value.shape[1:2], n_q) if f.name in ("q", "v") else (n, *value.shape[1:])
            array = np.full(shape, np.nan) if f.name in ("q", "v") else np.empty(shape, value.dtype)
            for index, part in parts:
                part_value = getattr(part, f.name)
                if f.name in ("q", "v"):
                    array[index, :, : part_value.shape[2]] = part_value
                else:
                    array[index] = part_value
            merged[f.name] = array
    return BatchResult(**merged)  # type: ignore[arg-type]


def _merged_adjusters(
    n: int, parts: Sequence[tuple[np.ndarray, BatchResult]], name: str = "lash_adjuster"
) -> np.ndarray:
    """The parts' ``lash_adjuster`` tables (or ``extension`` histories) as one, NaN for the
    cases of a part without one (empty if no part has one)."""
    tables = [(index, getattr(part, name)) for index, part in parts if getattr(part, name).size]
    if not tables:
        return np.zeros(0)
    out = np.full((n, *tables[0][1].shape[1:]), np.nan)
    for index, table in tables:
        out[index] = table
    return out
