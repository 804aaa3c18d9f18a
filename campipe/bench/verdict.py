"""The bench's verdict: every goal with its measured figure and whether the run reached it, and
every reference cross-check with whether it agrees and why.

Pure functions of a :class:`~campipe.bench.run.Bench`, a live run or one read back from its
``bench.json`` (where a missing figure is None). :func:`text` names the figures that got slower
than the previous run's too (``campipe.bench.gate``). ``campipe bench`` prints it last and
exits with status 1 unless :func:`all_agree`; ``campipe.bench.pages`` writes
:func:`markdown` into the documentation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from campipe.bench import gate, sweep
from campipe.bench.figures import finite, format_short
from campipe.bench.onset import GOAL_MAP_SECONDS, GOAL_MAP_WORKERS
from campipe.bench.run import (
    ACCURACY_DEFAULT_ERROR,
    ACCURACY_NEWMARK_ERROR,
    ACCURACY_SCENE,
    GOAL_IVP,
    GOAL_NEWMARK,
    GOAL_THROUGHPUT,
    GOAL_THROUGHPUT_WORKERS,
    THESIS_STEP,
    Bench,
)
from campipe.constants import INCH

#: A goal's status.
REACHED, NOT_REACHED, NOT_SHOWN = "reached", "not reached", "not shown"
#: The differences a cross-check compares: (key, words, factor from SI, unit).
CHECKED = (
    ("valve_lift", "valve lift", 1 / INCH, "in"),
    ("event_angle", "event angles", math.degrees(1.0), "deg"),
    ("separation", "separation per turn", math.degrees(1.0), "deg"),
    ("seating_velocity", "seating velocity", 1 / INCH, "in/s"),
    ("impact_velocity", "cam-impact velocity", 1 / INCH, "in/s"),
)


@dataclass(frozen=True)
class Goal:
    """One goal as a run shows it."""

    area: str  # which goal: "speed", "accuracy", "throughput" or "onset" (the developer's
    # benchmark, ``benchmarks/`` in the repository, adds "study")
    what: str  # the goal, in words
    figure: str  # what the run measured, with its unit ("–": nothing measured)
    status: str  # REACHED, NOT_REACHED or NOT_SHOWN
    note: str  # where the figure comes from, or why it cannot show the goal


@dataclass(frozen=True)
class Check:
    """One scene's reference cross-check."""

    scene: str  # scene name
    agrees: bool  # every difference within the stated agreement, and the same events
    reason: str  # the differences against their limits; what differs first


def _or_inf(x) -> float:
    return x if finite(x) else math.inf


def _speed_goals(bench: Bench, peer: str, goal: float) -> list[Goal]:
    """The goal at the default's error (the issue's ratio) and at the peer's own point."""
    if peer == "newmark-linear":
        point = f"the thesis's {THESIS_STEP * 1e6:g} µs step, for that step's"
    else:
        point = "its most accurate setting, for that setting's"
    at_default = f"default ≥ {goal:g}× faster than {peer} at the default's valve-lift error"
    at_point = f"default ≥ {goal:g}× faster than {peer} at {point} valve-lift error"
    g = bench.goals.get(peer)
    mine = [r for r in bench.ratios if r["peer"] == peer]
    if not g or not mine:
        why = f"no scene ran {peer}"
        return [
            Goal("speed", at_default, "–", NOT_SHOWN, why),
            Goal("speed", at_point, "–", NOT_SHOWN, why),
        ]
    over = f"smallest over {len(mine)} scene{'s' if len(mine) > 1 else ''}"

    least = min(mine, key=lambda r: _or_inf(r["measured_ratio_at_default_error"]))
    bound = not least["peer_reaches_default_error"]
    short = g["peer_not_reaching_default_error"]
    note = f"{over}, on {least['scene']}"
    if short:
        note += (
            f"; {peer}'s most accurate setting falls short of the default's error on "
            f"{', '.join(short)}, where its time is a lower bound"
        )
    verdict = g["verdict_at_default_error"]
    if verdict == "reached":
        status = REACHED
    else:
        status = NOT_SHOWN if verdict.startswith("not shown") else NOT_REACHED
    goals = [
        Goal(
            "speed",
            at_default,
            f"{'≥ ' if bound else ''}{format_short(g['min_ratio_at_default_error'])}×",
            status,
            note,
        )
    ]

    # A ratio of 0: campipe's ladder does not reach the peer's error there (run._goals).
    compared = [r for r in mine if finite(r["ratio_at_peer_error"]) and r["ratio_at_peer_error"]]
    if not compared:
        goals.append(
            Goal(
                "speed",
                at_point,
                "–",
                NOT_SHOWN,
                f"campipe's ladder reaches {peer}'s error on no scene",
            )
        )
        return goals
    least = min(compared, key=lambda r: r["ratio_at_peer_error"])
    note = f"{over}, on {least['scene']} at {least['peer_point']}"
    if least["how_campipe"] == "cheapest":
        note += ": campipe's cheapest setting is already more accurate there"
    if g["campipe_not_reaching"]:
        note += f"; campipe's ladder does not reach it on {', '.join(g['campipe_not_reaching'])}"
    goals.append(
        Goal(
            "speed",
            at_point,
            f"{format_short(least['ratio_at_peer_error'])}×",
            REACHED if g["reached_at_peer_error"] else NOT_REACHED,
            note,
        )
    )
    return goals


def _accuracy_goals(bench: Bench) -> list[Goal]:
    """On the separation scene: the default's error below its target, at less cost than
    newmark-linear needs for its (looser) target."""
    error = (
        f"the default's valve-lift error below "
        f"{format_short(ACCURACY_DEFAULT_ERROR / INCH)} in on {ACCURACY_SCENE}"
    )
    cost = (
        f"the default at less cost than newmark-linear needs for "
        f"{format_short(ACCURACY_NEWMARK_ERROR / INCH)} in on {ACCURACY_SCENE}"
    )
    a = bench.accuracy_for_cost
    if not a:
        why = f"{ACCURACY_SCENE} was not run"
        return [
            Goal("accuracy", error, "–", NOT_SHOWN, why),
            Goal("accuracy", cost, "–", NOT_SHOWN, why),
        ]
    goals = [
        Goal(
            "accuracy",
            error,
            f"{format_short(a['default_error'] / INCH, 2)} in",
            REACHED if a["default_below_target"] else NOT_REACHED,
            f"{format_short(a['default_seconds'] * 1e3)} ms per case",
        )
    ]
    ratio = a["ratio"]
    if a["how"] not in ("cheapest", "interpolated") or not finite(ratio):
        goals.append(
            Goal(
                "accuracy",
                cost,
                "–",
                NOT_SHOWN,
                f"newmark-linear's ladder does not reach it ({a['how']})",
            )
        )
        return goals
    cheapest = a["newmark_cheapest_meeting"]
    note = "newmark-linear's time, interpolated on its ladder, over the default's"
    if a["how"] == "cheapest":
        note = (
            f"newmark-linear's time over the default's; its cheapest ladder point "
            f"({cheapest['setting']}) already reaches the target"
        )
    if finite(a.get("ratio_contacts_only")):
        note += f"; {format_short(a['ratio_contacts_only'])}× sampling only the contact coordinates"
    goals.append(
        Goal(
            "accuracy", cost, f"{format_short(ratio)}×", REACHED if ratio > 1 else NOT_REACHED, note
        )
    )
    return goals


def _throughput(bench: Bench) -> Goal:
    what = (
        f"newmark-linear above {format_short(GOAL_THROUGHPUT)} case-steps/s on "
        f"{GOAL_THROUGHPUT_WORKERS} workers"
    )
    row = next(
        (
            t
            for t in bench.throughput
            if t["integrator"] == "newmark-linear" and t["workers"] == GOAL_THROUGHPUT_WORKERS
        ),
        None,
    )
    if row is None:
        return Goal("throughput", what, "–", NOT_SHOWN, "not measured: --no-scaling")
    return Goal(
        "throughput",
        what,
        f"{format_short(row['rate'])} case-steps/s",
        REACHED if row["rate"] > GOAL_THROUGHPUT else NOT_REACHED,
        f"a {row['n_cases']}-case batch, {format_short(row['revolutions'])} turns per case",
    )


def _sweep_goals(bench: Bench) -> list[Goal]:
    """Issue 34's goals on the speed sweep (``campipe.bench.sweep``)."""
    s = bench.sweep
    whats = (
        ("thesis_ratio", f"the default at least ×{format_short(sweep.GOAL_THESIS)} faster than "
         "the thesis's algorithm (a compiled scalar loop at 1 µs)"),
        ("newmark_ratio", f"the default at least ×{format_short(sweep.GOAL_NEWMARK)} faster than "
         "newmark-linear at 1 µs"),
        ("overhead", f"at most {format_short(sweep.GOAL_OVERHEAD * 1e3)} ms overhead a call, 32 "
         f"one-case calls within {format_short(sweep.GOAL_CALLS)}× one 32-case call"),
    )  # fmt: skip
    if not s:
        return [Goal("sweep", w, "–", NOT_SHOWN, "not measured: --no-scaling") for _, w in whats]
    note = f"{s['cases']} speeds, {format_short(s['revolutions'])} turns, least of several runs"
    out = []
    for key, what in whats:
        if key == "overhead":
            figure = (
                f"{format_short(s['overhead'] * 1e3, 3)} ms, {format_short(s['calls_ratio'], 3)}×"
            )
            reached = s["reached"]["overhead"] and s["reached"]["calls_ratio"]
        else:
            figure = f"×{format_short(s[key], 3)}"
            reached = s["reached"][key]
        out.append(Goal("sweep", what, figure, REACHED if reached else NOT_REACHED, note))
    return out


def _onset_map(bench: Bench) -> Goal:
    what = (
        f"an onset map of 1000 designs in under {format_short(GOAL_MAP_SECONDS)} s on "
        f"{GOAL_MAP_WORKERS} workers"
    )
    o = bench.onset
    if not o:
        return Goal("onset", what, "–", NOT_SHOWN, "not measured")
    if o["designs"] < 1000:
        return Goal("onset", what, "–", NOT_SHOWN, f"--quick maps {o['designs']} designs")
    return Goal(
        "onset",
        what,
        f"{format_short(o['seconds'], 2)} s",
        REACHED if o["seconds"] < GOAL_MAP_SECONDS else NOT_REACHED,
        f"{o['designs']} designs to {format_short(o['tolerance_rpm'])} rpm; the "
        f"{o['grid_speeds']}-speed time-domain grid would take "
        f"{format_short(o['grid_seconds'], 2)} s (estimated from 64 of its runs)",
    )


def goals(bench: Bench) -> list[Goal]:
    """Every goal the bench judges, in a fixed order, each shown or not by this run."""
    return [
        *_speed_goals(bench, "solve_ivp", GOAL_IVP),
        *_speed_goals(bench, "newmark-linear", GOAL_NEWMARK),
        *_accuracy_goals(bench),
        _throughput(bench),
        _onset_map(bench),
        *_sweep_goals(bench),
    ]


def _events_text(counts: dict | None) -> str:
    if counts is None:
        return ""
    present = {k: n for k, n in counts.items() if n}
    if not present:
        return " (the reference has none)"
    listed = ", ".join(f"{n} × {k.replace('_', ' ')}" for k, n in present.items())
    return f" (the reference's: {listed})"


def checks(bench: Bench) -> list[Check]:
    """Each scene's reference cross-check against the run's stated agreement."""
    limits = bench.meta["agreement"]
    out = []
    for c in bench.checks:
        within, beyond = [], []
        for key, words, scale, unit in CHECKED:
            value = c.get(key)
            if not finite(value):
                continue
            text = f"{words} {format_short(value * scale, 2)} {unit}"
            if value > limits[key]:
                beyond.append(f"{text} above its limit {format_short(limits[key] * scale)}")
            else:
                within.append(f"{text} (limit {format_short(limits[key] * scale)})")
        if c["agrees"]:
            out.append(Check(c["scene"], True, "within the stated agreement: " + ", ".join(within)))
            continue
        why = []
        if not c["events_match"]:
            why.append(
                "the events differ from the reference's in kind or number"
                + _events_text(c.get("reference_events"))
                + ", so no event angle can be paired"
            )
        why += beyond
        if not why:
            why.append("a difference could not be computed")
        if within:
            why.append("within the agreement: " + ", ".join(within))
        out.append(Check(c["scene"], False, "; ".join(why)))
    return out


def all_agree(bench: Bench) -> bool:
    """Every reference cross-check of the run agreed (``campipe bench``'s exit status 0)."""
    return all(c["agrees"] for c in bench.checks)


def text(bench: Bench) -> str:
    """The verdict block ``campipe bench`` ends with."""
    n = len(bench.checks)
    lines = [
        f"verdict ({'--quick, ' if bench.quick else ''}{n} scene{'s' if n != 1 else ''}):",
        "goals:",
    ]
    width = max(len(s) for s in (REACHED, NOT_REACHED, NOT_SHOWN))
    for g in goals(bench):
        lines.append(f"  {g.status:<{width}}  {g.area}: {g.what}: {g.figure} ({g.note})")
    lines += gate.text(bench)
    lines.append(
        f"reference cross-checks ({bench.meta['reference']}, against "
        f"{bench.meta['reference_check']}):"
    )
    for c in checks(bench):
        lines.append(f"  {'agree' if c.agrees else 'disagree':<8}  {c.scene}: {c.reason}")
    agreed = sum(c["agrees"] for c in bench.checks)
    lines.append(
        f"{agreed} of {n} cross-checks agree"
        + ("" if all_agree(bench) else "; exit status 1 (a cross-check disagrees)")
    )
    return "\n".join(lines)


def markdown(bench: Bench) -> str:
    """The verdict as markdown bullets: the goals, then the cross-checks."""
    lines = [
        f"- **{g.status}** ({g.area}): {g.what}: **{g.figure}** ({g.note})." for g in goals(bench)
    ]
    lines += [
        f"- cross-check on {c.scene}: **{'agrees' if c.agrees else 'disagrees'}**, {c.reason}."
        for c in checks(bench)
    ]
    return "\n".join(lines)
