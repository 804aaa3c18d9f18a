"""The whole bench as one call: suite × methods × ladders, references, peers, ratios, scaling.

:func:`run_bench` returns a :class:`Bench` of plain rows and numbers and writes nothing;
``campipe.bench.report`` turns a Bench into a table and a plot. campipe's own latencies and
its study layer are the developer's benchmark's (``benchmarks/`` in the repository), not
this one's.
"""

from __future__ import annotations

import logging
import math
import os
import platform
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from campipe.bench import cluster, measure, memory, onset, scaling, settling, sweep
from campipe.bench.ivp import ChatterError
from campipe.bench.suite import FULL, QUICK, Ladder, Scene, suite
from campipe.constants import INCH
from campipe.engine import RunSettings
from campipe.vocabulary import EV_KIND, EVENT_KINDS

log = logging.getLogger(__name__)

#: The default integrator's settings as a study gets them (modal-exact, its own steps).
DEFAULT = RunSettings()
#: The thesis algorithm at the thesis's step (1 µs): the peer the speed goals compare with.
THESIS_STEP = 1e-6
#: Accuracy for cost on 11000 rpm: the valve-lift error the default must reach, and the error
#: at which newmark-linear's cheapest step is timed [m].
ACCURACY_DEFAULT_ERROR = 1e-6 * INCH
ACCURACY_NEWMARK_ERROR = 1e-3 * INCH
ACCURACY_SCENE = "separation-11000"
#: Speed goals at equal valve-lift error: the default this many times faster than solve_ivp
#: and than newmark-linear; reported, not asserted.
GOAL_IVP = 100.0
GOAL_NEWMARK = 10.0
#: The throughput goal: newmark-linear's throughput on the 256-case batch with this many workers
#: [case-steps/s], judged in the verdict (``campipe.bench.verdict``).
GOAL_THROUGHPUT = 2e7
GOAL_THROUGHPUT_WORKERS = 2
#: Cam turns per scene in --quick: past 11000 rpm's first re-impact (431°) and bounce.
QUICK_REVOLUTIONS = 1.5
#: Scaling counts: the full run, and --quick.
SCALING_COUNTS = (1, 10, 100, 1000, 10000)
QUICK_SCALING_COUNTS = (1, 16, 256)

#: Families of rows: how each is labelled in the table and the plot.
FAMILIES = (
    "modal-exact",
    "modal-exact capped",
    "contacts only",
    "newmark-linear",
    "solve_ivp",
)


#: The error columns of a run that failed.
FAILED = {
    "valve_lift": math.nan,
    "events_match": False,
    "event_angle": math.nan,
    "separation_angle": math.nan,
    "separation": math.nan,
    "seating_velocity": math.nan,
    "impact_velocity": math.nan,
}


@dataclass
class Bench:
    """Everything a bench run measured (SI inside; the report converts)."""

    quick: bool  # --quick
    meta: dict  # machine, versions, settings of the references and ladders
    rows: list[dict] = field(default_factory=list)  # one per scene × method × setting
    checks: list[dict] = field(default_factory=list)  # reference cross-checks per scene
    ratios: list[dict] = field(default_factory=list)  # per scene × peer
    goals: dict = field(default_factory=dict)  # the speed goals, reached or not
    accuracy_for_cost: dict = field(default_factory=dict)  # the error target on 11000 rpm
    throughput: list[dict] = field(default_factory=list)  # newmark-linear's throughput, 256 cases
    scaling: list[dict] = field(default_factory=list)  # the engine's time against cases, workers
    #: a study with --parts on 1, 2, … worker processes: cases/s, the client's CPU
    cluster: list[dict] = field(default_factory=list)
    #: a study's peak memory against the bound campipe validate states (campipe.bench.memory)
    memory: dict = field(default_factory=dict)
    steady: list[dict] = field(default_factory=list)  # the steady-state path per scene
    onset: dict = field(default_factory=dict)  # the onset map against the time-domain grid
    settling: dict = field(default_factory=dict)  # automatic run length against 4 turns
    sweep: dict = field(default_factory=dict)  # the speed sweep: ratios, overhead (issue 34)
    seconds: float = 0.0  # wall time of the whole bench [s]
    # The previous run's timed figures and how they compare (campipe.bench.gate.compare):
    # empty until the report is written; then the figures more than 10 % slower.
    previous: dict = field(default_factory=dict)
    regressions: list[dict] = field(default_factory=list)


def processor() -> str:
    """The CPU's model name (Linux's /proc/cpuinfo; else what ``platform`` knows): two machines
    of one architecture and core count can differ by half in speed."""
    from campipe.disk_cache import cpu_info

    return cpu_info().get("model name") or platform.processor() or "unknown"


def machine() -> dict:
    """The machine, versions, date and load a run measures on (every bench records them)."""
    import numba
    import scipy

    return {
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.system()}",
        "processor": processor(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
        "date": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
        "load_average_at_start": os.getloadavg()[0],
        "campipe": campipe_revision(),
    }


def campipe_revision() -> str:
    """campipe's version, and the commit of the tree it runs from where that is a git work
    tree with git at hand ("+changes" where it differs from the commit): which code the
    figures measure."""
    import subprocess

    import campipe

    root = Path(campipe.__file__).resolve().parents[1]
    try:
        commit = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
            capture_output=True, text=True, timeout=10, check=True,
        ).stdout.strip()  # fmt: skip
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True, text=True, timeout=10, check=True,
        ).stdout.strip()  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return campipe.__version__
    return f"{campipe.__version__}, commit {commit}{' +changes' if dirty else ''}"


def _meta(quick: bool, ladder: Ladder, scenes: Sequence[Scene]) -> dict:
    return {
        **machine(),
        "scenes": {
            s.name: {"description": s.description, "revolutions": s.revolutions} for s in scenes
        },
        "output_every_deg": math.degrees(measure.OUTPUT_EVERY),
        "reference": (
            f"modal-exact, tolerance {measure.REFERENCE.tolerance:g} s, step cap "
            f"{measure.REFERENCE_STEP_CAP * 1e6:g} µs"
        ),
        "reference_check": (
            f"solve_ivp {measure.CHECK_METHOD}, rtol = atol = "
            f"{measure.CHECK_RTOL:g} (campipe.bench.ivp)"
        ),
        "agreement": {k: v for k, v in measure.AGREEMENT.items()},
        "default": "modal-exact, tolerance 1e-12 s, steps chosen by the integrator, full",
        "ladder": asdict(ladder),
        "timing": (
            f"engine: per-case time of a batch of up to {ladder.copies} copies "
            f"(about {measure.BATCH_SECONDS:g} s), best of {ladder.repeats} or more runs "
            f"(up to {measure.MAX_REPEATS} while they take less than "
            f"{measure.BATCH_SECONDS:g} s), kernels "
            f"loaded first; solve_ivp: one run, best of {ladder.ivp_repeats}"
        ),
    }


def throughput_repeats(quick: bool) -> int:
    """Runs a throughput batch is the least of (the run's and the gate's second look)."""
    return 2 if quick else 5


def settings_rows(ladder: Ladder) -> list[tuple[str, str, RunSettings, bool]]:
    """(family, label, settings, full_state) of every engine run of a scene."""
    rows = [
        ("modal-exact", f"tol {t:g} s", RunSettings(tolerance=t), True)
        for t in ladder.modal_tolerances
    ]
    rows += [
        ("modal-exact capped", f"cap {c * 1e6:g} µs", RunSettings(dt=c), True)
        for c in ladder.modal_caps
    ]
    if ladder.contacts_only:
        rows.append(("contacts only", "full", RunSettings(), False))
    rows += [
        (
            "newmark-linear",
            f"dt {dt * 1e6:g} µs",
            RunSettings(integrator="newmark-linear", dt=dt),
            True,
        )
        for dt in ladder.newmark_steps
    ]
    return rows


def _row(
    scene: Scene, family: str, label: str, seconds: float, cost: int, err: measure.Errors,
    check: measure.Errors, **extra,
) -> dict:  # fmt: skip
    """A ladder's row, its errors at least the reference's resolution (``check``, its
    difference from the second reference: ``measure.resolved``; ``at_resolution`` names the
    errors raised to it, shown as bounds, ≤)."""
    row = {
        "scene": scene.name,
        "family": family,
        "setting": label,
        "seconds": seconds,
        "cost": cost,
    }
    row.update(extra)
    err, raised = measure.resolved(err, check)
    row.update(err.as_dict())
    row["at_resolution"] = raised
    return row


def _is_default(s: RunSettings) -> bool:
    return (
        s.method == DEFAULT.method
        and s.tolerance == DEFAULT.tolerance
        and s.dt is None
        and s.fidelity == "full"
    )


def _ratios(scene: str, rows: list[dict]) -> list[dict]:
    """Each peer's time to the default's valve-lift error, and campipe's time to the peer's
    own error at its operating point."""
    mine = [r for r in rows if r["scene"] == scene]
    default = next(r for r in mine if r.get("default"))
    # campipe's side: the default integrator at full fidelity, any tolerance or step cap.
    modal = [r for r in mine if r["family"] in ("modal-exact", "modal-exact capped")]
    out = []
    for peer in ("newmark-linear", "solve_ivp"):
        pts = [r for r in mine if r["family"] == peer]
        if not pts:
            continue
        t = [r["seconds"] for r in pts]
        e = [r["valve_lift"] for r in pts]
        t_peer, how = measure.time_to_error(t, e, default["valve_lift"])
        t_bound, reached = measure.measured_time_to_error(t, e, default["valve_lift"])
        if peer == "newmark-linear":
            point = next((r for r in pts if r.get("thesis")), pts[0])
        else:
            point = min(pts, key=lambda r: r["valve_lift"])
        t_mine, how_mine = measure.time_to_error(
            [r["seconds"] for r in modal], [r["valve_lift"] for r in modal], point["valve_lift"]
        )
        # The same at every point of the peer's ladder: where the ratio stands at each error.
        ladder = []
        for r in sorted(pts, key=lambda r: -r["valve_lift"]):
            t_at, how_at = measure.time_to_error(
                [m["seconds"] for m in modal], [m["valve_lift"] for m in modal], r["valve_lift"]
            )
            ladder.append(
                {
                    "setting": r["setting"],
                    "seconds": r["seconds"],
                    "error": r["valve_lift"],
                    "campipe_seconds": t_at,
                    "how_campipe": how_at,
                    "ratio": r["seconds"] / t_at,
                }
            )
        out.append(
            {
                "scene": scene,
                "peer": peer,
                "default_seconds": default["seconds"],
                "default_error": default["valve_lift"],
                "peer_seconds_at_default_error": t_peer,
                "how": how,
                "ratio_at_default_error": t_peer / default["seconds"],
                # Measured only: the estimate where the ladder reaches the default's error, else
                # the lower bound its most accurate point gives.
                "peer_seconds_at_default_error_measured": t_bound,
                "peer_reaches_default_error": reached,
                "measured_ratio_at_default_error": t_bound / default["seconds"],
                "peer_point": point["setting"],
                "peer_point_seconds": point["seconds"],
                "peer_point_error": point["valve_lift"],
                "campipe_seconds_at_peer_error": t_mine,
                "how_campipe": how_mine,
                "ratio_at_peer_error": point["seconds"] / t_mine,
                "ladder": ladder,
            }
        )
    return out


def _accuracy_for_cost(rows: list[dict]) -> dict:
    mine = [r for r in rows if r["scene"] == ACCURACY_SCENE]
    if not mine:
        return {}
    default = next(r for r in mine if r.get("default"))
    lean = next(
        (r for r in mine if r["family"] == "contacts only" and r["setting"] == "full"), None
    )
    nm = [r for r in mine if r["family"] == "newmark-linear"]
    t_nm, how = measure.time_to_error(
        [r["seconds"] for r in nm], [r["valve_lift"] for r in nm], ACCURACY_NEWMARK_ERROR
    )
    meeting = [r for r in nm if r["valve_lift"] <= ACCURACY_NEWMARK_ERROR]
    cheapest = min(meeting, key=lambda r: r["seconds"]) if meeting else None
    return {
        "scene": ACCURACY_SCENE,
        "default_error": default["valve_lift"],
        "default_seconds": default["seconds"],
        "default_steps": default["cost"],
        "default_below_target": default["valve_lift"] < ACCURACY_DEFAULT_ERROR,
        "newmark_target": ACCURACY_NEWMARK_ERROR,
        "newmark_seconds_at_target": t_nm,
        "how": how,
        "newmark_cheapest_meeting": cheapest
        and {
            "setting": cheapest["setting"],
            "seconds": cheapest["seconds"],
            "error": cheapest["valve_lift"],
            "steps": cheapest["cost"],
        },
        "ratio": t_nm / default["seconds"],
        "contacts_only_seconds": lean and lean["seconds"],
        "contacts_only_error": lean and lean["valve_lift"],
        "ratio_contacts_only": lean and t_nm / lean["seconds"],
    }


def _goals(ratios: list[dict]) -> dict:
    out = {}
    for peer, goal in (("solve_ivp", GOAL_IVP), ("newmark-linear", GOAL_NEWMARK)):
        mine = [r for r in ratios if r["peer"] == peer]
        if not mine:
            continue
        # A ratio of 0 means campipe's ladder did not reach the peer's error: not comparable
        # there, and named rather than averaged in.
        at_peer = min(
            (r["ratio_at_peer_error"] for r in mine if r["ratio_at_peer_error"] > 0),
            default=math.nan,
        )
        # The goals' ratio: the peer's time to reach the default's error. Judged on what the
        # ladders measured (a lower bound where the peer's ladder does not reach it); the
        # extrapolated estimate is reported beside it.
        least = min(mine, key=lambda r: r["measured_ratio_at_default_error"])
        at_default = least["measured_ratio_at_default_error"]
        # Below the goal on a lower bound: the ladder is too short to tell.
        verdict = (
            "reached"
            if at_default >= goal
            else "not shown (a lower bound)"
            if not least["peer_reaches_default_error"]
            else "not reached"
        )
        at_default_extrapolated = min(r["ratio_at_default_error"] for r in mine)
        # Per scene, the largest error from which on (to the most accurate point) every
        # point of the peer's ladder is at least ``goal`` times slower than campipe.
        below = {}
        for r in mine:
            bound = math.nan
            for point in sorted(r["ladder"], key=lambda p: p["error"]):
                if not point["ratio"] >= goal:
                    break
                bound = point["error"]
            below[r["scene"]] = bound
        out[peer] = {
            "goal": goal,
            "min_ratio_at_peer_error": at_peer,
            "goal_reached_below_error": below,
            "min_ratio_at_default_error": at_default,
            "min_ratio_at_default_error_extrapolated": at_default_extrapolated,
            "peer_not_reaching_default_error": [
                r["scene"] for r in mine if not r["peer_reaches_default_error"]
            ],
            "reached_at_peer_error": at_peer >= goal,
            "reached_at_default_error": at_default >= goal,
            "verdict_at_default_error": verdict,
            "campipe_not_reaching": [r["scene"] for r in mine if not r["ratio_at_peer_error"] > 0],
        }
    return out


def run_bench(
    quick: bool = False,
    scenes: Sequence[str] | None = None,
    *,
    with_scaling: bool = True,
    with_suite: bool = True,
    progress: Callable[[str], None] | None = None,
    with_cluster: bool | None = None,
) -> Bench:
    """Run the bench.

    Parameters
    ----------
    quick : bool
        Small ladders, 1.5 cam turns per scene, scaling up to 256 cases (under a minute).
    scenes : sequence of str, optional
        Scene names to run (default: the whole suite).
    with_scaling : bool
        Run the speed sweep, the throughput and the engine's scaling measurements.
    with_suite : bool
        Run the scenes: references, ladders, peers and fidelity.
    progress : callable, optional
        Called with a line of text as each stage starts.
    with_cluster : bool, optional
        Run a study with ``--parts`` on a local dask cluster of 1, 2 and 4 worker processes
        (:mod:`campipe.bench.cluster`; default: with the scaling measurements).
    """
    started = time.perf_counter()
    say = progress or (lambda text: log.info("%s", text))
    ladder = QUICK if quick else FULL
    chosen = suite()
    if scenes:
        unknown = set(scenes) - {s.name for s in chosen}
        if unknown:
            raise ValueError(
                f"unknown scenes {sorted(unknown)}; known: " + ", ".join(s.name for s in chosen)
            )
        chosen = tuple(s for s in chosen if s.name in scenes)
    if quick:
        chosen = tuple(Scene(s.name, s.description, s.case, QUICK_REVOLUTIONS) for s in chosen)
    bench = Bench(quick, _meta(quick, ladder, chosen))
    if with_suite:
        say("loading the compiled kernels")
        measure.warm_up()
    for scene in chosen if with_suite else ():
        say(f"{scene.name}: reference and its check")
        ref = measure.reference(scene)
        check = measure.check_reference(scene, ref)
        bench.checks.append(
            {
                "scene": scene.name,
                "agrees": check.agrees,
                "seconds": check.seconds,
                # What the check's events are compared with, for the verdict's reason.
                "reference_events": {
                    name: int(np.sum(ref.events[:, EV_KIND] == kind))
                    for kind, name in EVENT_KINDS.items()
                },
                **check.errors.as_dict(),
            }
        )
        say(f"{scene.name}: campipe and newmark-linear ladders")
        for family, label, settings, full_state in settings_rows(ladder):
            seconds, out, steps = measure.time_engine(
                scene, settings, ladder.copies, ladder.repeats, full_state=full_state
            )
            bench.rows.append(
                _row(
                    scene,
                    family,
                    label,
                    seconds,
                    steps,
                    measure.errors(out, ref),
                    check.errors,
                    integrator=settings.method,
                    fidelity=settings.fidelity,
                    full_state=full_state,
                    default=_is_default(settings) and full_state,
                    thesis=settings.method == "newmark-linear" and settings.dt == THESIS_STEP,
                )
            )
        say(f"{scene.name}: solve_ivp {ladder.ivp_method}")
        for rtol in ladder.ivp_rtols:
            label = f"{ladder.ivp_method} rtol {rtol:g}"
            try:
                seconds, out, nfev = measure.time_ivp(
                    scene, rtol, ladder.ivp_method, ladder.ivp_repeats
                )
            except (ChatterError, RuntimeError) as exc:
                log.warning("%s: solve_ivp %s failed: %s", scene.name, label, exc)
                bench.rows.append(
                    {
                        "scene": scene.name,
                        "family": "solve_ivp",
                        "setting": label,
                        "seconds": math.nan,
                        "cost": 0,
                        "failed": str(exc),
                        **FAILED,
                    }
                )
                continue
            bench.rows.append(
                _row(
                    scene,
                    "solve_ivp",
                    label,
                    seconds,
                    nfev,
                    measure.errors(out, ref),
                    check.errors,
                    integrator=f"solve_ivp {ladder.ivp_method}",
                    fidelity="full",
                    default=False,
                    thesis=False,
                )
            )
        bench.ratios += _ratios(scene.name, bench.rows)
    say("the steady-state path on the scenes that follow the cam")
    bench.steady = onset.steady_scenes(chosen, ladder.copies, ladder.repeats)
    say("onset map: designs × speed range against the time-domain grid")
    bench.onset = onset.onset_map(quick, repeats=ladder.repeats)
    if with_suite and not scenes:
        say("automatic run length: a sweep through the onset against a fixed 4 turns")
        bench.settling = settling.settling_cost(quick, repeats=1 if quick else 2)
    bench.goals = _goals(bench.ratios)
    bench.accuracy_for_cost = _accuracy_for_cost(bench.rows)
    if with_scaling:
        say("speed sweep: 32 speeds, the default against the thesis's loop and newmark-linear")
        bench.sweep = sweep.speed_sweep(quick)
        say("throughput: 256 cases, newmark-linear and modal-exact")
        for integrator, workers in (
            ("newmark-linear", 1),
            ("newmark-linear", 2),
            ("modal-exact", 2),
        ):
            tp = scaling.throughput(256, workers, integrator, repeats=throughput_repeats(quick))
            bench.throughput.append({**asdict(tp), "rate": tp.rate})
        counts = QUICK_SCALING_COUNTS if quick else SCALING_COUNTS
        say(f"scaling: engine on dask threads, {counts[0]}–{counts[-1]} cases")
        points = scaling.engine_scaling(counts)
        bench.scaling = [{**asdict(p), "per_case": p.per_case} for p in points]
    if with_scaling if with_cluster is None else with_cluster:
        sizes, processes = (
            (cluster.QUICK_CLUSTER_COUNTS, cluster.QUICK_CLUSTER_WORKERS)
            if quick
            else (cluster.CLUSTER_COUNTS, cluster.CLUSTER_WORKERS)
        )
        say(f"cluster: a study with --parts on {', '.join(map(str, processes))} worker processes")
        with tempfile.TemporaryDirectory(prefix="campipe-cluster-") as folder:
            bench.cluster = cluster.as_dicts(cluster.cluster_scaling(folder, sizes, processes))
    if with_scaling:
        # After the cluster: the memory study writes an archive of 10000 cases, whose
        # write-back slowed the cluster's client (its CPU per case 44-50 µs after it, 22 µs
        # alone).
        n = memory.QUICK_MEMORY_CASES if quick else memory.MEMORY_CASES
        say(f"memory: a study of {n} cases, its peak against the bound validate states")
        with tempfile.TemporaryDirectory(prefix="campipe-memory-") as folder:
            bench.memory = memory.as_dict(memory.study_memory(n, folder))
    bench.seconds = time.perf_counter() - started
    bench.meta["load_average_at_end"] = os.getloadavg()[0]
    return bench
