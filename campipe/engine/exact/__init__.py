"""``modal-exact``: closed-form propagation between events, events located inside the step.

Between events the solution is exact (``campipe.engine.modal``): the state at any time is
V·(y₀ ∘ e^{λτ}) plus the exact particular solution of the piece's polynomial and harmonic
forcing. The integrator walks a grid (steps sized by the modes that can still matter, so that
the output angles fall on it), watches each configuration's monitors (thesis Table I) at the
grid points, and on a sign change locates the event by a bracketed root search (Newton with
Illinois) on the closed form, to ``tolerance`` in time. A segment ends at an event or at a
break of the cam profile; the next starts from the exact state there.

Monitors, each an event when it rises through its level (direction: upward only):

- cam held (I, III), force closure: F1 (the cam would pull) → release the cam;
- cam free (II, IV): q1 + lift(θ) (the follower reaches the cam surface) → cam impact;
- seat free (I, II), with a seat: q7_seat − q7 (the valve reaches the seat) → seat impact;
- seat held (III, IV): −F7 (the seat would pull) → release the seat.

Impacts are the thesis's: infinite cam (seat) mass, perfectly plastic; the struck coordinate
takes the obstacle's velocity and, through the consistent mass, the free coordinates change
velocity by −M_ff⁻¹ M_fp Δv_p: the impulse m_eff·v_closing is applied at the instant of
contact, so no force measures 1/Δt. With a coefficient of restitution e (``cam_restitution``,
``seat_restitution``) the impulse is (1 + e) times that and the contact is left open, the
struck coordinate leaving at e·v_closing, until a series of bounces is captured
(``_impact``).

There is no step-size limit to trip: a step is at most ``RESOLUTION``·π/|λ| of the fastest
mode that could bring a monitor to its level, so a monitor's maximum inside a step shows as a
sign change of its derivative; ``run.dt`` only caps the step.

Notation (``campipe.engine.modal`` for the equations)
-----------------------------------------------------
==============  ===========================================================================
z = [x; ẋ]      state of the free coordinates (2·n_f entries, ``ns``); ż = A z + forcing
X, B_b          A = X·blockdiag(B_b)·X⁻¹: block b (1×1 or 2×2) and its basis X_b
λ̄, δ², N_b      tr B_b / 2, (tr B_b / 2)² − det B_b, B_b − λ̄I
f1, f2          the block's basis functions e^{λ̄τ}C(τ), e^{λ̄τ}S(τ): e^{B_b τ} = f1 I + f2 N_b
t_s, τ          the segment's start [s]; τ = t − t_s
θ, x            cam angle ωt [rad]; x = θ − θ0, the angle from the piece's start θ0
z_p             particular solution Σ_k Z_k x^k + Re(Z_T e^{iθ}) (``Z``, ``ZT``)
u               X⁻¹ (z(t_s) − z_p(t_s)), the homogeneous part in the blocks' basis
z(t)            Σ_b (f1 X_b u_b + f2 X_b N_b u_b) + z_p(t)
g_m             monitor m (0: cam, 1: seat) = Σ_b (W1_mb f1 + W2_mb f2) + Σ_k G_mk x^k
                + Re(GT_m e^{iθ}); an event where g_m rises through ``level[m]``
h, D1, D2       grid step [s] and the blocks' f1(h), f2(h), which advance f1, f2 a step
column          one block each, fastest first
==============  ===========================================================================

The per-block work arrays: ``MC`` rows F1 … RATE (f1, f2, their step factors, the envelope,
the block's shares of coordinates and forces, its constants), ``WC`` rows W1 … WL2_ABS (the
coefficients of f1, f2 in a monitor and its derivatives, and their magnitudes),
``VY[:, jj, s]`` the state's coefficients of f1, f2.

The kernel's steps, each a function below: begin a segment (``_begin_segment``: forcing,
particular solution, modal start, monitors, mode pairs), walk the grid (``_walk``: plan the
steps, advance, watch the monitors), locate an event (``_earliest_crossing``, ``_root``), apply
it (``_apply_event``), cross a profile break (``_cross_break``); the held forces' peaks between
the grid's points are ``peaks``' (``_force_peaks``, and ``_near_peak`` for the step's plan).
"""

from campipe.engine.exact.kernel import ahead_signatures, modal_exact_batch

__all__ = ["ahead_signatures", "modal_exact_batch"]
