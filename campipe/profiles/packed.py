"""Profiles packed into padded arrays, and the one compiled evaluator every kernel uses.

A batch of cases steps together; each case has its own profile, with its own piece count.
The arrays are padded to the largest piece count P: breaks with +inf (never found by the
search, which only looks at a case's real breaks anyway), coefficients with zeros.

On piece i of case c the lift is Σₖ poly[c, i, k]·xᵏ + trig[c, i, 0]·sin θ + trig[c, i, 1]·cos θ
with x = θ − 2π·rev − breaks[c, i] the angle from the piece's start in turn ``rev``
(``campipe.profiles.pieces``). The kernels walk the pieces turn by turn, so they carry
(rev, piece) and evaluate a known piece (:func:`piece_eval`); :func:`evaluate_packed` finds the
piece first.
"""

from __future__ import annotations

import functools
import weakref
from collections.abc import Sequence
from typing import NamedTuple

import numba
import numpy as np

from campipe.constants import TWO_PI
from campipe.profiles.pieces import N_COEFFS, Profile


class PackedProfiles(NamedTuple):
    """The profiles of a batch of cases as padded, C-contiguous float64 arrays (a named tuple,
    so the compiled kernels take it as one argument)."""

    breaks: np.ndarray  # (n_cases, P+1) piece boundaries [rad], +inf past breaks[c, n_pieces[c]]
    poly: np.ndarray  # (n_cases, P, 8) polynomial coefficients, zero-padded [m/rad**k]
    trig: np.ndarray  # (n_cases, P, 2) sin θ and cos θ coefficients, zero-padded [m]
    n_pieces: np.ndarray  # (n_cases,) int64 number of real pieces of each case
    #: (n_cases, P + 1, 4) a lever layout's ratio r(θ) [-] on each piece, a cubic in x as the
    #: lift's (its roller's normal force on the cam per valve-side force:
    #: ``campipe.profiles.levers.lever_tables``), and in the last row a bound on it over the
    #: turn (:func:`ratio_bound`); zeros for any other case (one array, not two: each array
    #: of a kernel's arguments costs every call its unboxing)
    ratio: np.ndarray


class Keyed:
    """A profile keyed by its numbers (breaks, coefficients): equal and of one hash for two
    profiles of the same numbers, so a cache keyed by it serves a profile rebuilt per case
    (a study's), and holds no bare ``id``. A profile's arrays are read-only, so its key stays
    its numbers'."""

    __slots__ = ("_hash", "key", "profile")

    def __init__(self, profile: Profile) -> None:
        self.profile = profile
        self.key = profile.content_key
        self._hash = hash(self.key)

    def __hash__(self) -> int:
        return self._hash

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Keyed) and self.key == other.key


_KEYED: weakref.WeakKeyDictionary[Profile, Keyed] = weakref.WeakKeyDictionary()


def keyed(profile: Profile) -> Keyed:
    """The profile's :class:`Keyed`, made once per profile object."""
    found = _KEYED.get(profile)
    if found is None:
        found = _KEYED[profile] = Keyed(profile)
    return found


#: The most profiles (cases) whose packing :func:`pack_cached` caches: the batches whose
#: preparation weighs on a call; a larger batch is packed per call, so that the cache holds
#: at most 256 packings of a few cases.
CACHED_PROFILES = 16


def pack_cached(profiles: Sequence[Profile]) -> PackedProfiles:
    """:func:`pack`, cached by the profiles' numbers (the last 256 batches of up to
    ``CACHED_PROFILES`` cases). A larger batch of at most ``CACHED_PROFILES`` distinct
    profiles (a sweep of speeds or seats on a few cams) takes its rows from the distinct
    ones' packing (cached), a gather of three arrays instead of a loop over its cases; any
    other is packed per call. The kernels only read the packed arrays: callers must not
    write into the cached ones."""
    if len(profiles) == 0:
        raise ValueError("pack needs at least one profile")
    keys = tuple(keyed(p) for p in profiles)
    if len(keys) <= CACHED_PROFILES:
        return _pack_keyed(keys)
    distinct = dict.fromkeys(keys)
    if len(distinct) > CACHED_PROFILES:
        return pack(profiles)
    packed = _pack_keyed(tuple(distinct))
    row = {k: i for i, k in enumerate(distinct)}
    rows = np.array([row[k] for k in keys])
    return PackedProfiles(*(a[rows] for a in packed))


@functools.lru_cache(maxsize=256)
def _pack_keyed(profiles: tuple[Keyed, ...]) -> PackedProfiles:
    return pack([k.profile for k in profiles])


def pack(profiles: Sequence[Profile]) -> PackedProfiles:
    """Pack a list of profiles, one per case, for the compiled evaluators below."""
    if len(profiles) == 0:
        raise ValueError("pack needs at least one profile")
    n_pieces = np.array([p.n_pieces for p in profiles], dtype=np.int64)
    n_cases, width = len(profiles), int(n_pieces.max())
    breaks = np.full((n_cases, width + 1), np.inf)
    poly = np.zeros((n_cases, width, N_COEFFS))
    trig = np.zeros((n_cases, width, 2))
    ratio = np.zeros((n_cases, width + 1, RATIO_COEFFS))
    for c, p in enumerate(profiles):
        n = p.n_pieces
        breaks[c, : n + 1] = p.breaks
        poly[c, :n] = p.poly
        trig[c, :n] = p.trig
        ratio[c, width, 0] = _ratio(p, ratio[c, :n])
    return PackedProfiles(breaks, poly, trig, n_pieces, ratio)


#: The coefficients of a lever's ratio on a piece (a cubic spline's).
RATIO_COEFFS = 4


def _ratio(profile: Profile, out: np.ndarray) -> float:
    """A lever layout's ratio on each of ``profile``'s pieces into ``out`` (its pieces are the
    lift's, ``campipe.profiles.levers.lever_tables``), and a bound on it over the turn (its
    largest at five points of each piece, and 1e-6 of it more); 0 for a profile that is no
    lever's."""
    tables = getattr(profile, "tables", None)
    if tables is None:
        return 0.0
    table = tables[0]
    if not np.array_equal(table.breaks, profile.breaks) or np.any(table.poly[:, RATIO_COEFFS:]):
        raise ValueError("a lever's ratio table must be a cubic on the lift's own pieces")
    out[:] = table.poly[:, :RATIO_COEFFS]
    x = np.diff(profile.breaks)[None, :] * np.linspace(0.0, 1.0, 5)[:, None]  # (5, pieces)
    values = np.polynomial.polynomial.polyval(x, out.T, tensor=False)
    return float(values.max()) * (1.0 + 1e-6)


@numba.njit(cache=True, nogil=True, inline="always")
def horner(coef, x, deg=N_COEFFS - 1):
    """Σ_{k ≤ deg} coef[k]·x^k and its first two derivatives in x, by Horner's scheme.

    The one polynomial evaluator of the kernels (profile pieces, particular solutions,
    monitors). Inlined, so a caller's view ``poly[c, p]`` costs no reference counting per call,
    and compiled with the caller's floating-point flags.
    """
    p0 = 0.0
    p1 = 0.0
    p2 = 0.0
    for k in range(deg, -1, -1):
        p2 = p2 * x + 2.0 * p1
        p1 = p1 * x + p0
        p0 = p0 * x + coef[k]
    return p0, p1, p2


@numba.njit(cache=True, nogil=True, inline="always")
def ratio_bound(profiles, c):
    """A bound on case c's lever ratio over the turn [-]; 0 for a case that is no lever's."""
    return profiles.ratio[c, profiles.ratio.shape[1] - 1, 0]


@numba.njit(cache=True, nogil=True)
def locate(profiles, c, theta):
    """(turn, piece) holding cam angle ``theta`` [rad] for case ``c``."""
    rev = np.floor(theta / TWO_PI)
    phi = theta - rev * TWO_PI
    lo = 0
    hi = profiles.n_pieces[c] - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if profiles.breaks[c, mid] <= phi:
            lo = mid
        else:
            hi = mid - 1
    return int(rev), lo


@numba.njit(cache=True, nogil=True)
def piece_eval(profiles, c, piece, rev, theta):
    """Lift [m] and its first two θ-derivatives [m/rad, m/rad²] of case c at cam angle
    ``theta`` [rad], on ``piece`` of turn ``rev`` (evaluated as is, also outside the piece:
    one-sided limits at a break)."""
    x = theta - rev * TWO_PI - profiles.breaks[c, piece]
    p0, p1, p2 = horner(profiles.poly[c, piece], x)
    s = np.sin(theta)
    co = np.cos(theta)
    a = profiles.trig[c, piece, 0]
    b = profiles.trig[c, piece, 1]
    return p0 + a * s + b * co, p1 + a * co - b * s, p2 - a * s - b * co


@numba.njit(cache=True, nogil=True)
def evaluate_packed(profiles, c, theta):
    """Lift [m], dlift/dθ [m/rad] and d²lift/dθ² [m/rad²] of case c at any cam angle
    ``theta`` [rad] (at a break, the piece to the right); the compiled twin of
    :func:`campipe.profiles.evaluate`."""
    rev, piece = locate(profiles, c, theta)
    return piece_eval(profiles, c, piece, rev, theta)


@numba.njit(cache=True, nogil=True)
def degree(profiles, c, piece):
    """Highest power with a nonzero coefficient on a piece (Horner need go no higher)."""
    for k in range(N_COEFFS - 1, 0, -1):
        if profiles.poly[c, piece, k] != 0.0:
            return k
    return 0


@numba.njit(cache=True, nogil=True, inline="always")
def next_break(profiles, c, piece, rev):
    """The piece after ``piece`` of turn ``rev``, its turn, and the cam angle [rad] where it
    starts (inlined: computed with the caller's floating-point flags)."""
    pn = piece + 1
    revn = rev
    if pn == profiles.n_pieces[c]:
        pn = 0
        revn = rev + 1
    return pn, revn, revn * TWO_PI + profiles.breaks[c, pn]
