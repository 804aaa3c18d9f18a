"""Rewrite the outputs the README shows (its five-line analysis, the quickstart's query
summary and its figure, ``docs/quickstart-metric.png``) from a fresh run of
``studies/quickstart.yaml``, and its note on the preset's damping from the model, so they are
never typed or drawn by hand.

    python docs/readme_outputs.py          # rewrite README.md and the figure
    python docs/readme_outputs.py --check  # exit 1 if README.md differs (the figure aside)

A case that never repeats (``period_turns`` 0) reports statistics over a chaotic window, whose
bits follow the platform's round-off: its mean a turn is compared within three combined
standard errors (:func:`analysis_differences`, :func:`summary_differences`), every other
number exactly. ``tests/integration/test_docs.py`` runs the same commands and compares them
with the README by the same rules.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import sys
import tempfile
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from campipe.cli import main
from campipe.constants import INCH, LBF
from campipe.model import system_matrices, thesis_train
from campipe.study import load_study
from campipe.study.run.execute import run_study

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
SUMMARY = "$ campipe query studies/quickstart.nc --summary\n"
#: The README's figure and the command that draws it (the README's first plot command).
FIGURE = ROOT / "docs" / "quickstart-metric.png"
PLOT = ["plot", "metric"]


def _fenced_after(text: str, marker: str) -> tuple[int, int]:
    """The span of the body of the first fenced block after ``<!-- marker -->``."""
    start = text.index(f"<!-- {marker} -->\n")
    open_ = text.index("```", start)
    body = text.index("\n", open_) + 1
    return body, text.index("```", body)


#: A number of the analysis's printout; a mean ± its standard error of the summary's.
NUMBER = re.compile(r"^[-+]?(\d+\.?\d*(e[-+]?\d+)?|nan)$", re.IGNORECASE)
PAIR = re.compile(r"(\d+\.?\d*) ± (\d+\.?\d*)")


def never_repeating(archive) -> list[tuple[float, bool, float]]:
    """(speed [rpm], seated, the standard error of its no-follow a turn [degree]) of each case
    of the quickstart that never repeats: its statistics over a chaotic window, whose bits (and
    so its mean, within its standard error) follow the platform's round-off
    (tests/integration/test_digest.py), where a settled case's numbers agree to 1e-6."""
    import xarray as xr

    with xr.open_dataset(archive) as ds:
        never = np.flatnonzero(ds["period_turns"].values == 0)
        seat = ds["seat"].values
        return [
            (
                float(ds["speed_rpm"].values[i]),
                bool(np.isfinite(seat[i])),  # no seat: -inf
                float(ds["separation_deg_per_rev_uncertainty"].values[i]),
            )
            for i in never
        ]


def analysis_differences(printed: str, shown: str, never) -> list[str]:
    """Where the analysis's printout (its table: the seat, then speed, no seat, seated a row)
    differs from the one shown: its words exactly, its numbers to 1e-6, a never-repeating
    case's (``never``) within 3·√2 of its standard error."""
    a, b = printed.split(), shown.split()
    words = [t for t in a if not NUMBER.match(t)], [t for t in b if not NUMBER.match(t)]
    if words[0] != words[1]:
        return [f"the analysis's words: {words[0]} against {words[1]}"]
    values = np.array([float(t) for t in a if NUMBER.match(t)])
    expected = np.array([float(t) for t in b if NUMBER.match(t)])
    if values.size != expected.size:
        return [f"the analysis's numbers: {values.size} against {expected.size}"]
    atol = np.zeros(expected.size)
    speeds = values[1::3].tolist()
    for speed, seated, error in never:
        atol[1 + 3 * speeds.index(speed) + (2 if seated else 1)] = 3.0 * np.sqrt(2.0) * error
    off = np.abs(values - expected) > 1e-6 * np.abs(expected) + atol
    pairs = zip(values[off], expected[off], strict=True)
    return [f"the analysis's {x:g} against {y:g}" for x, y in pairs]


def summary_differences(printed: str, shown: str) -> list[str]:
    """Where the summary printed differs from the one shown: its text exactly but for each
    mean ± standard error (a never-repeating case's), those within three combined standard
    errors."""
    if PAIR.sub("…", printed) != PAIR.sub("…", shown):
        return ["the summary's text"]
    return [
        f"the summary's {a} ± {ea} against {b} ± {eb}"
        for (a, ea), (b, eb) in zip(PAIR.findall(printed), PAIR.findall(shown), strict=True)
        if abs(float(a) - float(b)) > 3.0 * np.hypot(float(ea), float(eb))
    ]


def outputs(figure: Path | None = None) -> tuple[str, str, list[tuple[float, bool, float]]]:
    """(the analysis's printout, the summary's, :func:`never_repeating`'s cases) from a fresh
    quickstart run; with ``figure``, ``campipe plot metric`` of that run is written there."""
    text = README.read_text()
    a, b = _fenced_after(text, "readme-analysis")
    code = text[a:b]
    with tempfile.TemporaryDirectory() as tmp:
        archive = Path(tmp) / "studies" / "quickstart.nc"
        archive.parent.mkdir()
        run_study(load_study(ROOT / "studies" / "quickstart.yaml"), archive, scheduler="threads")
        here = os.getcwd()
        os.chdir(tmp)
        try:
            out = io.StringIO()
            with contextlib.redirect_stdout(out):
                exec(compile(code, "README.md", "exec"), {})
        finally:
            os.chdir(here)
        summary = CliRunner().invoke(main, ["query", str(archive), "--summary"]).output
        never = never_repeating(archive)
        if figure is not None:
            drawn = CliRunner().invoke(main, [*PLOT, str(archive), "-o", str(figure)])
            if drawn.exit_code != 0:
                raise RuntimeError(drawn.output)
    return out.getvalue(), summary, never


DAMPING = "<!-- preset-damping -->\n"
END = "<!-- end preset-damping -->"


def damping_note(rpm: float = 9000.0) -> str:
    """The preset's first-mode damping as the dashpot it is, from the model: the damping the
    first mode's shape meets, per unit valve velocity, and its drag at the peak valve velocity
    of the thesis's 1 in harmonic cam at ``rpm``, against the spring preload."""
    train = thesis_train()
    sm = system_matrices(train)
    shape = sm.modes[:, 0] / sm.modes[6, 0]  # mode 1, unit valve motion
    dashpot = float(shape @ sm.damping @ shape)  # [N·s/m] at the valve
    ratio = -shape[0]  # cam-end motion per unit valve motion: 1 / the rocker ratio
    omega = rpm * 3.141592653589793 / 30
    drag = dashpot * omega * 0.5 * INCH / ratio  # at the valve's peak velocity [N]
    zeta = train.damping_ratios[0]
    return (
        f"The thesis's preset damps its first mode (the whole train on its spring) with "
        f"ζ1 = {zeta:g}: a dashpot to ground of {dashpot:.0f} N·s/m at the valve, which at "
        f"{rpm:.0f} rpm drags the valve with up to {drag / LBF:.0f} lbf, more than the "
        f"{train.spring_preload / LBF:.0f} lbf preload that holds the train on the cam. Damping, "
        "not only inertia, sets the preset's separation speeds, and ζ1 is the thesis's choice, "
        "not a measured property: a study of separation speeds should vary `damping_ratios` "
        "beside the spring."
    )


def rewritten(figure: Path | None = None) -> tuple[str, list[str]]:
    """The README with its outputs from a fresh run, and where they differ from those it shows
    beyond a never-repeating case's standard error (none: the README is up to date)."""
    text = README.read_text()
    analysis, summary, never = outputs(figure)
    a, b = _fenced_after(text, "readme-analysis-output")
    differences = analysis_differences(analysis, text[a:b], never)
    text = text[:a] + analysis + text[b:]
    head, rest = text.split(SUMMARY, 1)
    differences += summary_differences(summary, rest[: rest.index("```")])
    text = head + SUMMARY + summary + rest[rest.index("```") :]
    head, rest = text.split(DAMPING, 1)
    text = head + DAMPING + damping_note() + "\n" + rest[rest.index(END) :]
    return text, differences


def _outside_outputs(text: str) -> str:
    """``text`` with the README's two printed outputs taken out."""
    a, b = _fenced_after(text, "readme-analysis-output")
    text = text[:a] + text[b:]
    head, rest = text.split(SUMMARY, 1)
    return head + rest[rest.index("```") :]


if __name__ == "__main__":
    if "--check" in sys.argv[1:]:
        new, differences = rewritten()
        for difference in differences:
            print(f"README.md differs: {difference}", file=sys.stderr)
        same = _outside_outputs(new) == _outside_outputs(README.read_text())
        sys.exit(0 if same and not differences else 1)
    README.write_text(rewritten(FIGURE)[0])
