"""The ``campipe`` command line (click). I/O only: every number comes from the numerics layer."""

from __future__ import annotations

import json
import logging

import click
import numpy as np
import yaml

from campipe.model import (
    CONFIGURATIONS,
    COORDINATES,
    PARAMETERS,
    PRESETS,
    ROMAN,
    ModelParameterError,
    newmark_linear_stability_limit,
    system_matrices,
    valve_train,
)
from campipe.model.assembly import TRANSLATIONS, to_display_units
from campipe.units import convert

#: The thesis's display units: lengths in inches, energies in lbf·in.
INCH = 0.0254
LBF_IN = convert(1.0, "lbf*in", "J")
RAD_S_TO_RPM = 60.0 / (2.0 * np.pi)


def parse_overrides(pairs: tuple[str, ...]) -> dict[str, object]:
    """``("spring_rate=260 lbf/in", …)`` → ``{"spring_rate": "260 lbf/in"}``, values as YAML."""
    out: dict[str, object] = {}
    for pair in pairs:
        key, sep, text = pair.partition("=")
        key = key.strip()
        if not sep or not key:
            raise click.BadParameter(
                f"{pair!r}: write NAME=VALUE, e.g. spring_rate='260 lbf/in'", param_hint="--set"
            )
        try:
            out[key] = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise click.BadParameter(f"{key}: cannot read {text!r} ({exc})", param_hint="--set")
    return out


@click.group()
@click.version_option(package_name="campipe")
@click.option("-v", "--verbose", count=True, help="More log output (-v info, -vv debug).")
def main(verbose: int) -> None:
    """campipe: parametric studies of cam-driven valve-train dynamics."""
    logging.basicConfig(level=[logging.WARNING, logging.INFO, logging.DEBUG][min(verbose, 2)])


@main.command()
@click.option("--preset", default="thesis-1971", show_default=True,
              type=click.Choice(sorted(PRESETS)), help="Named parameter set.")
@click.option("--set", "sets", multiple=True, metavar="NAME=VALUE",
              help="Override a model parameter, with units: --set spring_rate='260 lbf/in'. "
                   "Repeatable. Names: " + ", ".join(PARAMETERS))
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object (SI units).")
def model(preset: str, sets: tuple[str, ...], as_json: bool) -> None:
    """Print the model's matrices, natural frequencies, mode shapes and stability limits."""
    overrides = parse_overrides(sets)
    try:
        train = valve_train(preset, overrides)
    except ModelParameterError as exc:
        raise click.UsageError(str(exc)) from None
    sm = system_matrices(train)
    limits = {
        ROMAN[c]: newmark_linear_stability_limit(sm.mass, sm.stiffness, c) for c in CONFIGURATIONS
    }
    if as_json:
        click.echo(json.dumps(model_report(train, sm, limits, preset), indent=1))
    else:
        click.echo(model_text(train, sm, limits, preset, overrides))


def model_report(train, sm, limits, preset) -> dict[str, object]:
    """The JSON form of ``campipe model``: SI units throughout."""
    return {
        "preset": preset,
        "parameters": {
            name: {"value": getattr(train, name), "units": p.units or "1"}
            for name, p in PARAMETERS.items()
        },
        "coordinates": [
            {"symbol": c.symbol, "name": c.name, "kind": c.kind, "positive": c.positive,
             "units": "m" if c.kind == "translation" else "rad"}
            for c in COORDINATES
        ],
        "natural_frequencies": sm.frequencies.tolist(),
        "natural_frequencies_rpm": (sm.frequencies * RAD_S_TO_RPM).tolist(),
        "mass_matrix": sm.mass.tolist(),
        "stiffness_matrix": sm.stiffness.tolist(),
        "damping_matrix": sm.damping.tolist(),
        "mode_shapes": sm.modes.tolist(),
        "stability_limit_s": limits,
        "units": {
            "natural_frequencies": "rad/s",
            "mass_matrix": "kg (translation pairs), kg·m (mixed), kg·m² (rotation pairs)",
            "stiffness_matrix": "N/m (translation pairs), N (mixed), N·m (rotation pairs)",
            "damping_matrix": "N·s/m (translation pairs), N·s (mixed), N·m·s (rotation pairs)",
            "mode_shapes": "mass-normalised (Φᵀ M Φ = I, SI)",
            "stability_limit_s": "s",
        },
    }


def _matrix_text(a: np.ndarray, scale: float) -> list[str]:
    head = "      " + "".join(f"{c.symbol:>9}" for c in COORDINATES)
    rows = [head]
    for c, row in zip(COORDINATES, a / scale, strict=True):
        rows.append(f"  {c.symbol:<4}" + "".join(f"{v:9.2f}" for v in row))
    return rows


def model_text(train, sm, limits, preset, overrides) -> str:
    """The human form of ``campipe model``, in the thesis's units and layout."""
    lines = [f"campipe model: preset {preset}"
             + (f", overrides {', '.join(overrides)}" if overrides else "")]
    lines.append("")
    lines.append("Parameters (thesis units)")
    for name, p in PARAMETERS.items():
        v = getattr(train, name)
        text = (", ".join(f"{x:g}" for x in v) if p.length
                else f"{convert(v, p.units, p.thesis_units):g} {p.thesis_units}")
        lines.append(f"  {name:<28} {text}")
    lines.append("")
    lines.append("Coordinates (thesis order and signs)")
    for c in COORDINATES:
        lines.append(f"  {c.symbol}  {c.name:<28} {c.kind:<11} positive {c.positive}")
    rot = "rows/cols with a rotation carry rad: ×in per translation index"
    blocks = [
        ("Mass matrix [M] (Figure 11)", sm.mass, 1e-5, "lbf·s²/in", "×1e-5"),
        ("Stiffness matrix [K] (Figure 12)", sm.stiffness, 1e5, "lbf/in", "×1e5"),
        ("Damping matrix [C] (Figure 13)", sm.damping, 1e-2, "lbf·s/in", "×1e-2"),
    ]
    for title, a, scale, unit, tag in blocks:
        lines.append("")
        lines.append(f"{title}  {tag} {unit} ({rot})")
        lines += _matrix_text(to_display_units(a, INCH, LBF_IN), scale)
    lines.append("")
    lines.append("Natural frequencies (Figure 14)")
    lines.append(f"  {'mode':>4} {'rad/s':>14} {'rpm':>14} {'ζ':>6}")
    for i, (w, z) in enumerate(zip(sm.frequencies, train.damping_ratios, strict=True), 1):
        lines.append(f"  {i:>4} {w:14.1f} {w * RAD_S_TO_RPM:14.1f} {z:6.3f}")
    lines.append("")
    lines.append("Mode shapes (Figure 14), one column a mode, scaled to a largest translation of 1"
                 " (rotations in rad/in)")
    modes = sm.modes / np.where([c.kind == "translation" for c in COORDINATES], INCH, 1.0)[:, None]
    modes = modes / np.abs(modes[TRANSLATIONS]).max(axis=0)
    lines.append("      " + "".join(f"{'mode ' + str(j):>9}" for j in range(1, 8)))
    for c, row in zip(COORDINATES, modes, strict=True):
        lines.append(f"  {c.symbol:<4}" + "".join(f"{v:9.3f}" for v in row))
    lines.append("")
    lines.append("Stability limit of newmark-linear (Δt < √12/ω_max of the held configuration)")
    for name, dt in limits.items():
        lines.append(f"  {name:<4} {dt * 1e6:8.4f} µs")
    return "\n".join(lines)
