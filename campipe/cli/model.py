"""``campipe model``, ``campipe init`` and ``campipe schema``: the model's matrices and limits, the
example specs, the JSON Schemas."""

from __future__ import annotations

import json
import math

import click
import numpy as np

from campipe.cli.base import Failure, InputFailure, parse_overrides
from campipe.cli.model_cam import (
    ratio_table,
    ratio_text,
    shape_report,
    shape_text,
    shown_cam,
)
from campipe.constants import INCH, LBF_IN, RPM, TWO_PI
from campipe.model import (
    ELEMENTS,
    PARAMETERS,
    PRESETS,
    Coordinate,
    ModelParameterError,
    coordinates,
    modal_damping_ratios,
    system_matrices,
    to_display_units,
    valve_train,
)
from campipe.model.assembly import (
    CONVERGENCE_ELEMENTS,
    NEWMARK_LINEAR_OMEGA_DT,
    SystemMatrices,
    frequency_convergence,
    normal_modes,
    observed_orders,
)
from campipe.model.checks import DIRECT_ACTING, LUMPED, PUSHROD_ROCKER, layouts_of_key
from campipe.model.contact_modes import ContactMode, contact_modes
from campipe.model.hla import adjuster, hla_series, on_pivot, seated_stiffness
from campipe.model.layouts import mirror, own_matrices, used_coordinates
from campipe.model.levers import LEVERS, pivot_gain
from campipe.profiles.levers import cam_of
from campipe.units import QuantityError, convert, parse_quantity, pint_without_dask
from campipe.vocabulary import CONFIGURATIONS, ROMAN, free_coordinates

#: The parameters ``campipe model --convergence`` refines.
REFINEMENTS = tuple(f"{member}_elements" for member in ELEMENTS)


@click.command()
@click.option(
    "--preset",
    default="thesis-1971",
    show_default=True,
    type=click.Choice(sorted(PRESETS)),
    help="Named parameter set.",
)
@click.option(
    "--set",
    "sets",
    multiple=True,
    metavar="NAME=VALUE",
    help="Override a model parameter, with units: --set spring_rate='260 lbf/in'. "
    "Repeatable. Names: " + ", ".join(PARAMETERS),
)
@click.option(
    "--spec",
    "spec_path",
    type=click.Path(dir_okay=False),
    metavar="SPEC",
    help="Take the model from a study spec (its case --case's, where it varies model keys); "
    "--set then sets the spec's model keys.",
)
@click.option(
    "--case",
    "case_index",
    default=0,
    show_default=True,
    type=click.IntRange(min=0),
    metavar="N",
    help="With --spec, the case (from 0, in the archive's order) whose model is shown.",
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object (SI units).")
@click.option(
    "--convergence",
    type=click.Choice(REFINEMENTS),
    metavar="NAME",
    help="Instead, show how the lowest natural frequencies converge as the parameter NAME "
    f"(one of: {', '.join(REFINEMENTS)}) divides its member into "
    + ", ".join(map(str, CONVERGENCE_ELEMENTS))
    + " elements.",
)
@click.option(
    "--cam-lift",
    default="6 mm",
    show_default=True,
    metavar="QUANTITY",
    help="The harmonic cam's lift under which a lever layout's kinematic ratio is tabulated "
    "and the cam's shape drawn (without --spec).",
)
@click.option(
    "--ratio-step",
    default=30.0,
    show_default=True,
    type=click.FloatRange(min=0.1, max=180.0),
    metavar="DEG",
    help="Cam-angle step [deg] of the kinematic ratio's table.",
)
@click.option(
    "--modes",
    default=6,
    show_default=True,
    type=click.IntRange(1, 64),
    help="Modes shown with --convergence.",
)
def model(
    preset: str,
    sets: tuple[str, ...],
    spec_path: str | None,
    case_index: int,
    as_json: bool,
    convergence: str | None,
    cam_lift: str,
    ratio_step: float,
    modes: int,
) -> None:
    """Print the model's matrices, natural frequencies, mode shapes, stability limits and
    kinematic ratio over the cam turn."""
    pint_without_dask()  # this process is the command's own
    overrides = parse_overrides(sets)
    if spec_path is None and case_index:
        raise click.UsageError("--case chooses a case of --spec SPEC: give the spec")
    cam = drive = None
    metric = False  # the thesis's train in the thesis's units, unless its spec writes mm
    if spec_path is not None:
        train, preset, cam, drive, metric = spec_model(spec_path, sets, overrides, case_index)
    else:
        try:
            train = valve_train(preset, overrides)
        except ModelParameterError as exc:
            raise click.UsageError(str(exc)) from None
    if convergence is not None and train.chain:
        raise click.UsageError(
            f"--convergence refines the thesis's members; layout {train.layout} has none"
        )
    if convergence is not None:
        report = convergence_report(train, convergence, modes)
        if as_json:
            click.echo(json.dumps({**_source_json(preset), **report}, indent=1))
        else:
            click.echo(convergence_text(report, preset, overrides))
        return
    sm = system_matrices(train)
    limits = stability_limits(train, sm)
    try:
        lift = parse_quantity(cam_lift, "m", "--cam-lift", "mm")
    except QuantityError as exc:
        raise click.UsageError(str(exc)) from None
    cam, label = shown_cam(cam, lift)
    table = ratio_table(train, sm, lift, math.radians(ratio_step), cam, label)
    contacts = contact_modes(train, sm)
    shape = shape_report(train, cam, label)
    if as_json:
        report = model_report(train, sm, limits, preset, drive)
        click.echo(json.dumps({**report, **table, **shape, **contact_report(contacts)}, indent=1))
    else:
        text = model_text(train, sm, limits, preset, overrides, drive, metric)
        text += ratio_text(table)
        click.echo(text + shape_text(shape) + contact_text(contacts))


def spec_model(spec_path: str, sets: tuple[str, ...], overrides: dict, index: int):
    """The train of a study spec's case ``index`` (each of ``sets``, NAME=VALUE, set as the
    spec's ``model.NAME``; ``overrides`` the same parsed), the name it is shown under, its
    cam, its drive, and whether to show it in metric units (a spec written in mm); where the
    spec varies model keys, a line on stderr gives the case's values."""
    from pathlib import Path

    from campipe.cli.base import load_spec
    from campipe.study.query.display import spec_system, written_units

    study = load_spec(spec_path, tuple(f"model.{s.strip()}" for s in sets))
    name = Path(spec_path).name
    varied = [k for k in study.varied if k.startswith("model.")]
    swept = sorted({f"model.{k}" for k in overrides} & set(varied))
    if swept:
        raise click.UsageError(
            f"{name} varies {', '.join(swept)} across its cases: --set does not choose among "
            "them; choose a case with --case N"
        )
    n = len(study.cases)
    if not 0 <= index < n:
        raise click.BadParameter(f"{name} has cases 0 … {n - 1}", param_hint="--case")
    case = study.cases[index]
    train = case.case.train
    written = written_units({"spec": study.spec.text, "spec_overrides": json.dumps(overrides)})
    metric = train.layout != PUSHROD_ROCKER or spec_system(written) == "mm"
    if varied:
        keys = [k.removeprefix("model.") for k in varied]
        shown = ", ".join(
            f"{k} {_parameter_text(PARAMETERS[k], case.values['model.' + k], metric)}" for k in keys
        )
        click.echo(
            f"campipe model: {name} varies {', '.join(varied)} across its {n} cases; shown: "
            f"case {index}'s ({shown}); another with --case N",
            err=True,
        )
    return train, f"{name} (case {index})", cam_of(case.case.profile), study.spec.drive, metric


def _json_value(value: object) -> object:
    """NaN (a parameter given as none) as JSON's null."""
    return None if isinstance(value, float) and math.isnan(value) else value


def _shown(train, sm) -> tuple[SystemMatrices, tuple[Coordinate, ...], list[str]]:
    """What ``campipe model`` shows of ``train``: its matrices, coordinates and parameters,
    without a lumped chain's placeholders (its modes the chain's own) or another layout's
    keys."""
    shown = (None, train.layout, LUMPED if train.chain else None)
    names = [
        n
        for n in PARAMETERS
        if not layouts_of_key(n, ELEMENTS) or set(layouts_of_key(n, ELEMENTS)) & set(shown)
    ]
    coords = coordinates(train)
    used = used_coordinates(train)
    if used.size == len(coords):
        return sm, coords, names
    mass, stiffness, damping = own_matrices(train, sm.mass, sm.stiffness, sm.damping)
    omega, phi = normal_modes(mass, stiffness, np.ones(used.size, bool))
    view = SystemMatrices(mass, stiffness, damping, omega, phi, sm.preload[used])
    return view, tuple(coords[i] for i in used), names


def stability_limits(train, sm: SystemMatrices) -> dict[str, float | None]:
    """newmark-linear's stability limit [s] in each configuration (√12/ω_max of what it
    leaves free), on the train's own coordinates: a chain's placeholders, decoupled and below
    every mode, set none; None where nothing is free (a two-mass chain's cam's mass and
    valve both held, a one-mass chain's follower held at either end)."""
    used = set(used_coordinates(train).tolist()) | (
        {sm.mass.shape[0] - 1} if mirror(train) else set()
    )
    out: dict[str, float | None] = {}
    for c in CONFIGURATIONS:
        free = [i for i in free_coordinates(c, sm.mass.shape[0]) if i in used]
        if mirror(train) and len(free) < 2:  # its one mass, q1 and its mirror q7
            free = []
        if not free:
            out[ROMAN[c]] = None
            continue
        omega, _ = normal_modes(sm.mass[np.ix_(free, free)], sm.stiffness[np.ix_(free, free)])
        out[ROMAN[c]] = NEWMARK_LINEAR_OMEGA_DT / float(omega.max())
    return out


def on_the_cam(sm: SystemMatrices, coords: tuple[Coordinate, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The undamped natural frequencies [rad/s] with the follower held on the cam
    (configuration I: q1, the first coordinate, prescribed), ascending, and each mode's
    damping ratio (Φᵀ C Φ)ⱼⱼ / (2ωⱼ) with that configuration's C; none for a one-mass chain
    (nothing of it is free on the cam)."""
    if len(coords) < 2:
        return np.zeros(0), np.zeros(0)
    free = slice(1, None)
    trans = np.array([c.kind == "translation" for c in coords[free]])
    omega, phi = normal_modes(sm.mass[free, free], sm.stiffness[free, free], trans)
    damping = sm.damping[free, free]
    return omega, modal_damping_ratios(damping, phi, omega)


def model_report(train, sm, limits, preset, drive: float | None = None) -> dict[str, object]:
    """The JSON form of ``campipe model``: SI units throughout (rpm the cam's, and with a
    spec's ``drive``, cam turns per crank turn, the engine's beside)."""
    sm, coords, names = _shown(train, sm)
    held, held_zeta = on_the_cam(sm, coords)
    return {
        **_source_json(preset),
        "layout": train.layout,
        "parameters": {
            name: {
                "value": _json_value(getattr(train, name)),
                "units": PARAMETERS[name].units or "1",
            }
            for name in names
        },
        "coordinates": [
            {
                "symbol": c.symbol,
                "name": c.name,
                "kind": c.kind,
                "positive": c.positive,
                "units": "m" if c.kind == "translation" else "rad",
            }
            for c in coords
        ],
        "natural_frequencies": sm.frequencies.tolist(),
        "natural_frequencies_rpm": (sm.frequencies / RPM).tolist(),
        **(
            {"natural_frequencies_engine_rpm": (sm.frequencies / RPM / drive).tolist()}
            if drive
            else {}
        ),
        "natural_frequencies_hz": (sm.frequencies / TWO_PI).tolist(),
        "modal_damping_ratios": modal_damping_ratios(sm.damping, sm.modes, sm.frequencies).tolist(),
        "natural_frequencies_on_the_cam": held.tolist(),
        "natural_frequencies_on_the_cam_hz": (held / TWO_PI).tolist(),
        "modal_damping_ratios_on_the_cam": held_zeta.tolist(),
        "mass_matrix": sm.mass.tolist(),
        "stiffness_matrix": sm.stiffness.tolist(),
        "damping_matrix": sm.damping.tolist(),
        "mode_shapes": sm.modes.tolist(),
        "stability_limit_s": limits,
        **_adjuster_json(train),
        "units": {
            "natural_frequencies": "rad/s",
            "natural_frequencies_rpm": "rpm of the cam whose first order meets the mode",
            "natural_frequencies_engine_rpm": "rpm of the engine (a spec's drive), the cam's "
            "over drive.cam_per_crank",
            "natural_frequencies_hz": "Hz",
            "natural_frequencies_on_the_cam": "rad/s, the follower held on the cam (q1)",
            "modal_damping_ratios": "1, (Φᵀ C Φ)ⱼⱼ / (2ωⱼ)",
            "modal_damping_ratios_on_the_cam": "1, (Φᵀ C Φ)ⱼⱼ / (2ωⱼ) of the modes on the cam, "
            "with the damping there",
            "mass_matrix": "kg (translation pairs), kg·m (mixed), kg·m² (rotation pairs)",
            "stiffness_matrix": "N/m (translation pairs), N (mixed), N·m (rotation pairs)",
            "damping_matrix": "N·s/m (translation pairs), N·s (mixed), N·m·s (rotation pairs)",
            "mode_shapes": "mass-normalised (Φᵀ M Φ = I, SI)",
            "stability_limit_s": "s",
        },
    }


def _adjuster_stiffnesses(train) -> tuple[float, float, float] | None:
    """(the link next to the cam as the matrices hold it, ``stiffnesses[0]`` in series with
    the adjuster; the adjuster's stiffness in that link, :func:`~campipe.model.hla.hla_series`;
    its seated stiffness) [N/m], or None without an adjuster."""
    if adjuster(train) is None:
        return None
    k_link, k_hla = float(train.stiffnesses[0]), hla_series(train)
    return 1.0 / (1.0 / k_link + 1.0 / k_hla), k_hla, seated_stiffness(train)


def _adjuster_lines(train) -> list[str]:
    """:func:`_adjuster_stiffnesses` in words and N/mm: the listed stiffnesses are not what
    the matrices hold; [] without an adjuster."""
    found = _adjuster_stiffnesses(train)
    if found is None:
        return []
    link, in_link, seated = (k * 1e-3 for k in found)
    seen = ""
    if on_pivot(train):
        seen = f" at the pallet (hla_stiffness / g₀², the pivot's gain g₀ {pivot_gain(train):.4g})"
    return [
        f"  {'(link next to the cam)':<30} {link:.6g} N/mm in the matrices: stiffnesses[0] "
        f"{float(train.stiffnesses[0]) * 1e-3:.6g} N/mm in series with the adjuster's "
        f"{in_link:.6g} N/mm{seen}",
        f"  {'(adjuster, seated)':<30} {seated:.6g} N/mm: its load per unit of its extension "
        "on the base circle, the valve seated",
    ]


def _adjuster_json(train) -> dict[str, object]:
    """:func:`_adjuster_stiffnesses` for the JSON form, in N/m; {} without an adjuster."""
    found = _adjuster_stiffnesses(train)
    if found is None:
        return {}
    names = ("link_stiffness", "adjuster_stiffness_in_the_link", "seated_stiffness")
    return {"adjuster": {**dict(zip(names, found, strict=True)), "units": "N/m"}}


def _matrix_text(
    a: np.ndarray, scale: float, coords: tuple[Coordinate, ...], thesis: bool = True
) -> list[str]:
    """A matrix's rows over ``scale``: to two decimals as the thesis's figures print them, or
    (``thesis`` False: a layout beyond it) to six significant digits. A chain's entries can
    differ in the fourth (a finger's K: 12.035 beside 12.000 ×1e6 N/m, the spring's rate),
    and its modes recomputed from two decimals were 7 % off (a valve-train engineer's check)."""
    width = 9 if thesis else 12
    head = "      " + "".join(f"{c.symbol:>{width}}" for c in coords)
    rows = [head]
    for c, row in zip(coords, a / scale, strict=True):
        cells = (f"{v:9.2f}" if thesis else f"{v:12.6g}" for v in row)
        rows.append(f"  {c.symbol:<4}" + "".join(cells))
    return rows


#: A layout beyond the thesis's shows its parameters in the trade's metric units: the
#: thesis's inch–pound units by their metric counterparts (others as they are).
METRIC = {
    "in": "mm",
    "lbf": "N",
    "lbf/in": "N/mm",
    "lbf*s/in": "N*s/mm",
    "lbf/in**1.5": "N/mm**1.5",
    "s/in": "s/mm",
    "lbf/in**2": "N/mm**2",
}


def _parameter_text(p, value, metric: bool = False) -> str:
    shown = METRIC.get(p.thesis_units, p.thesis_units) if metric else p.thesis_units
    if p.length and p.units:
        return ", ".join(f"{convert(x, p.units, shown):g} {shown}" for x in value)
    if p.length:
        return ", ".join(f"{x:g}" for x in value)
    if p.allow_none and isinstance(value, float) and math.isnan(value):
        return "none"
    if p.choices or p.integer or not p.units:
        return f"{value:g}" if isinstance(value, float) else str(value)
    return f"{convert(value, p.units, shown):g} {shown}"


#: How ``campipe model`` shows each layout's matrices: (length, energy) of the display units
#: in SI, and each matrix's scale and units.
DISPLAY = {
    PUSHROD_ROCKER: (
        (INCH, LBF_IN),
        ((1e-5, "lbf·s²/in", "×1e-5"), (1e5, "lbf/in", "×1e5"), (1e-2, "lbf·s/in", "×1e-2")),
    ),
    LUMPED: ((1.0, 1.0), ((1e-3, "kg", "×1e-3"), (1e6, "N/m", "×1e6"), (1.0, "N·s/m", "×1"))),
}
for _chain in (DIRECT_ACTING, *LEVERS):
    DISPLAY[_chain] = DISPLAY[LUMPED]


def contact_report(contacts: list[ContactMode]) -> dict[str, object]:
    """The compliant contacts linearised at their static loads (JSON form, SI;
    :mod:`campipe.model.contact_modes`); none for rigid contacts."""
    return {
        "compliant_contacts": [
            {
                "contact": c.contact,
                "law": c.law,
                "static_load": c.load,
                "stiffness": c.stiffness,
                "damping": c.damping,
                "ratio": c.ratio,
                "valve_side_stiffness": c.valve_side_stiffness,
                "valve_side_damping": c.valve_side_damping,
                "natural_frequencies": c.frequencies.tolist(),
                "natural_frequencies_hz": (c.frequencies / TWO_PI).tolist(),
                "damping_ratios": c.damping_ratios.tolist(),
                "struck_mass": c.struck_mass,
                "contact_damping_ratio": c.contact_damping_ratio,
                "restitution": _json_value(c.restitution),
                "units": {
                    "static_load": "N",
                    "stiffness": "N/m",
                    "damping": "N·s/m",
                    "ratio": "1, the valve's travel per the contact's",
                    "valve_side_stiffness": "N/m",
                    "valve_side_damping": "N·s/m",
                    "natural_frequencies": "rad/s",
                    "damping_ratios": "1, each mode's φᵀCφ/(2ω)",
                    "struck_mass": "kg, at the contact's coordinate (a lever's cam: valve side)",
                    "contact_damping_ratio": "1, c/(2·√(k·m)) of the struck mass",
                    "restitution": "1, of the struck mass's landing (null: it depends on the "
                    "speed, a damped hertz law)",
                },
            }
            for c in contacts
        ]
    }


def contact_text(contacts: list[ContactMode]) -> str:
    """The human form of :func:`contact_report`; empty for rigid contacts."""
    if not contacts:
        return ""
    lines = [
        "",
        "",
        "Compliant contacts, linearised at their static load (the spring's preload as the "
        "valve leaves its seat, through the train to the cam); at the valve, k/r² and c/r² "
        "(r the lever ratio at the cam, 1 elsewhere)",
        f"  {'contact':<8} {'law':<13} {'load N':>9} {'k N/mm':>11} {'c N·s/m':>9} "
        f"{'r':>7} {'k/r² N/mm':>11} {'c/r² N·s/m':>11}",
    ]
    for c in contacts:
        lines.append(
            f"  {c.contact:<8} {c.law:<13} {c.load:9.1f} {c.stiffness / 1e3:11.5g} "
            f"{c.damping:9.4g} {c.ratio:7.4f} {c.valve_side_stiffness / 1e3:11.5g} "
            f"{c.valve_side_damping:11.4g}"
        )
    for c in contacts:
        hz = ", ".join(
            f"{f:.1f} (ζ {z:.3g})"
            for f, z in zip(c.frequencies / TWO_PI, c.damping_ratios, strict=True)
        )
        other = "seat" if c.contact == "cam" else "cam"
        lines.append(f"  natural frequencies, the {c.contact} closed ({other} open) [Hz]: {hz}")
    for c in contacts:
        rebound = (
            f"a landing rebounds with e = {c.restitution:.3f}"
            if math.isfinite(c.restitution)
            else "its restitution depends on the landing's speed v (e ≈ 1 − 2·α·v/3)"
        )
        lines.append(
            f"  the {c.contact}'s landing: {c.struck_mass * 1e3:.4g} g struck at its coordinate,"
            f" ζ = c/(2√(k·m)) = {c.contact_damping_ratio:.3g}: {rebound}"
        )
    return "\n".join(lines)


def _source_json(preset: str) -> dict[str, str]:
    """The JSON's key for where the model came from: ``preset``, or ``spec`` (its case)."""
    return {"preset": preset} if preset in PRESETS else {"spec": preset}


def _source(preset: str) -> str:
    """The header's words for where the model came from: a preset, or a spec."""
    return f"preset {preset}" if preset in PRESETS else f"spec {preset}"


def model_text(
    train, sm, limits, preset, overrides, drive: float | None = None, metric: bool = False
) -> str:
    """The human form of ``campipe model``, in the thesis's units and layout (a lumped
    chain's in SI); its parameters in the trade's metric units for a layout beyond the
    thesis's or where ``metric``."""
    lines = [
        f"campipe model: {_source(preset)}, layout {train.layout}"
        + (f", overrides {', '.join(overrides)}" if overrides else "")
    ]
    sm, coords, names = _shown(train, sm)
    lines.append("")
    metric = metric or train.layout != PUSHROD_ROCKER
    lines.append("Parameters (metric units)" if metric else "Parameters (thesis units)")
    for name in names:
        text = _parameter_text(PARAMETERS[name], getattr(train, name), metric)
        lines.append(f"  {name:<30} {text}")
    lines += _adjuster_lines(train)
    trans = np.array([c.kind == "translation" for c in coords])
    lines.append("")
    lines.append(
        "Coordinates (thesis order and signs; refined members' internal nodes after q7)"
        if train.layout == PUSHROD_ROCKER
        else "Coordinates (the cam's mass q1, the valve q7, the chain's others between and "
        "after; a chain of fewer than seven masses leaves the rest unused)"
    )
    for c in coords:
        lines.append(f"  {c.symbol:<4} {c.name:<30} {c.kind:<11} positive {c.positive}")
    rot = " (rows/cols with a rotation carry rad: ×in per translation index)"
    (length, energy), scales = DISPLAY[train.layout]
    titles = (
        "Mass matrix [M] (Figure 11)",
        "Stiffness matrix [K] (Figure 12)",
        f"Damping matrix [C] ({train.damping_kind}; Figure 13: modal)",
    )
    if train.chain:
        rot = ""
        titles = (
            "Mass matrix [M]",
            "Stiffness matrix [K]",
            f"Damping matrix [C] ({train.damping_kind})",
        )
    for title, a, (scale, unit, tag) in zip(
        titles, (sm.mass, sm.stiffness, sm.damping), scales, strict=True
    ):
        lines.append("")
        lines.append(f"{title}  {tag} {unit}{rot}")
        lines += _matrix_text(
            to_display_units(a, length, energy, trans), scale, coords, not train.chain
        )
    lines.append("")
    figure = " (Figure 14)" if train.n_coordinates == 7 and not train.chain else ""  # its 7
    lines.append(f"Natural frequencies{figure}, each mode's damping ratio (Φᵀ C Φ)ⱼⱼ / (2ωⱼ)")
    lines.append(
        "  (cam rpm: the cam speed whose first order meets the mode, its frequency a minute"
        + (f"; engine rpm: the crank's, by drive.cam_per_crank {drive:g})" if drive else ")")
    )
    engine = f" {'engine rpm':>14}" if drive else ""

    def speeds(w: float) -> str:
        return f"{w / TWO_PI:12.1f} {w / RPM:14.1f}" + (
            f" {w / RPM / drive:14.1f}" if drive else ""
        )

    lines.append(f"  {'mode':>4} {'rad/s':>14} {'Hz':>12} {'cam rpm':>14}{engine} {'ζ':>6}")
    zeta = modal_damping_ratios(sm.damping, sm.modes, sm.frequencies)
    for i, (w, z) in enumerate(zip(sm.frequencies, zeta, strict=True), 1):
        lines.append(f"  {i:>4} {w:14.1f} {speeds(w)} {z:6.3f}")
    lines.append("")
    held, held_zeta = on_the_cam(sm, coords)
    lines.append(
        "Natural frequencies with the follower on the cam (configuration I: q1 held), each "
        "mode's damping ratio there"
    )
    if held.size:
        lines.append(f"  {'mode':>4} {'rad/s':>14} {'Hz':>12} {'cam rpm':>14}{engine} {'ζ':>6}")
        for i, (w, z) in enumerate(zip(held, held_zeta, strict=True), 1):
            lines.append(f"  {i:>4} {w:14.1f} {speeds(w)} {z:6.3f}")
    else:
        lines.append("  none: nothing of the train is free on the cam (a rigid follower)")
    lines.append("")
    lines.append(
        f"Mode shapes{figure}, one column a mode, scaled to a largest translation of 1"
        + ("" if train.chain else " (rotations in rad/in)")
    )
    shapes = sm.modes / np.where(trans, length, 1.0)[:, None]
    shapes = shapes / np.abs(shapes[trans]).max(axis=0)
    lines.append("      " + "".join(f"{'mode ' + str(j):>9}" for j in range(1, len(coords) + 1)))
    for c, row in zip(coords, shapes, strict=True):
        lines.append(f"  {c.symbol:<4}" + "".join(f"{v:9.3f}" for v in row))
    lines.append("")
    lines.append("Stability limit of newmark-linear (Δt < √12/ω_max of the held configuration)")
    for name, dt in limits.items():
        shown = "    none: nothing is free" if dt is None else f"{dt * 1e6:8.4f} µs"
        lines.append(f"  {name:<4} {shown}")
    return "\n".join(lines)


def convergence_report(train, parameter: str, n_modes: int) -> dict[str, object]:
    """The natural frequencies as ``parameter`` (``spring_elements`` …) refines its member:
    the JSON form of ``campipe model --convergence`` (SI)."""
    member = parameter.removesuffix("_elements")
    freqs, roundoff = frequency_convergence(train, member, CONVERGENCE_ELEMENTS, n_modes)
    orders = observed_orders(freqs, roundoff, CONVERGENCE_ELEMENTS)

    def listed(a: np.ndarray) -> list:
        return (
            [None if np.isnan(v) else float(v) for v in a]
            if a.ndim == 1
            else [listed(row) for row in a]
        )

    return {
        "parameter": parameter,
        "elements": list(CONVERGENCE_ELEMENTS),
        "natural_frequencies": listed(freqs),
        "roundoff": listed(roundoff),
        "observed_orders": listed(orders),
        "units": {"natural_frequencies": "rad/s", "roundoff": "rad/s", "observed_orders": "1"},
    }


def convergence_text(report: dict, preset: str, overrides) -> str:
    """The human form of ``campipe model --convergence``."""
    parameter = report["parameter"]
    freqs = np.array(report["natural_frequencies"], dtype=float)
    roundoff = np.array(report["roundoff"], dtype=float)
    orders = np.array(report["observed_orders"], dtype=float)
    counts = report["elements"]
    member = parameter.removesuffix("_elements").replace("_", " ")
    lines = [
        f"campipe model --convergence {parameter}: {_source(preset)}"
        + (f", overrides {', '.join(overrides)}" if overrides else ""),
        "",
        f"Lowest natural frequencies [rad/s] with the {member} divided into n equal elements.",
        "New internal modes (a spring's surge) enter as n grows: a column is one mode once it "
        "settles.",
        "",
        f"  {'n':>6}" + "".join(f"{'mode ' + str(j):>14}" for j in range(1, freqs.shape[1] + 1)),
    ]
    for n, row, noise in zip(counts, freqs, roundoff, strict=True):
        cells = (_resolved(v, e) if v == v else "" for v, e in zip(row, noise, strict=True))
        lines.append(f"  {n:>6}" + "".join(f"{c:>14}" for c in cells))
    lines.append(
        f"  {'order':>6}" + "".join(f"{v:14.1f}" if v == v else f"{'-':>14}" for v in orders)
    )
    lines += [
        "",
        f"order: the observed order in 1/n from n = {', '.join(map(str, counts[-3:]))} "
        "(consistent mass: 2 for a bar, 4 for a beam);",
        "'-' where the column has not settled into one mode or has converged to the "
        "eigensolver's round-off.",
        "Each frequency to the digits above ten times its round-off (about ε/2·(ω_max/ω)²·ω,",
        "at most ten digits); each order to one decimal.",
    ]
    return "\n".join(lines)


def _resolved(value: float, roundoff: float, digits: int = 10) -> str:
    """``value`` to the decade above ten times its ``roundoff`` (at most ``digits``
    significant): the digits the eigensolver resolves, none that another machine's LAPACK
    would print differently."""
    decade = math.ceil(math.log10(10.0 * roundoff)) if roundoff > 0.0 else -digits
    decade = max(decade, math.floor(math.log10(abs(value))) + 1 - digits) if value else decade
    return f"{round(value, -decade):.{max(-decade, 0)}f}"


# -- starting without the repository -----------------------------------------------------------


def packaged_specs() -> dict[str, bytes]:
    """The example specs shipped in the package (``campipe/specs/``): file name → content."""
    from importlib import resources

    folder = resources.files("campipe") / "specs"
    return {
        entry.name: entry.read_bytes()
        for entry in sorted(folder.iterdir(), key=lambda e: e.name)
        if entry.name.endswith((".yaml", ".md"))
    }


@click.command()
@click.argument("directory", default="studies", type=click.Path(file_okay=False))
@click.option(
    "--overwrite",
    "--force",
    "overwrite",
    is_flag=True,
    help="Replace files of the same names in DIRECTORY that differ from the examples.",
)
def init(directory, overwrite) -> None:
    """Write the example specs into DIRECTORY (default: studies): the quickstart, the
    separation map and the thesis's runs, with a README; then run one with campipe study."""
    import os
    from pathlib import Path

    folder = Path(directory)
    specs = packaged_specs()
    _check_init(folder, specs, overwrite)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for name, content in specs.items():
            # a new file renamed into place: a link at the path is replaced, never followed
            tmp = folder / f".{name}.{os.getpid()}.tmp"
            tmp.write_bytes(content)
            os.replace(tmp, folder / name)
    except OSError as exc:
        raise Failure(f"{exc.filename or folder}: cannot write ({exc.strerror or exc})") from None
    for name in specs:
        click.echo(str(folder / name))
    click.echo(
        f"campipe init: {len(specs)} files in {folder}; next: campipe study "
        f"{folder / 'quickstart.yaml'}",
        err=True,
    )


def _check_init(folder, specs: dict[str, bytes], overwrite: bool) -> None:
    """The output rule (``campipe.io.outputs``) for each example: inside ``folder`` (a link
    out of it refused), a file identical to the example left as it is, any other file
    replaced only with ``overwrite``."""
    import functools

    from campipe.io.outputs import Kind, OutputExistsError, check_output

    refused: list[OutputExistsError] = []
    for name, content in specs.items():
        same = Kind("the example", functools.partial(_holds, content=content))
        try:
            check_output(folder / name, "DIRECTORY", same, overwrite=overwrite, inside=folder)
        except OutputExistsError as exc:
            refused.append(exc)
    if refused:
        more = f" (and {len(refused) - 1} more of the example files)" if len(refused) > 1 else ""
        raise InputFailure(f"{refused[0]}{more}")


def _holds(path, content: bytes) -> bool:
    """The file at ``path`` holds exactly ``content``."""
    return path.stat().st_size == len(content) and path.read_bytes() == content


@click.command()
@click.argument("which", default="study", type=click.Choice(["study", "model"]))
def schema(which) -> None:
    """Print the JSON Schema of a study spec (or of its model: block), for an editor's YAML
    checking: campipe schema > study.schema.json."""
    if which == "model":
        from campipe.model.schema import model_schema

        click.echo(json.dumps(model_schema(), indent=2, ensure_ascii=False))
        return
    from campipe.study.spec.schema import schema_text

    click.echo(schema_text(), nl=False)
