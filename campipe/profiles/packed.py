"""Profiles packed into padded arrays, and their evaluation inside compiled (numba) kernels.

A batch of cases steps together; each case has its own profile, with its own piece count.
The arrays are padded to the largest piece count P: breaks with +inf (never found by the
search, which only looks at a case's real breaks anyway), coefficients with zeros.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np

from campipe.profiles.pieces import N_COEFFS, TWO_PI, Profile


# eq=False: the fields are arrays, so the generated __eq__ would raise on comparison.
@dataclass(frozen=True, eq=False)
class PackedProfiles:
    """The profiles of a batch of cases as padded, C-contiguous float64 arrays."""

    breaks: np.ndarray  # (n_cases, P+1) piece boundaries [rad], +inf past breaks[c, n_pieces[c]]
    poly: np.ndarray  # (n_cases, P, 8) polynomial coefficients, zero-padded [m/rad**k]
    trig: np.ndarray  # (n_cases, P, 2) sin θ and cos θ coefficients, zero-padded [m]
    n_pieces: np.ndarray  # (n_cases,) int64 number of real pieces of each case


def pack(profiles: Sequence[Profile]) -> PackedProfiles:
    """Pack a list of profiles, one per case, for :func:`evaluate_packed`."""
    if len(profiles) == 0:
        raise ValueError("pack needs at least one profile")
    n_pieces = np.array([p.n_pieces for p in profiles], dtype=np.int64)
    n_cases, width = len(profiles), int(n_pieces.max())
    breaks = np.full((n_cases, width + 1), np.inf)
    poly = np.zeros((n_cases, width, N_COEFFS))
    trig = np.zeros((n_cases, width, 2))
    for c, p in enumerate(profiles):
        n = p.n_pieces
        breaks[c, : n + 1] = p.breaks
        poly[c, :n] = p.poly
        trig[c, :n] = p.trig
    return PackedProfiles(breaks, poly, trig, n_pieces)


@numba.njit(cache=True, nogil=True)
def evaluate_packed(
    breaks: np.ndarray,
    poly: np.ndarray,
    trig: np.ndarray,
    n_pieces: np.ndarray,
    case: int,
    theta: float,
) -> tuple[float, float, float]:
    """Lift [m], dlift/dθ [m/rad] and d²lift/dθ² [m/rad²] of one case at one angle.

    Same result as :func:`campipe.profiles.evaluate` (at a break, the piece to the right),
    without allocating: θ [rad] wraps modulo 2π, the piece is found by binary search on the
    case's real breaks, the polynomial is evaluated by Horner's scheme.
    """
    t = theta % TWO_PI
    if t >= TWO_PI:  # a tiny negative θ rounds up to 2π, which is 0 on the next turn
        t = 0.0
    lo = 0
    hi = n_pieces[case]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if breaks[case, mid] <= t:
            lo = mid
        else:
            hi = mid
    x = t - breaks[case, lo]
    p = poly[case, lo, N_COEFFS - 1]
    dp = 0.0
    ddp = 0.0
    for k in range(N_COEFFS - 2, -1, -1):
        ddp = ddp * x + 2.0 * dp
        dp = dp * x + p
        p = p * x + poly[case, lo, k]
    a = trig[case, lo, 0]
    b = trig[case, lo, 1]
    s = math.sin(t)
    co = math.cos(t)
    return p + a * s + b * co, dp + a * co - b * s, ddp - a * s - b * co
