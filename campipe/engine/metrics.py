"""The per-turn metrics, declared once: name, units, reduction over a turn, description.

Every metric is a row of :data:`METRICS`. From the table follow

- the engine's per-turn output array (``common.Outputs.per_rev``, one column per row whose
  ``source`` is ``"engine"``, at the index :func:`column` gives it: the integrators
  accumulate into it with :data:`COLUMNS`' constants);
- :class:`~campipe.engine.batch.BatchResult`'s ``<key>_per_rev`` (SI, per case and turn) and
  ``<key>`` (over the measured turns, as the row's ``summary`` says);
- the archive's two variables per row (``per_rev`` per revolution, ``summary`` over the
  measured ones: :mod:`campipe.study.spec.variables`), and so ``campipe query``'s columns;
- the variable table of ``docs/studies.md`` (``python -m campipe.engine.metrics``).

Adding a metric an integrator produces is its row here plus the lines in each integrator
that accumulate it into its column. A metric computed from what a run already gives (its
histories, or other metrics) is its row with a ``derive`` function and nothing else
(:func:`register` adds one at run time; the tests add a toy one that way).

No numba here: the study layer reads the table without loading the kernels.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from campipe.engine.loads import per_turn, pushing_joints, turn_maxima
from campipe.model.contact import contact_law
from campipe.model.hla import taken_up

#: Reductions over a turn, and what the summary over the measured turns takes of them: an
#: angle or a count accumulated over the turn reads as its mean per turn; an extreme as the
#: extreme of the turns.
SUMMARY = {"sum": "mean", "count": "mean", "max": "max", "min": "min"}
#: How an archive's long name says the summary.
READS = {"mean": "per revolution, mean over", "max": "largest in", "min": "least in"}
#: Contiguous batches a window of turns is split into for its mean's standard error
#: (:func:`batch_means_error`).
BATCHES = 4
#: The suffix of the archive's name of a mean metric's uncertainty (``<summary>_uncertainty``).
UNCERTAINTY = "_uncertainty"


@dataclass(frozen=True)
class Metric:
    """One per-turn metric."""

    key: str  # BatchResult's name: ``<key>_per_rev`` per turn, ``<key>`` summary (SI)
    summary: str  # the archive's (and query's) name of the summary over the measured turns
    per_rev: str  # the archive's name of the per-revolution values
    description: str  # what it is (the archive's long name starts with it)
    units: str | None  # the archive's units (pint spelling; None for a count)
    reduction: str  # over a turn: "sum", "count", "max" or "min" (:data:`SUMMARY`)
    si_units: str | None = None  # the engine's units where the archive's differ (rad)
    dtype: str = "f8"  # the archive's type per revolution ("i4" for counts)
    record: str | None = None  # the run.record item that stores it (None: always)
    source: str = "engine"  # "engine": an integrator accumulates it; "derived": ``derive``
    archived: bool = True  # stored in a study's archive
    #: (result, per-case trains) → (n_cases, n_turns) SI values, for a derived metric
    derive: Callable[[Any, Any], np.ndarray] | None = None
    label: str = ""  # a figure's words for it ("No-follow"); "": its description's first words

    @property
    def summary_of_turns(self) -> str:
        """How the summary reads the measured turns: "mean", "max" or "min"."""
        return SUMMARY[self.reduction]

    @property
    def uncertainty(self) -> str | None:
        """The archive's name of its summary's standard error where the response never
        repeats (:func:`batch_means_error`): a mean's only; None for a max or a min."""
        return self.summary + UNCERTAINTY if self.summary_of_turns == "mean" else None

    def to_archive(self, values: np.ndarray) -> np.ndarray:
        """SI per-turn values in the archive's units."""
        return np.degrees(values) if self.si_units == "rad" else values

    def summarise(self, values: np.ndarray, measured: np.ndarray) -> np.ndarray:
        """(n_cases,) the summary of (n_cases, n_turns) values over the ``measured`` turns:
        (n_turns,) for every case, or (n_cases, n_turns) each case's own (a run of automatic
        length; a turn whose value is NaN, beyond a case's run, is left out)."""
        if measured.ndim == 2:
            return self._summarise_windows(values, measured)
        kept = values[:, measured]
        how = self.summary_of_turns
        return (
            kept.mean(axis=1)
            if how == "mean"
            else kept.max(axis=1)
            if how == "max"
            else (kept.min(axis=1))
        )

    def _summarise_windows(self, values: np.ndarray, measured: np.ndarray) -> np.ndarray:
        kept = np.where(measured, values, np.nan)
        out = np.full(values.shape[0], np.nan)
        some = np.isfinite(kept).any(axis=1)
        how = self.summary_of_turns
        reduce = np.nanmean if how == "mean" else np.nanmax if how == "max" else np.nanmin
        out[some] = reduce(kept[some], axis=1)
        return out


def batch_means_error(
    values: np.ndarray, measured: np.ndarray, batches: int = BATCHES
) -> np.ndarray:
    """(n_cases,) the standard error of each case's mean of ``values`` over its ``measured``
    turns, by batch means: the turns (those measured with a finite value, in order) split into
    ``batches`` contiguous batches of as equal a length as they allow, the standard deviation
    of the batch means (n − 1) over √batches. NaN for a case with fewer than two such turns
    (fewer turns than batches: a batch per turn).

    Successive turns of a response that never repeats are correlated (a turn starts where
    the last ended), so the naive standard error of the mean, the turns' standard deviation
    over √n, misstates it: by about √((1 + ρ)/(1 − ρ)) for a lag-one correlation ρ (too small
    for ρ > 0). Batches several turns long are nearly independent of each other, and their
    means' spread carries the correlation within them.

    Parameters
    ----------
    values : (n_cases, n_turns) array
        A metric per turn (NaN where a case did not run the turn).
    measured : (n_turns,) or (n_cases, n_turns) bool array
        The turns of each case's window.
    batches : int
        How many contiguous batches.
    """
    values = np.asarray(values, float)
    window = np.broadcast_to(measured, values.shape) & np.isfinite(values)
    out = np.full(values.shape[0], np.nan)
    for i in range(values.shape[0]):
        turns = values[i, window[i]]
        k = min(batches, turns.size)
        if k < 2:
            continue
        means = np.array([b.mean() for b in np.array_split(turns, k)])
        out[i] = means.std(ddof=1) / np.sqrt(k)
    return out


def _pressure(side: int) -> Callable[[Any, Any], np.ndarray]:
    def derive(result, trains) -> np.ndarray:
        # A pressure rises with its force: the turn's peak pressure is its peak force's, on
        # one radius of curvature (``cam_curvature_radius``, ``seat_contact_radius``).
        force = result.max_cam_force_per_rev if side == 0 else result.max_seat_force_per_rev
        contact = ("cam", "seat")[side]
        out = np.stack(
            [contact_law(t, contact).pressure(force[i]) for i, t in enumerate(trains)]
        ).reshape(force.shape)
        radius = result.cam_contact_radius if side == 0 else np.zeros((0, 0))
        theta = np.asarray(result.cam_angle, float)
        for i in range(radius.shape[0]):
            # The cam's radius over the turn (``engine.levers.contact_radii``): each turn's
            # largest F/R', the samples' and the exact peak's at its sample's radius.
            if np.isnan(radius[i]).all():
                continue
            load = turn_maxima(np.maximum(result.cam_force[i], 0.0), 1.0 / radius[i], theta,
                               force[i])  # fmt: skip
            out[i] = contact_law(trains[i], contact).line_pressure(load)
        return out

    return derive


def _spring(name: str, how: str) -> Callable[[Any, Any], np.ndarray]:
    def derive(result, trains) -> np.ndarray:
        histories = result.spring_histories()
        return per_turn(histories[name], result.cam_angle, result.n_turns, how)

    return derive


def _least_joint_force(result, trains) -> np.ndarray:
    least = np.full(result.q.shape[:2], np.nan)
    for i, train in enumerate(trains):
        joints = pushing_joints(train, result.q[i], result.extension_of(i))
        if joints.shape[-1]:
            least[i] = joints.min(axis=-1)
    return per_turn(least, result.cam_angle, result.n_turns, "min")


def _adjuster(column: int, less_lash: bool = False) -> Callable[[Any, Any], np.ndarray]:
    def derive(result, trains) -> np.ndarray:
        # a run with a hydraulic lash adjuster keeps them per turn (engine.lash_adjuster)
        table = result.lash_adjuster
        if not table.size:
            return np.full(result.per_rev.shape[:2], np.nan)
        values = table[:, :, column]
        if less_lash:  # the effective lash: the dry lash less what the plunger takes up
            pairs = zip(trains, values, strict=True)
            values = np.stack([t.lash - taken_up(t, v) for t, v in pairs])
        return values

    return derive


def _adjuster_metric(key: str, what: str, reduction: str, derive, label: str) -> Metric:
    return Metric(key, key, f"{key}_by_rev", what, "m", reduction, record="lash_adjuster",
                  source="derived", derive=derive, label=label)  # fmt: skip


#: The metrics, in the engine's column order (those of source "engine" first).
METRICS: list[Metric] = [
    Metric(
        "separation",
        "separation_deg_per_rev",
        "separation_deg",
        "no-follow: cam angle in configuration II (follower off the cam, valve off its seat)",
        "degree",
        "sum",
        si_units="rad",
        label="No-follow",
    ),
    Metric(
        "seated_off_cam",
        "seated_off_cam_deg_per_rev",
        "seated_off_cam_deg",
        "cam angle in configuration IV (valve seated, follower off the cam: the lash)",
        "degree",
        "sum",
        si_units="rad",
        label="Seated off the cam",
    ),
    Metric(
        "cam_impacts",
        "cam_impacts",
        "cam_impacts_by_rev",
        "cam impacts",
        None,
        "count",
        dtype="i4",
        label="Cam impacts",
    ),  # fmt: skip
    Metric(
        "seat_impacts",
        "seat_impacts",
        "seat_impacts_by_rev",
        "valve seat impacts",
        None,
        "count",
        dtype="i4",
        label="Seat impacts",
    ),  # fmt: skip
    Metric(
        "max_cam_impact_velocity",
        "max_cam_impact_velocity",
        "max_cam_impact_velocity_by_rev",
        "largest closing velocity at a cam impact",
        "m/s",
        "max",
        label="Cam impact velocity",
    ),
    Metric(
        "max_seating_velocity",
        "max_seating_velocity",
        "max_seating_velocity_by_rev",
        "largest closing velocity at a seat impact",
        "m/s",
        "max",
        label="Seating velocity",
    ),
    Metric(
        "max_cam_force",
        "max_cam_force",
        "max_cam_force_by_rev",
        "largest compressive cam force between impacts",
        "N",
        "max",
        label="Cam force",
    ),
    Metric(
        "max_seat_force",
        "max_seat_force",
        "max_seat_force_by_rev",
        "largest compressive seat force between impacts",
        "N",
        "max",
        label="Seat force",
    ),
    Metric(
        "thesis_impact_force",
        "thesis_impact_force",
        "thesis_impact_force_by_rev",
        "largest cam force including the steps an impact's impulse passes through (the "
        "thesis's impact force; measures 1/dt for newmark-linear)",
        "N",
        "max",
        archived=False,
        label="Cam force with impacts",
    ),
    Metric(
        "max_roller_force",
        "max_roller_force",
        "max_roller_force_by_rev",
        "a lever layout's largest normal force of its roller on the cam between impacts (0 for "
        "any other; its max_cam_force in an archive: campipe.engine.levers)",
        "N",
        "max",
        archived=False,
        label="Roller force",
    ),
    Metric(
        "max_cam_pressure",
        "max_cam_pressure",
        "max_cam_pressure_by_rev",
        "peak Hertz pressure at the cam contact",
        "Pa",
        "max",
        record="contact_pressure",
        source="derived",
        derive=_pressure(0),
        label="Cam contact pressure",
    ),
    Metric(
        "max_seat_pressure",
        "max_seat_pressure",
        "max_seat_pressure_by_rev",
        "peak Hertz pressure at the valve seat contact",
        "Pa",
        "max",
        record="contact_pressure",
        source="derived",
        derive=_pressure(1),
        label="Seat contact pressure",
    ),
    Metric(
        "max_spring_force",
        "max_spring_force",
        "max_spring_force_by_rev",
        "largest compressive force along the valve spring (any element) at the output angles",
        "N",
        "max",
        record="spring",
        source="derived",
        derive=_spring("max_spring_element_force", "max"),
        label="Largest spring force",
    ),
    Metric(
        "min_spring_clash_margin",
        "min_spring_clash_margin",
        "min_spring_clash_margin_by_rev",
        "least valve spring coil-clash margin at the output angles",
        "m",
        "min",
        record="spring",
        source="derived",
        derive=_spring("spring_clash_margin", "min"),
        label="Coil-clash margin",
    ),
    Metric(
        "min_joint_force",
        "min_joint_force",
        "min_joint_force_by_rev",
        "least force at the output angles through the joints that only push in the hardware "
        "(a chain's links; the thesis train's pushrod ends and its rocker on the valve's "
        "tip), compressive positive: below 0 the model's two-sided joint pulls",
        "N",
        "min",
        record="member_loads",
        source="derived",
        derive=_least_joint_force,
        label="Joint force",
    ),
    _adjuster_metric(
        "hla_extension",
        "hydraulic lash adjuster's plunger extension from bottomed out at the turn's start",
        "max",
        _adjuster(0),
        "Plunger extension",
    ),  # fmt: skip
    _adjuster_metric(
        "hla_lash",
        "effective lash at the turn's start: the dry lash less what the lash adjuster's "
        "extension takes up (a few µm below 0 once pumped up: its check force presses the "
        "train; the valve is held off its seat only below minus the seated spring force "
        "over the train's stiffness from the adjuster to the seat)",
        "min",
        _adjuster(0, less_lash=True),
        "Effective lash",
    ),  # fmt: skip
    _adjuster_metric(
        "hla_leak_down",
        "hydraulic lash adjuster's leak-down over the turn (check valve closed)",
        "sum",
        _adjuster(1),
        "Leak-down",
    ),  # fmt: skip
    _adjuster_metric(
        "hla_pump_up",
        "hydraulic lash adjuster's pump-up over the turn (check valve open)",
        "sum",
        _adjuster(2),
        "Pump-up",
    ),  # fmt: skip
]

#: The engine's columns: every metric an integrator accumulates, in the table's order. Fixed
#: at import: the compiled kernels take these indices as constants.
ENGINE = tuple(m.key for m in METRICS if m.source == "engine")


def column(key: str) -> int:
    """The column of an engine metric in ``Outputs.per_rev``."""
    return ENGINE.index(key)


#: The engine metrics' columns by name, for the kernels (module-level constants numba folds).
SEPARATION = column("separation")
SEATED_OFF_CAM = column("seated_off_cam")
CAM_IMPACTS = column("cam_impacts")
SEAT_IMPACTS = column("seat_impacts")
MAX_CAM_IMPACT_VELOCITY = column("max_cam_impact_velocity")
MAX_SEATING_VELOCITY = column("max_seating_velocity")
MAX_CAM_FORCE = column("max_cam_force")
MAX_SEAT_FORCE = column("max_seat_force")
THESIS_IMPACT_FORCE = column("thesis_impact_force")
MAX_ROLLER_FORCE = column("max_roller_force")
N_ENGINE = len(ENGINE)


def by_key() -> dict[str, Metric]:
    """The metrics by key (the table as it is now, rows registered at run time included)."""
    return {m.key: m for m in METRICS}


def archived_metrics() -> list[Metric]:
    """The metrics a study's archive stores (those of the table as it is now)."""
    return [m for m in METRICS if m.archived]


def register(metric: Metric) -> None:
    """Add a derived metric to the table (an engine metric needs its integrators' code, so
    it is a row written above, not registered)."""
    if metric.source != "derived" or metric.derive is None:
        raise ValueError(f"{metric.key}: only a derived metric (with derive) is registered")
    if metric.key in by_key():
        raise ValueError(f"{metric.key}: a metric of that name exists")
    METRICS.append(metric)


@contextmanager
def registered(metric: Metric) -> Iterator[Metric]:
    """:func:`register` for the duration of a ``with`` block."""
    register(metric)
    try:
        yield metric
    finally:
        METRICS.remove(metric)


def markdown_table() -> str:
    """The metrics as the Markdown table of ``docs/studies.md``."""
    lines = [
        "| summary | per revolution | units | over a turn | summary of the turns | record | "
        "what it is |",
        "|---|---|---|---|---|---|---|",
    ]
    for m in METRICS:
        if not m.archived:
            continue
        lines.append(
            f"| `{m.summary}` | `{m.per_rev}` | {m.units or '– (none)'} | {m.reduction} | "
            f"{m.summary_of_turns} | {m.record or 'always'} | {m.description} |"
        )
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover - the docs' table
    sys.stdout.write(markdown_table() + "\n")
