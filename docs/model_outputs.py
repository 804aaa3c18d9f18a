"""Rewrite the outputs docs/model.md shows (``campipe model --convergence``) from the
command itself, so they are never typed by hand.

    python docs/model_outputs.py          # rewrite docs/model.md
    python docs/model_outputs.py --check  # exit 1 if docs/model.md differs

``tests/integration/test_cli_model.py`` runs the same commands and compares them with the page.
"""

from __future__ import annotations

import sys
from pathlib import Path

from click.testing import CliRunner

from campipe.cli import main

PAGE = Path(__file__).resolve().parent / "model.md"

#: Marker → the ``campipe model`` arguments whose output follows it in a fenced block.
OUTPUTS = {
    "model-convergence-spring": ["--convergence", "spring_elements", "--modes", "4"],
    "model-convergence-rocker": ["--convergence", "rocker_valve_arm_elements", "--modes", "5"],
}


def output(args: list[str]) -> str:
    """The command line and what it prints."""
    result = CliRunner().invoke(main, ["model", *args], catch_exceptions=False)
    return f"$ campipe model {' '.join(args)}\n{result.output}"


def rewritten(text: str) -> str:
    """``text`` with the fenced block after each ``<!-- marker -->`` replaced by its output."""
    for marker, args in OUTPUTS.items():
        start = text.index(f"<!-- {marker} -->\n")
        body = text.index("\n", text.index("```", start)) + 1
        end = text.index("```", body)
        text = text[:body] + output(args) + text[end:]
    return text


if __name__ == "__main__":
    old = PAGE.read_text()
    new = rewritten(old)
    if "--check" in sys.argv[1:]:
        sys.exit(0 if new == old else 1)
    PAGE.write_text(new)
