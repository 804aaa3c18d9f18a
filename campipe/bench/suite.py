"""The bench's fixed suite: six scenes of the thesis model, and the ladders each method climbs.

Every scene is the thesis preset (245 lbf/in, 151 lbf preload) on a 1 in cam, started on its
periodic steady state (the engine's default start, ``RunSettings.start``; every method
compared starts there), sampled every degree of cam angle. A scene that follows the cam
repeats its first turn: the default integrates it once and copies it to the other
(docs/engine.md), where the peers integrate both, so about half of its ratio there is that.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from campipe.constants import INCH, RPM
from campipe.engine import Case
from campipe.model import ValveTrain, thesis_train
from campipe.profiles import flat, harmonic, polydyne

#: Output spacing of every run the bench compares [rad]: the study default.
OUTPUT_EVERY = math.radians(1.0)


def rpm(speed: float) -> float:
    """Cam speed [rpm] → [rad/s]."""
    return speed * RPM


@dataclass(frozen=True)
class Scene:
    """One case of the suite."""

    name: str  # short id, used in tables and on the command line
    description: str  # what the scene exercises
    case: Case  # the engine's input
    revolutions: float  # cam turns integrated


def suite(train: ValveTrain | None = None) -> tuple[Scene, ...]:
    """The six scenes, in a fixed order: contact, separation, seat, bouncing, defect, form.

    Parameters
    ----------
    train : ValveTrain, optional
        The valve train (default: the thesis preset).
    """
    t = train or thesis_train()
    cam = harmonic(1.0 * INCH)
    return (
        Scene("smooth-9000", "smooth contact, 9000 rpm, no seat", Case(t, cam, rpm(9000)), 2),
        Scene(
            "separation-11000",
            "separation and re-bounce, 11000 rpm, no seat",
            Case(t, cam, rpm(11000)),
            2,
        ),
        Scene(
            "seat-13205",
            "seat chatter, 13205 rpm, seat at 0.1 in",
            Case(t, cam, rpm(13205), seat=0.1 * INCH),
            2,
        ),
        Scene(
            "bouncing-20000", "continuous bouncing, 20000 rpm, no seat", Case(t, cam, rpm(20000)), 2
        ),
        Scene(
            "flat-15000",
            "flat defect 268–272 deg, 15000 rpm, no seat",
            Case(t, flat(cam, math.radians(268), math.radians(272)), rpm(15000)),
            2,
        ),
        Scene(
            "polydyne-9000",
            "polydyne-4567 90/90/90 deg, form closure, 9000 rpm",
            Case(t, polydyne("4567", INCH, *np.radians([90, 90, 90])), rpm(9000), closure="form"),
            2,
        ),
    )


SCENE_NAMES = tuple(s.name for s in suite())


@dataclass(frozen=True)
class Ladder:
    """The settings each method is run at: steps, tolerances, cut-offs."""

    newmark_steps: tuple[float, ...]  # newmark-linear Δt [s]
    modal_tolerances: tuple[float, ...]  # modal-exact event tolerance [s], no step cap
    modal_caps: tuple[float, ...]  # modal-exact step caps [s] at the default tolerance
    #: The default also run with only the contact coordinates sampled (``run_batch(…,
    #: full_state=False)``).
    contacts_only: bool
    ivp_rtols: tuple[float, ...]  # solve_ivp relative tolerances
    copies: int  # copies of a case in one timed batch (amortises the Python overhead)
    repeats: int  # timed repeats of an engine batch; the best is kept
    ivp_repeats: int  # timed repeats of a solve_ivp run; the best is kept
    ivp_method: str = "Radau"  # the solve_ivp peer's method


FULL = Ladder(
    newmark_steps=(3e-6, 2e-6, 1e-6, 0.5e-6, 0.25e-6, 0.1e-6, 0.05e-6, 0.025e-6),
    modal_tolerances=(1e-6, 1e-8, 1e-10, 1e-12),
    modal_caps=(2e-6, 0.5e-6),
    contacts_only=True,
    ivp_rtols=(1e-4, 1e-6, 1e-8, 1e-10),
    copies=32,
    repeats=3,
    ivp_repeats=2,
)
QUICK = Ladder(
    newmark_steps=(3e-6, 1e-6, 0.3e-6),
    modal_tolerances=(1e-8, 1e-12),
    modal_caps=(),
    contacts_only=True,
    ivp_rtols=(1e-5, 1e-7),
    copies=8,
    repeats=2,
    ivp_repeats=1,
)
