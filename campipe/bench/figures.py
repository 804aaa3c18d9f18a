"""How the bench writes a figure: to a few significant digits, and whether it is one at all.

Shared by the verdict, the regression gate, the report and the pages (and the developer's
benchmark, through ``campipe.bench.verdict``, which imports them from here).
"""

from __future__ import annotations

import math
from typing import TypeGuard


def format_short(x: float, digits: int = 3) -> str:
    """``x`` to ``digits`` significant digits: plain from 1e-3 to 1e5 (0.0963, 15000), else
    with a short exponent (2.1e-8, 2.68e7); trailing zeros dropped."""
    if x == 0 or not math.isfinite(x):
        return format(x, "g")
    if 1e-3 <= abs(x) < 1e5:
        rounded = float(format(x, f".{digits}g"))
        decimals = max(digits - 1 - math.floor(math.log10(abs(rounded))), 0)
        text = format(rounded, f".{decimals}f")
        return text.rstrip("0").rstrip(".") if "." in text else text
    mantissa, _, exponent = format(x, f".{digits - 1}e").partition("e")
    if "." in mantissa:
        mantissa = mantissa.rstrip("0").rstrip(".")
    return f"{mantissa}e{int(exponent)}"


def finite(x: object) -> TypeGuard[float]:
    """``x`` is a finite number (not None, as bench.json holds NaN, nor a flag)."""
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)
