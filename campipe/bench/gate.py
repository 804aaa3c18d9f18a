"""The regression gate: a run's timed figures against the previous run's on the same machine.

Every figure of a run that is a cost, a time (issue 34: "the bench keeps the last figures and
names what got slower"):

- each engine run of a scene's ladders, per case (modal-exact at each tolerance and step cap,
  contacts only, newmark-linear at each step); not solve_ivp's, the peer's time is SciPy's;
- the steady-state path on each scene that follows the cam, its margin and one turn of it;
- the throughput batches (the batch's time), the engine's scaling points, the onset map and
  the time-domain grid it replaces;
- the speed sweep's default, quasi-static start, one-case calls and newmark-linear, and
  the quickstart's first run from an empty kernel cache (its kernels compiled).

:func:`compare` matches the new figures with the previous run's by scene, figure and cam
turns, and names every one more than :data:`SLOWER` slower; :func:`confirm` times each named
figure once more (``campipe.bench.retime``) and keeps named only those slower again. Two
runs are compared only when their machine and the versions of :data:`SAME_MACHINE` are the
same, and both are full runs or both ``--quick``; otherwise nothing is named and the reason
says why. Pure functions of plain dicts and a :class:`~campipe.bench.run.Bench` (the timing
again handed in); ``campipe.bench.report`` reads the previous ``bench.json`` and keeps the
result in the new one (``Bench.previous``, ``Bench.regressions``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any

from campipe.bench.figures import finite, format_short
from campipe.bench.run import Bench

#: A figure more than this fraction slower than the previous run's is named (0.1: 10 %).
SLOWER = 0.10
#: The fields of ``meta`` two runs must share to be compared: the machine (architecture,
#: cores, system), its processor's model and the versions of the two libraries the timed
#: code runs on. A run recorded before the processor was (None) is compared with no other.
SAME_MACHINE = ("machine", "processor", "numpy", "numba")
#: How a comparison ended (``Bench.previous["status"]``).
COMPARED = "compared"
NO_PREVIOUS = "no previous run"
UNREADABLE = "unreadable"
OTHER_MACHINE = "another machine"
OTHER_KIND = "another kind of run"
NOTHING_IN_COMMON = "no figure in common"
#: The speed sweep's timed figures (``campipe.bench.sweep``), by key and name; not the thesis's
#: loop, the reference the others are measured against.
SWEEP_FIGURES = (
    ("default", "default, 32 cases"),
    ("default_quasi_static", "default with the quasi-static start, 32 cases"),
    ("one_case_calls", "32 one-case calls"),
    ("newmark", "newmark-linear at 1 µs, 32 cases"),
    ("first_run", "the quickstart's first run from an empty kernel cache"),
)
#: The steady-state path's two timed figures on a scene.
STEADY_MARGIN, STEADY_TURN = "steady state, its margin", "steady state, one turn"
#: The families of rows whose time is campipe's own (solve_ivp's is the peer's).
TIMED_FAMILIES = ("modal-exact", "modal-exact capped", "contacts only", "newmark-linear")


def _figure(scene: str, figure: str, seconds: Any, turns: Any = None) -> list[dict]:
    if not finite(seconds):
        return []
    return [{"scene": scene, "figure": figure, "turns": turns, "seconds": float(seconds)}]


def _workers(n: int) -> str:
    return f"{n} worker{'s' if n != 1 else ''}"


def row_name(r: Mapping[str, Any]) -> str:
    """A ladder row's figure: its family and setting."""
    return f"{r['family']}, {r['setting']}"


def throughput_name(t: Mapping[str, Any]) -> str:
    """A throughput batch's figure."""
    return (
        f"{t['integrator']}, {t['n_cases']} cases × {format_short(t['revolutions'])} turns, "
        f"{_workers(t['workers'])}"
    )


def scaling_name(p: Mapping[str, Any]) -> str:
    """A scaling point's figure."""
    return f"{p['layer']}, {p['n_cases']} cases, {_workers(p['workers'])}"


def figures(run: Mapping[str, Any]) -> list[dict]:
    """Every timed figure of a run (a ``bench.json`` as a dict, or ``vars(bench)``): scene,
    figure, the scene's cam turns (None for the figures of no scene) and seconds."""
    meta = run.get("meta") or {}
    turns = {name: s.get("revolutions") for name, s in (meta.get("scenes") or {}).items()}
    out: list[dict] = []
    for r in run.get("rows") or ():
        if r.get("family") in TIMED_FAMILIES:
            out += _figure(r["scene"], row_name(r), r.get("seconds"), turns.get(r["scene"]))
    for s in run.get("steady") or ():
        if s.get("applies"):
            at = turns.get(s["scene"])
            out += _figure(s["scene"], STEADY_MARGIN, s.get("margin_seconds"), at)
            out += _figure(s["scene"], STEADY_TURN, s.get("seconds"), at)
    for t in run.get("throughput") or ():
        out += _figure("throughput", throughput_name(t), t.get("seconds"))
    for p in run.get("scaling") or ():
        out += _figure("scaling", scaling_name(p), p.get("seconds"))
    sweep = run.get("sweep") or {}
    for key, name in SWEEP_FIGURES:
        out += _figure("speed sweep", name, (sweep.get("seconds") or {}).get(key))
    o = run.get("onset") or {}
    if o:
        out += _figure("onset map", map_name(o), o.get("seconds"))
        out += _figure("onset map", grid_name(o), o.get("grid_seconds"))
    return out


def map_name(o: Mapping[str, Any]) -> str:
    """The figure name of a run's onset map (its ``onset``)."""
    return f"{o['designs']} designs, {_workers(o['workers'])}"


def grid_name(o: Mapping[str, Any]) -> str:
    """The figure name of the time-domain grid an onset map replaces."""
    return f"its time-domain grid, {o['grid_speeds']} speeds a design"


def _key(f: Mapping[str, Any]) -> tuple:
    return (f["scene"], f["figure"], f.get("turns"))


def _meta_of(previous: Mapping[str, Any]) -> dict:
    """The previous run's identity, as its block keeps it."""
    meta = previous.get("meta") or {}
    return {
        "date": meta.get("date"),
        "quick": bool(previous.get("quick")),
        **{k: meta.get(k) for k in SAME_MACHINE},
        "load_average_at_start": meta.get("load_average_at_start"),
    }


def _not_comparable(new: Bench, previous: Mapping[str, Any]) -> tuple[str, str] | None:
    """(status, reason) when the two runs cannot be compared, else None."""
    if bool(previous.get("quick")) != new.quick:
        kinds = ("a --quick run", "a full run")
        was, now = kinds[not previous.get("quick")], kinds[not new.quick]
        return OTHER_KIND, (
            f"the previous run was {was}, this one {now}: only runs of the same kind are compared"
        )
    meta = previous.get("meta") or {}
    differ = [k for k in SAME_MACHINE if meta.get(k) != new.meta.get(k)]
    if differ:
        what = "; ".join(f"{k} {meta.get(k)} then, {new.meta.get(k)} now" for k in differ)
        return OTHER_MACHINE, f"the previous run was on another machine or versions ({what})"
    return None


def compare(
    new: Bench, previous: Mapping[str, Any] | None, source: str, problem: str | None = None
) -> tuple[dict, list[dict]]:
    """The previous run's block and the regressions of ``new`` against it.

    Parameters
    ----------
    new : Bench
        The run just measured.
    previous : mapping or None
        The previous run's ``bench.json`` as a dict; None when there is none (or it could not
        be read: ``problem`` says why).
    source : str
        Where the previous run was looked for (a path).
    problem : str, optional
        Why ``previous`` could not be read.

    Returns
    -------
    previous_block : dict
        ``source``, ``status`` (:data:`COMPARED` or why not), ``reason`` in words, the
        previous run's date, kind, machine and versions, ``figures`` (its timed figures, kept
        beside the new ones), ``compared`` (how many figures both runs hold), ``faster`` (how
        many got more than :data:`SLOWER` faster) and ``threshold``.
    regressions : list of dict
        Every figure more than :data:`SLOWER` slower: scene, figure, turns, previous and new
        seconds and their ratio (new over previous), slowest first.
    """
    block: dict[str, Any] = {"source": source, "threshold": SLOWER}
    if previous is None:
        status = UNREADABLE if problem else NO_PREVIOUS
        reason = f"{source} could not be read: {problem}" if problem else f"no {source}"
        return {**block, "status": status, "reason": reason}, []
    before = figures(previous)
    block.update(_meta_of(previous), figures=before, compared=0, faster=0)
    refused = _not_comparable(new, previous)
    if refused:
        return {**block, "status": refused[0], "reason": refused[1]}, []
    old = {_key(f): f["seconds"] for f in before}
    pairs = [(f, old[_key(f)]) for f in figures(vars(new)) if _key(f) in old]
    if not pairs:
        reason = "the two runs share no timed figure (other scenes, ladders or turns)"
        return {**block, "status": NOTHING_IN_COMMON, "reason": reason}, []
    regressions = [
        {**f, "previous": was, "new": f["seconds"], "ratio": f["seconds"] / was}
        for f, was in pairs
        if was > 0 and f["seconds"] > was * (1 + SLOWER)
    ]
    for r in regressions:
        del r["seconds"]
    regressions.sort(key=lambda r: -r["ratio"])
    block.update(
        status=COMPARED,
        reason=f"the same machine and versions ({', '.join(SAME_MACHINE)})",
        compared=len(pairs),
        faster=sum(f["seconds"] * (1 + SLOWER) < was for f, was in pairs),
    )
    return block, regressions


def confirm(bench: Bench, retime: Callable[[dict], float | None]) -> Bench:
    """``bench`` with each figure :func:`compare` named slower timed once more: ``retime``
    (a regression → the figure's seconds measured again now, or None where it cannot be)
    gives its time ``again``; a figure whose time again is within :data:`SLOWER` of the
    previous run's is no longer named, and is listed in the previous block's ``not_again``
    (scene, figure, turns, the run's and the second time). A timing moved by the machine for
    a moment passes the second look; a slowdown of the code, which every timing shows, does
    not. The run's own figures are kept as measured."""
    if not bench.regressions:
        return bench
    named, passed = [], []
    for r in bench.regressions:
        again = retime(r)
        r = {**r, "again": again}
        if again is not None and again <= r["previous"] * (1 + SLOWER):
            passed.append({k: r[k] for k in ("scene", "figure", "turns", "new", "again")})
        else:
            named.append(r)
    return replace(bench, previous={**bench.previous, "not_again": passed}, regressions=named)


def slower_scenes(bench: Bench) -> list[str]:
    """The scenes (or "throughput", "scaling", "onset map") with a figure named slower, in the
    order of their slowest figure."""
    return list(dict.fromkeys(r["scene"] for r in bench.regressions))


def _seconds(x: float) -> str:
    return f"{format_short(x * 1e3)} ms" if x < 1 else f"{format_short(x)} s"


def summary(bench: Bench) -> str:
    """One sentence: which scenes got slower than the previous run, none, or why none could
    be compared."""
    p = bench.previous
    percent = f"{format_short(SLOWER * 100)} %"
    if not p:
        return "No previous run to compare with: this run's bench.json keeps none."
    if p["status"] in (NO_PREVIOUS, UNREADABLE):
        return f"No previous run to compare with: {p['reason']}."
    was = f"the previous run ({p['source']}"
    was += f", {p['date']})" if p.get("date") else ")"
    if p["status"] != COMPARED:
        return f"Not compared with {was}: {p['reason']}; no figure is named slower."
    if not bench.regressions:
        return (
            f"Against {was}, on {p['reason']}: none of {p['compared']} timed figures is more "
            f"than {percent} slower ({p['faster']} more than {percent} faster){_load(bench)}"
            f"{_passed(bench)}."
        )
    scenes = slower_scenes(bench)
    return (
        f"Against {was}, on {p['reason']}: {len(bench.regressions)} of {p['compared']} timed "
        f"figures more than {percent} slower, on {', '.join(scenes)} ({p['faster']} more than "
        f"{percent} faster){_load(bench)}{_passed(bench)}."
    )


def _passed(bench: Bench) -> str:
    """The figures timed again (:func:`confirm`) and then within :data:`SLOWER`."""
    passed = bench.previous.get("not_again") or ()
    if not passed:
        return ""
    each = "; ".join(
        f"{f['scene']}: {f['figure']} {_seconds(f['new'])}, again {_seconds(f['again'])}"
        for f in passed
    )
    return (
        f"; {len(passed)} more, more than {format_short(SLOWER * 100)} % slower in the run, "
        f"were timed again and then were not ({each})"
    )


def _load(bench: Bench) -> str:
    """The two runs' load averages at their start, where both are known: other work on the
    machine slows a run's timings."""
    was, now = bench.previous.get("load_average_at_start"), bench.meta.get("load_average_at_start")
    if not (finite(was) and finite(now)):
        return ""
    return f"; load average {format_short(was, 2)} then, {format_short(now, 2)} now"


def rows(bench: Bench) -> list[list[str]]:
    """The regressions as table rows: scene, figure, previous, new, ratio, and the time again
    (:func:`confirm`; "–" where it was not)."""
    return [
        [
            r["scene"],
            r["figure"],
            _seconds(r["previous"]),
            _seconds(r["new"]),
            f"{format_short(r['ratio'])}×",
            _seconds(r["again"]) if finite(r.get("again")) else "–",
        ]
        for r in bench.regressions
    ]


HEADER = ["scene", "figure", "previous run", "this run", "ratio", "timed again"]


def markdown(bench: Bench) -> str:
    """The comparison as markdown: :func:`summary`, then a table of the regressions."""
    lines = [summary(bench)]
    if bench.regressions:
        table = ["| " + " | ".join(HEADER) + " |", "|" + "|".join("---" for _ in HEADER) + "|"]
        table += ["| " + " | ".join(r) + " |" for r in rows(bench)]
        lines += ["", *table]
    return "\n".join(lines)


def text(bench: Bench) -> list[str]:
    """The comparison as ``campipe bench``'s verdict prints it: a line, and one per figure
    named slower."""
    lines = [summary(bench)]
    lines += [
        f"  slower  {s}: {f}: {p} → {n} ({r}){'' if a == '–' else f', timed again {a}'}"
        for s, f, p, n, r, a in rows(bench)
    ]
    return lines
