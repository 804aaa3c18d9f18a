"""A proven bound on how fast configuration I's steady state can change with the cam speed:
what lets the onset search certify an interval of speeds free of no-follow
(``onset.onset_speeds``).

Below the onset the train follows the cam: its foot q1 = −y(θ) is prescribed by the lift y
and the rest is linear, time-invariant and driven with the cam's period. At speed ω the
periodic state is a Fourier series whose k-th harmonic goes through the train's transfer at
the frequency kω:

    F(θ, ω) = F₀ + Σ_{k≠0} G(ikω) U_k e^{ikθ},   U_k = −Y_k, Y_k = (1/2π)∫ y e^{−ikθ} dθ,

for the cam force F (the reaction on q1) and likewise for the valve coordinate q7 with its
own transfer. ``transfer`` writes G in pole–residue form from the train's M, C and K with q1
held (the free coordinates' poles λ_j and residues ρ_j, and the polynomial part of a force
that includes the foot's own inertia):

    G(s) = m s² + c s + g₀ + Σ_j ρ_j / (s − λ_j).

So ∂F/∂ω = 2mω u″(θ) + c u′(θ) − Σ_k Σ_j ik ρ_j U_k e^{ikθ} / (ikω − λ_j)², and for every θ
and every ω in [a, b]

    |∂F/∂ω| ≤ 2|m| b max|y″| + |c| max|y′| + 2 Σ_{k≥1} Σ_j k |Y_k| |ρ_j| / d_kj²,

d_kj² = (Re λ_j)² + dist(Im λ_j, [ka, kb])², the least of |ikω − λ_j|² over the interval
(harmonics −k give the same sum). The first K harmonics are summed exactly (``spectrum``:
each piece's integral in closed form, no sampling); beyond K, k|Y_k| is bounded by the
largest of the computed ones past K and, past those, by T_m/k^m (T_m the total variation of
the lift's m-th derivative over 2π, m ≤ 3), and Σ_k 1/d_kj² is bounded by its largest terms
and an integral (``_tail``). (For the summed harmonics the code bounds each one's
|Σ_j ρ_j/(ikω − λ_j)²| over [a, b] more tightly than Σ_j |ρ_j|/d_kj²: the larger of its
ends plus half the width times a bound of its derivative.) The least of F over the turn (the
margin) then changes by at most the bound times the width: a margin positive at a and b with
v_a + v_b ≥ L·(b − a) stays positive across [a, b]. The same holds for the valve's height
above its seat.

The bound is for configuration I's closed form, the margin the search reads, on profiles
whose lift is continuous (``provable``). A velocity step (a constant-velocity ramp's ends, a
flat's edges) makes u″ an impulse there: the series carries it (|Y_k| ≤ T₁/k², T₁ the
variation of y′ with its steps, is all the tail takes), the bound's polynomial part is the
pieces' one-sided y″ (the impulse's instant left out: the force on either side of it is
bounded at every speed, the impulse itself a push, not the least force), and the closed form
carries it as the run does where the follower is struck there (above ``held_from``: a
plastic impact; a step the follower leaves at, a release, is not configuration I). It does
not cover a seated steady state (impacts at the seat and the cam), whose no-follow is not
Lipschitz in the speed. It bounds the change between speeds of the least force over the
turn; at each speed that least is the closed form's own, found by
``steady.steady_extremes`` (sampled at ``steady.EXTREME_SAMPLES`` a turn, the least sample
refined by Newton's method).

Pure numerics: arrays in, arrays out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from campipe.constants import TWO_PI
from campipe.engine.common import jump_speed
from campipe.model.assembly import SystemMatrices
from campipe.profiles.pieces import N_COEFFS, Profile
from campipe.vocabulary import CAM, SEAT

#: Harmonics summed exactly; a profile's spectrum is kept to MAX_HARMONICS and a bound uses
#: the fewest of HARMONIC_STEPS whose tail is at most TAIL_SHARE of its sum.
HARMONIC_STEPS = (16, 64, 256, 2048, 16384)
MAX_HARMONICS = HARMONIC_STEPS[-1]
TAIL_SHARE = 0.1
#: The derivatives whose total variations bound the spectrum's tail (``Spectrum``).
TAIL_ORDERS = 3
#: The integrals' rounding: |Y_k| is exact to this share of the largest lift (measured:
#: 2e-17 against an FFT).
ROUNDING = 1e-15
#: Samples per piece for the profile's derivative bounds (each corrected by the next
#: derivative's bound times half a spacing, so the bounds are proven).
PIECE_SAMPLES = 512
#: A step in lift [m] or in a derivative [m/rad^m] larger than this share of the largest lift
#: (at least 1 mm) is a step (``provable``, ``_variations``); smaller ones are rounding.
STEP = 1e-9


@dataclass(frozen=True)
class Transfer:
    """Configuration I's transfers from the foot's displacement u = q1 to the cam reaction
    and to the valve coordinate q7, pole–residue form (module docstring)."""

    mass: float  # m: the s² coefficient of the force's transfer [kg]
    damping: float  # c: its s coefficient [N·s/m]
    poles: np.ndarray  # (p,) λ_j [1/s], complex
    force: np.ndarray  # (p,) ρ_j [N/(m·s)], complex
    valve: np.ndarray  # (p,) the valve coordinate's residues [1/s], complex
    static: float  # the force's constant part [N/m]


def transfer(sm: SystemMatrices) -> Transfer:
    """The pole–residue form of configuration I's transfers of a train (``Transfer``).

    With x the free coordinates and u = q1, D(s) = K + sC + s²M: x = −D_ff⁻¹ D_fc u and the
    reaction R = D_cc u + D_cf x. Through the companion matrix A of the free coordinates,
    D_ff(s)⁻¹ = Σ_j E_j/(s − λ_j) with Σ E_j = 0 and Σ λ_j E_j = M_ff⁻¹, which splits both
    transfers into their polynomial parts and simple poles."""
    M, C, K = sm.mass, sm.damping, sm.stiffness
    n = M.shape[0]
    f = np.array([i for i in range(n) if i != CAM])
    Mff, Cff, Kff = (X[np.ix_(f, f)] for X in (M, C, K))
    Mfc, Cfc, Kfc = (X[f, CAM] for X in (M, C, K))
    Mcf, Ccf, Kcf = (X[CAM, f] for X in (M, C, K))
    nf = f.size
    Minv = np.linalg.inv(Mff)
    A = np.block([[np.zeros((nf, nf)), np.eye(nf)], [-Minv @ Kff, -Minv @ Cff]])
    lam, V = np.linalg.eig(A)
    W = np.linalg.inv(V)
    left = V[:nf, :]  # E_j = left[:, j] ⊗ right[j]
    right = W[:, nf:] @ Minv
    N = lam[:, None] ** 2 * Mfc + lam[:, None] * Cfc + Kfc  # (p, nf): D_fc(λ_j)
    h = -left * np.einsum("jk,jk->j", right, N)[None, :]  # (nf, p): x's residues
    x0 = -Minv @ Mfc  # x's constant part
    g_v = Ccf - Mcf @ Minv @ Cff
    g_x = Kcf - Mcf @ Minv @ Kff
    rho = np.einsum("jk,kj->j", lam[:, None] * g_v + g_x, h)
    mass = M[CAM, CAM] - Mcf @ Minv @ Mfc
    damping = C[CAM, CAM] - Mcf @ Minv @ Cfc + g_v @ x0
    static = K[CAM, CAM] - Mcf @ Minv @ Kfc + g_x @ x0 + np.sum(g_v @ h)
    valve = h[list(f).index(SEAT)]
    return Transfer(float(mass), float(damping), lam, rho, valve, float(static.real))


def checked(tr: Transfer, sm: SystemMatrices, tolerance: float = 1e-6) -> bool:
    """The pole–residue form agrees with a direct solve of the dynamic stiffness to
    ``tolerance`` (relative) at a decade of frequencies around the poles: False for a train
    whose free coordinates' companion matrix is defective (repeated poles), where the
    residues are not to be trusted. The points lie right of the imaginary axis (s = ω·(0.1 +
    i)), off every pole: an undamped train's are on the axis, where the highest of them,
    ω = its modulus, would be a point."""
    f = [i for i in range(sm.mass.shape[0]) if i != CAM]
    top = float(np.max(np.abs(tr.poles)))
    for omega in top * np.logspace(-4, 1, 6):
        s = omega * (0.1 + 1j)
        D = sm.stiffness + s * sm.damping + s * s * sm.mass
        direct = D[CAM, CAM] - D[CAM, f] @ np.linalg.solve(D[np.ix_(f, f)], D[f, CAM])
        if not abs(force_transfer(tr, s) - direct) <= tolerance * abs(direct):
            return False
    return True


def force_transfer(tr: Transfer, s: np.ndarray) -> np.ndarray:
    """G(s), the reaction on q1 per unit of q1, from the pole–residue form (for checks)."""
    s = np.asarray(s, complex)[..., None]
    poles = np.sum(tr.force / (s - tr.poles), axis=-1)
    return tr.mass * s[..., 0] ** 2 + tr.damping * s[..., 0] + tr.static + poles


@dataclass(frozen=True)
class Spectrum:
    """What the bound needs of a lift profile: |Y_k| for k = 1 … MAX_HARMONICS, the total
    variation of y′ over a turn over 2π (infinite where the lift steps), and the largest
    |y′| and |y″| over the pieces (one-sided at the breaks, impulses left out)."""

    amplitude: np.ndarray  # (MAX_HARMONICS,) |Y_k| [m]
    #: T_m = TV(y^(m))/2π for m = 1 … TAIL_ORDERS [m/rad^m], so |Y_k| ≤ T_m/k^(m+1); +inf
    #: where a lower derivative steps
    variation: tuple[float, ...]
    #: bounds of max |y^(m)| over the pieces, m = 0 … 4 [m/rad^m]
    max_derivative: tuple[float, ...]

    #: (MAX_HARMONICS,) the largest k(|Y_k| + ROUNDING·max|y|) over k > K at index K − 1
    #: (the integrals' rounding allowed for)
    beyond: np.ndarray

    def tail_weight(self, K: int) -> float:
        """A bound on k|Y_k| for every k > K: the computed amplitudes' largest up to
        MAX_HARMONICS, beyond it T_m/k^m, and T_m/K^m over all."""
        total = self.variation
        far = min(t / MAX_HARMONICS**m for m, t in enumerate(total, start=1))
        near = float(self.beyond[K - 1]) if K < MAX_HARMONICS else 0.0
        return min(min(t / K**m for m, t in enumerate(total, start=1)), max(near, far))


def _derivative_coefficients(poly: np.ndarray, order: int) -> np.ndarray:
    """The coefficients of the order-th derivative of each row's polynomial (same width)."""
    out = poly.copy()
    for _ in range(order):
        out = np.concatenate([out[:, 1:] * np.arange(1, N_COEFFS), np.zeros((len(out), 1))], 1)
    return out


def _polynomial_sup(poly: np.ndarray, width: np.ndarray) -> np.ndarray:
    """(n,) a bound on |p(u)| for 0 ≤ u ≤ width, each row's polynomial: Σ |c_m| width^m."""
    powers = width[:, None] ** np.arange(N_COEFFS)
    return np.sum(np.abs(poly) * powers, axis=1)


def _derivative(profile: Profile, order: int, piece: np.ndarray, theta: np.ndarray):
    """The order-th derivative of the lift on ``piece`` at ``theta`` (any order)."""
    d = _derivative_coefficients(profile.poly, order)[piece]
    x = theta - profile.breaks[piece]
    value = np.zeros_like(x)
    for m in range(N_COEFFS - 1, -1, -1):
        value = value * x + d[..., m]
    a, b = profile.trig[piece, 0], profile.trig[piece, 1]
    phase = theta + 0.5 * math.pi * order  # (sin, cos)^(order) = sin, cos shifted
    return value + a * np.sin(phase) + b * np.cos(phase)


def _derivative_max(profile: Profile, order: int) -> np.ndarray:
    """(n,) a proven bound of |y^(order)| on each piece: the largest of PIECE_SAMPLES samples
    plus half a spacing times a bound of the next derivative."""
    width = np.diff(profile.breaks)
    u = np.linspace(0.0, 1.0, PIECE_SAMPLES)
    theta = profile.breaks[:-1, None] + width[:, None] * u
    piece = np.broadcast_to(np.arange(profile.n_pieces)[:, None], theta.shape)
    values = _derivative(profile, order, piece, theta)
    trig = np.hypot(profile.trig[:, 0], profile.trig[:, 1])
    nxt = _polynomial_sup(_derivative_coefficients(profile.poly, order + 1), width) + trig
    return np.max(np.abs(values), axis=1) + 0.5 * width / (PIECE_SAMPLES - 1) * nxt


def _one_sided(profile: Profile, order: int) -> tuple[np.ndarray, np.ndarray]:
    """(n,) y^(order) either side of each break (break k ends piece k): left, right."""
    n = profile.n_pieces
    left = _derivative(profile, order, np.arange(n), profile.breaks[1:])
    right = _derivative(profile, order, np.arange(1, n + 1) % n, profile.breaks[1:] % TWO_PI)
    return left, right


def _steps(profile: Profile, order: int) -> np.ndarray:
    """(n,) |the step of y^(order)| at each break (break k ends piece k)."""
    left, right = _one_sided(profile, order)
    return np.abs(left - right)


def _scale(profile: Profile) -> float:
    """The lift's scale [m]: its largest at the breaks, at least 1 mm (steps below STEP of it
    are rounding)."""
    lifts = _derivative(profile, 0, np.arange(profile.n_pieces), profile.breaks[:-1])
    return max(float(np.max(np.abs(lifts))), 1e-3)


def _variations(profile: Profile) -> tuple[float, ...]:
    """T_m = TV(y^(m))/2π, m = 1 … TAIL_ORDERS: the pieces' ∫|y^(m+1)| (bounded) and the
    steps of y^(m); +inf from the first m whose y^(m−1) steps."""
    width = np.diff(profile.breaks)
    scale = _scale(profile)
    out: list[float] = []
    for m in range(1, TAIL_ORDERS + 1):
        if out and math.isinf(out[-1]) or np.any(_steps(profile, m - 1) > STEP * scale):
            out.append(math.inf)
            continue
        inside = float(np.sum(_derivative_max(profile, m + 1) * width))
        out.append((inside + float(np.sum(_steps(profile, m)))) / TWO_PI)
    return tuple(out)


def _piece_integrals(profile: Profile, k: np.ndarray) -> np.ndarray:
    """(K,) Σ over pieces of ∫ y e^{−ikθ} dθ, exact: the polynomial by parts (its
    derivatives at both ends), the trig terms as exponentials."""
    width = np.diff(profile.breaks)
    start = profile.breaks[:-1]
    ik = 1j * k[:, None]  # (K, 1)
    total = np.zeros(k.size, complex)
    for m in range(N_COEFFS):
        d = _derivative_coefficients(profile.poly, m)
        at0 = d[:, 0]
        at1 = np.polynomial.polynomial.polyval(width, d.T, tensor=False)
        term = (at0[None, :] - np.exp(-ik * width[None, :]) * at1[None, :]) / ik ** (m + 1)
        total += np.sum(np.exp(-ik * start[None, :]) * term, axis=1)
    a, b = profile.trig[:, 0], profile.trig[:, 1]
    end = profile.breaks[1:]
    for sign, coef in ((1, 0.5 * (b - 1j * a)), (-1, 0.5 * (b + 1j * a))):
        r = sign - k[:, None]  # exponent of e^{i r θ}
        safe = np.where(r == 0, 1.0, r)
        integral = np.where(
            r == 0, width[None, :],
            (np.exp(1j * r * end[None, :]) - np.exp(1j * r * start[None, :])) / (1j * safe),
        )  # fmt: skip
        total += np.sum(coef[None, :] * integral, axis=1)
    return total


def spectrum(profile: Profile) -> Spectrum:
    """The lift's spectrum and derivative bounds (``Spectrum``), exact to rounding."""
    k = np.arange(1, MAX_HARMONICS + 1, dtype=float)
    amplitude = np.abs(_piece_integrals(profile, k)) / TWO_PI
    maxima = tuple(float(_derivative_max(profile, m).max()) for m in range(5))
    weighted = k * (amplitude + ROUNDING * maxima[0])
    beyond = np.append(np.maximum.accumulate(weighted[::-1])[::-1][1:], 0.0)
    return Spectrum(amplitude, _variations(profile), maxima, beyond)


def _tail(poles: np.ndarray, a: np.ndarray, b: np.ndarray, K: int) -> np.ndarray:
    """(r, p) a bound on Σ_{k>K} 1/d_kj² (module docstring) for each row's poles (r, p) over
    [a, b] (r,). Where every such harmonic lies above the pole (Ka ≥ |Im λ|) the terms fall
    with k: the integral from K. Else below the harmonics that can meet Im λ in [ka, kb] the
    terms rise, above it they fall, each side bounded by its term nearest the pole and an
    integral, and those that meet it are 1/(Re λ)² each. Finite for an undamped pole
    (Re λ = 0) that no harmonic meets over [a, b]."""
    a = a[:, None]
    b = b[:, None]
    re = np.abs(poles.real)
    im = np.abs(poles.imag)
    damped = re > 0.0  # Re λ = 0: a train without damping
    safe = np.where(damped, re, 1.0)

    def integral(d: np.ndarray, w: np.ndarray) -> np.ndarray:
        # ∫ du / (w·((Re λ)² + u²)) over u ≥ d = (π/2 − arctan(d/Re λ)) / (w·Re λ), as arctan2
        # so that it tends to its undamped limit 1/(w·d) (inf at d = 0).
        undamped = np.where(d > 0.0, 1.0 / (w * np.where(d > 0.0, d, 1.0)), np.inf)
        return np.where(damped, np.arctan2(re, d) / (w * safe), undamped)

    # Every harmonic above the pole: the terms fall with k, the integral from K.
    above = integral(K * a - im, a)
    # Else the nearest harmonic each side of those that may meet the pole (k·b < Im λ below,
    # k·a > Im λ above): its term and its side's integral; 1/(Re λ)² for each that may meet
    # it (inf undamped: the interval is halved).
    below_k = np.ceil(im / b) - 1.0
    has_below = below_k >= K + 1
    d_below = np.where(has_below, im - below_k * b, 1.0)
    above_k = np.maximum(K + 1.0, np.floor(im / a) + 1.0)
    d_above = above_k * a - im
    meeting = np.maximum(np.floor(im / a) - np.maximum(K + 1.0, np.ceil(im / b)) + 1.0, 0.0)
    anywhere = (
        np.where(has_below, 1.0 / (re**2 + d_below**2) + integral(d_below, b), 0.0)
        + 1.0 / (re**2 + d_above**2)
        + integral(d_above, a)
        + np.where(meeting > 0.0, np.where(damped, meeting / safe**2, np.inf), 0.0)
    )
    return np.where(K * a >= im, above, anywhere)


def _harmonic_sums(
    amplitude: np.ndarray, poles: np.ndarray, residues: np.ndarray, a: np.ndarray, b: np.ndarray
) -> np.ndarray:
    """(r, 2) 2 Σ_{k≤K} k|Y_k| max_ω |Σ_j r_j/(ikω − λ_j)²| for each row's force residues
    and valve residues (residues: (r, 2, p)), K = amplitude.size. Each harmonic's sup over
    [a, b] is the larger of its ends' plus half the width times a bound of its derivative,
    Σ_j 2k|r_j|/d_kj³."""
    k = np.arange(1, amplitude.size + 1, dtype=float)[None, :, None]  # (1, K, 1)
    lam = poles[:, None, :]  # (r, 1, p)
    a3 = a[:, None, None]
    b3 = b[:, None, None]
    im = np.abs(lam.imag)
    dist = np.maximum(0.0, np.maximum(k * a3 - im, im - k * b3))
    d2 = lam.real**2 + dist**2  # (r, K, p)
    inv_a = 1.0 / (1j * k * a3 - lam) ** 2
    inv_b = 1.0 / (1j * k * b3 - lam) ** 2
    slope = (b3 - a3) * k / (d2 * np.sqrt(d2))
    rt = np.swapaxes(residues, 1, 2)  # (r, p, 2)
    ends = np.maximum(np.abs(inv_a @ rt), np.abs(inv_b @ rt))  # (r, K, 2)
    total = ends + slope @ np.abs(rt)
    weight = 2.0 * k[0, :, 0] * amplitude  # (K,)
    return np.einsum("k,rkc->rc", weight, total)


@dataclass(frozen=True)
class Transfers:
    """Several trains' ``Transfer`` stacked by row (``stack``)."""

    mass: np.ndarray  # (r,)
    damping: np.ndarray  # (r,)
    poles: np.ndarray  # (r, p)
    residues: np.ndarray  # (r, 2, p): the force's, the valve's


def stack(transfers: list[Transfer]) -> Transfers:
    """Transfers with as many poles each (trains with as many coordinates) by row."""
    return Transfers(
        np.array([t.mass for t in transfers]),
        np.array([t.damping for t in transfers]),
        np.array([t.poles for t in transfers]),
        np.array([[t.force, t.valve] for t in transfers]),
    )


def slope_bounds_many(
    trs: Transfers, sp: Spectrum, a: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``slope_bounds`` for each row of ``trs`` over its own [a, b], one profile."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    if not np.all((0.0 < a) & (a <= b)):
        raise ValueError("every interval must satisfy 0 < a ≤ b")
    y = sp.max_derivative
    direct = np.zeros((a.size, 2))
    direct[:, 0] = 2.0 * np.abs(trs.mass) * b * y[2] + np.abs(trs.damping) * y[1]
    best = np.full((a.size, 2), np.inf)
    todo = np.arange(a.size)
    weights = np.abs(trs.residues)  # (r, 2, p)
    for K in HARMONIC_STEPS:
        # An undamped pole that a harmonic meets over [a, b] has no finite bound: inf (and
        # inf − inf, NaN, taken as inf), so the search halves the interval.
        with np.errstate(divide="ignore", invalid="ignore"):
            heads = _harmonic_sums(sp.amplitude[:K], trs.poles[todo], trs.residues[todo],
                                   a[todo], b[todo])  # fmt: skip
            tails = _tail(trs.poles[todo], a[todo], b[todo], K) * (2.0 * sp.tail_weight(K))
            total = direct[todo] + heads + np.einsum("rp,rcp->rc", tails, weights[todo])
            heads = np.where(np.isnan(heads), np.inf, heads)
            total = np.where(np.isnan(total), np.inf, total)
            # Done where the tail is a small share, or more harmonics gained little.
            done = np.all((total - direct[todo] - heads <= TAIL_SHARE * total)
                          | (total >= (1.0 - TAIL_SHARE) * best[todo]), axis=1)  # fmt: skip
        best[todo] = np.minimum(best[todo], total)
        todo = todo[~done]
        if not todo.size:
            break
    return best[:, 0], best[:, 1]


def slope_bounds(tr: Transfer, sp: Spectrum, a: float, b: float) -> tuple[float, float]:
    """Bounds on |∂F/∂ω| [N·s/rad] of the cam force and |∂q7/∂ω| [m·s/rad] of the valve,
    over every angle of the turn and every speed in [a, b] [rad/s], 0 < a ≤ b, for a train
    following the profile whose spectrum is ``sp`` (module docstring): the harmonics to the
    fewest of HARMONIC_STEPS whose tail is at most TAIL_SHARE of the bound, or past which
    more harmonics lower it by less than that share, plus that tail."""
    force, valve = slope_bounds_many(stack([tr]), sp, np.array([a]), np.array([b]))
    return float(force[0]), float(valve[0])


def provable(profile: Profile) -> bool:
    """The bound holds for the profile's closed form: its lift is continuous (no step beyond
    rounding). A velocity step (a constant-velocity ramp's ends, a flat's edges) leaves the
    spectrum's tail T₁ (|Y_k| ≤ T₁/k²) and the pieces' one-sided y″, which is all the bound
    takes; the step's impulse is the series' too, and the closed form carries it where the
    follower is struck there (``held_from``)."""
    return math.isfinite(_variations(profile)[0])


def held_from(profile: Profile, capture: float) -> float:
    """The speed [rad/s] above which every velocity step of ``profile`` beyond rounding (at
    least STEP of the lift's scale) is an impact of the held follower or a release
    (``common.jump_speed``: faster than the capture velocity ``capture`` [m/s]), not crossed
    smoothly; 0 without such steps. Below it the closed form crosses a step without its
    impulse, so it is not the Fourier series the bound is of; above it an impact is the
    series' impulse (plastic) and a release leaves configuration I (``periodic``)."""
    left, right = _one_sided(profile, 1)
    real = np.abs(right - left) > STEP * _scale(profile)
    speeds = [
        jump_speed(float(a), float(b), capture)
        for a, b in zip(left[real], right[real], strict=True)
    ]
    return max(speeds, default=0.0)
