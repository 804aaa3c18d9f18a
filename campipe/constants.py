"""Shared numerical constants: unit factors and 2π, each defined once.

The archive and the engine are SI; these turn the thesis's inch-pound-second values and the
designer's rpm into it. Pure Python: importing this module costs nothing.
"""

from __future__ import annotations

import math

TWO_PI = 2.0 * math.pi
#: Metres per inch (exact).
INCH = 0.0254
#: Newtons per pound-force (exact, standard gravity).
LBF = 4.4482216152605
#: Joules per inch pound-force.
LBF_IN = LBF * INCH
#: Standard gravity [m/s²]: turns the thesis's specific weight into density (386.088 in/s²).
STANDARD_GRAVITY = 9.80665
#: rad/s per rpm.
RPM = TWO_PI / 60.0
#: ``campipe onset``'s default tolerance [rpm] and, with a seat, its default level [deg of
#: no-follow a turn] (``engine.onset.onset_speeds``: why 0.5°); the design section's too.
DEFAULT_ONSET_TOLERANCE_RPM = 0.1
DEFAULT_ONSET_LEVEL_DEG = 0.5
