"""Rewrite the outputs the README shows (its five-line analysis, the quickstart's query
summary and its figure, ``docs/quickstart-metric.png``) from a fresh run of
``studies/quickstart.yaml``, and its note on the preset's damping from the model, so they are
never typed or drawn by hand.

    python docs/readme_outputs.py          # rewrite README.md and the figure
    python docs/readme_outputs.py --check  # exit 1 if README.md differs (the figure aside)

``tests/integration/test_docs.py`` runs the same commands and compares them with the README.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
import tempfile
from pathlib import Path

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


def outputs(figure: Path | None = None) -> tuple[str, str]:
    """(the analysis's printout, the summary's) from a fresh quickstart run; with ``figure``,
    ``campipe plot metric`` of that run is written there."""
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
        if figure is not None:
            drawn = CliRunner().invoke(main, [*PLOT, str(archive), "-o", str(figure)])
            if drawn.exit_code != 0:
                raise RuntimeError(drawn.output)
    return out.getvalue(), summary


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


def rewritten(figure: Path | None = None) -> str:
    text = README.read_text()
    analysis, summary = outputs(figure)
    a, b = _fenced_after(text, "readme-analysis-output")
    text = text[:a] + analysis + text[b:]
    head, rest = text.split(SUMMARY, 1)
    text = head + SUMMARY + summary + rest[rest.index("```") :]
    head, rest = text.split(DAMPING, 1)
    return head + DAMPING + damping_note() + "\n" + rest[rest.index(END) :]


if __name__ == "__main__":
    if "--check" in sys.argv[1:]:
        sys.exit(0 if rewritten() == README.read_text() else 1)
    README.write_text(rewritten(FIGURE))
