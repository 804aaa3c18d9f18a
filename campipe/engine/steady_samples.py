"""Configuration I's periodic state sampled at cam angles (the steady fidelity level's
histories): ``steady_samples`` on what ``steady.steady_extremes`` prepared."""

from __future__ import annotations

import numpy as np
from numba import njit

from campipe.engine.closed_form import D1, D2, block_basis, force_monitor
from campipe.engine.common import KERNEL, by_ref
from campipe.engine.steady import (
    _apply_block,
    _begin_case,
    _from_basis,
    _on_piece,
    _particular_at,
    _piece_of,
    _seat_row,
    _state_in_prepared_piece,
)
from campipe.profiles.packed import horner, piece_eval
from campipe.vocabulary import CAM


@njit(inline="always", nogil=True)
def _rate(trains, ws, st, s_row, x, ct, sn):
    """ż[s_row] at the prepared piece's local angle x (cos θ, sin θ given), from
    ws.u = e^{Bτ}u: X·B·e^{Bτ}u (B_b = λ̄I + N_b) plus the particular solution's rate."""
    tr, ci = st.tr, st.cfg - 1
    acc = 0.0
    for b in range(trains.n_blocks[tr, ci]):
        i0 = trains.bstart[tr, ci, b]
        i1 = i0 + trains.bdim[tr, ci, b]
        lbar = trains.lam_bar[tr, ci, b]
        for j in range(i0, i1):
            y = lbar * ws.u[j]
            for k in range(i0, i1):
                y += trains.block_n[tr, ci, j, k] * ws.u[k]
            acc += trains.basis[tr, ci, s_row, j] * y
    dz = horner(ws.Z[:, s_row], x, st.deg)[1]
    return acc + st.w * (dz - ws.ZT[s_row].real * sn - ws.ZT[s_row].imag * ct)


@njit(**KERNEL)
def steady_samples(cases, trains, profiles, runs, ws, state, z_turn, angles, active, q, v, acc,
                   force):  # fmt: skip
    """Configuration I's periodic state at the cam angles ``angles`` (n_out,) in [0, 2π],
    ascending, for the ``active`` cases, whose ``z_turn`` and ``runs.zeta``
    ``steady_extremes`` has filled: q, v (n, n_out, n) [m, rad, m/s, rad/s], the
    accelerations of q1 and q7 (n, n_out, 2) [m/s²] and the cam's compression (n, n_out) [N]."""
    st = state[0]
    ref = by_ref((cases, trains, profiles, runs, ws))
    for c in range(cases.omega.shape[0]):
        if not active[c]:
            continue
        _begin_case(cases, trains, runs, st, c)
        tr, ci, nf, ns = st.tr, st.cfg - 1, st.nf, st.ns
        nb = trains.n_blocks[tr, ci]
        row = _seat_row(trains, st)
        w = st.w
        p = -1
        theta_prev = 0.0
        h_prev = -1.0
        for k in range(angles.shape[0]):
            theta = angles[k]
            pk = _piece_of(profiles, c, theta)
            if pk != p:
                # A new piece: e^{Bτ}u at θ in closed form (left in ws.u).
                p = pk
                _on_piece(ref, st, p)
                for i in range(8):
                    ws.G[0, i] = 0.0
                force_monitor(trains, ws, st, 0, 1.0, 0.0)
                _state_in_prepared_piece(ref, st, z_turn[c, p], theta, ws.z)
            else:
                # Along the piece: e^{Bτ}u advanced block by block by its step factors.
                h = (theta - theta_prev) / w
                # Sample spacings equal but for rounding share their factors.
                if abs(h - h_prev) > 1e-12 * h:
                    for b in range(nb):
                        ws.MC[D1, b], ws.MC[D2, b] = block_basis(
                            trains.lam_bar[tr, ci, b], trains.delta2[tr, ci, b], h
                        )
                    h_prev = h
                _propagate_by(trains, ws, st, ws.u)
                _from_basis(trains, st, ws.u, ws.z)
                _particular_at(ws, st, theta)
                for s in range(ns):
                    ws.z[s] += ws.zb[s]
            theta_prev = theta
            x = theta - st.th0
            ct = np.cos(theta)
            sn = np.sin(theta)
            lift, dlift, ddlift = piece_eval(profiles, c, p, np.int64(0), theta)
            for j in range(nf):
                coord = trains.free[tr, ci, j]
                q[c, k, coord] = ws.z[j]
                v[c, k, coord] = ws.z[nf + j]
            q[c, k, CAM] = -lift
            v[c, k, CAM] = -w * dlift
            acc[c, k, 0] = -w * w * ddlift
            acc[c, k, 1] = _rate(trains, ws, st, nf + row, x, ct, sn)
            # F1 = ρX·e^{Bτ}u plus the piece's forced part (``closed_form.force_monitor``).
            f1 = horner(ws.G[0], x, st.kmax)[0] + ws.GT[0].real * ct - ws.GT[0].imag * sn
            for j in range(ns):
                f1 += trains.rho_x[tr, ci, 0, j] * ws.u[j]
            force[c, k] = -f1


@njit(inline="always", nogil=True)
def _propagate_by(trains, ws, st, u):
    """u ← e^{Bh} u with the blocks' step factors (f1(h), f2(h)) in ws.MC rows D1, D2."""
    for b in range(trains.n_blocks[st.tr, st.cfg - 1]):
        _apply_block(trains, st, u, b, ws.MC[D1, b], ws.MC[D2, b])
