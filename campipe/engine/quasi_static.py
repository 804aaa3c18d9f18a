"""The thesis's quasi-static start (Appendix B, step 1): every case of a batch at θ = 0 in
static equilibrium with the cam's lift, velocity and acceleration held (configuration I), on
its seat where the valve would stand below it (III), or off the cam where III's cam would have
to pull (IV). ``run_batch``'s ``start: quasi-static`` (``batch._starts``).

Pure numerics: arrays in, arrays out.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from campipe.engine.contact import held_inverses, held_mask, quasi_static_batch
from campipe.engine.modal import pad_stack
from campipe.engine.settings import Case
from campipe.model.assembly import SystemMatrices
from campipe.profiles.packed import evaluate_packed, pack
from campipe.vocabulary import CAM, CAM_AND_SEAT, CAM_CONTACT, SEAT, SEATED

#: The configurations a quasi-static start can take (``initial_states``).
START_CONFIGURATIONS = (CAM_CONTACT, CAM_AND_SEAT, SEATED)


def start_inverses(sm: SystemMatrices) -> np.ndarray:
    """(3, 2, n, n): K_ff⁻¹ and M_ff⁻¹ (``contact.held_inverses``) in configurations I, III
    and IV, the quasi-static start's (``START_CONFIGURATIONS``)."""
    n = sm.mass.shape[0]
    return np.array(
        [held_inverses(sm.mass, sm.stiffness, held_mask(c, n)) for c in START_CONFIGURATIONS]
    )


def initial_state(case: Case, sm: SystemMatrices, seat_q: float):
    """Quasi-static start of one case at θ = 0: (q, v, a, configuration); see
    ``initial_states``."""
    q, v, a, cfg = initial_states(
        [sm],
        np.zeros(1, np.int64),
        pack([case.profile]),
        np.array([case.speed]),
        np.array([case.has_seat]),
        np.array([seat_q]),
    )
    return q[0], v[0], a[0], int(cfg[0])


@njit(cache=True, nogil=True)
def cam_at(profiles, theta):
    """(n, 3): lift [m] and its θ-derivatives of every packed profile at one angle."""
    n = profiles.n_pieces.shape[0]
    out = np.empty((n, 3))
    for c in range(n):
        out[c, 0], out[c, 1], out[c, 2] = evaluate_packed(profiles, c, theta)
    return out


def initial_states(mats, which, packed, omega, has_seat, seat_q, inverses=None):
    """Quasi-static start of every case at θ = 0 (thesis Appendix B, step 1): configuration
    I; III where the valve would stand below its seat; IV where III's cam would have to pull
    (a seat above the valve's lift there: the valve rests on it and the follower stands off
    the cam, unloaded). ``mats``: the distinct trains' matrices, ``which`` each case's index
    into them; ``inverses`` their ``start_inverses`` (computed here if not given)."""
    if inverses is None:
        inverses = [start_inverses(m) for m in mats]
    n = which.size
    n_q = max(m.mass.shape[0] for m in mats)  # the most coordinates: the others zero-padded
    cam = cam_at(packed, 0.0)
    held_q = np.zeros((n, n_q))
    held_v = np.zeros((n, n_q))
    held_a = np.zeros((n, n_q))
    held_q[:, CAM] = -cam[:, 0]
    held_v[:, CAM] = -omega * cam[:, 1]
    held_a[:, CAM] = -(omega**2) * cam[:, 2]
    held_q[:, SEAT] = seat_q
    M = pad_stack([m.mass for m in mats])[which]
    C = pad_stack([m.damping for m in mats])[which]
    K = pad_stack([m.stiffness for m in mats])[which]
    load = pad_stack([m.preload for m in mats])[which]
    states = []
    for i_cfg, number in enumerate(START_CONFIGURATIONS):
        kinv = pad_stack([inv[i_cfg, 0] for inv in inverses])[which]
        minv = pad_stack([inv[i_cfg, 1] for inv in inverses])[which]
        held = np.tile(held_mask(number, n_q), (n, 1))
        qc, vc, ac = np.empty((n, n_q)), np.empty((n, n_q)), np.empty((n, n_q))
        quasi_static_batch(kinv, minv, M, C, K, load, held, held_q, held_v, held_a, qc, vc, ac)
        states.append((qc, vc, ac))
    (q, v, a), (q3, v3, a3), (q4, v4, a4) = states
    seated = has_seat & (q[:, SEAT] < seat_q)
    # The cam's force on the follower in III, the held coordinate's residual: positive
    # pushes (compressive), negative would pull.
    residual = load - np.einsum("nij,nj->ni", K, q3) - np.einsum("nij,nj->ni", C, v3)
    pulls = (residual - np.einsum("nij,nj->ni", M, a3))[:, CAM] < 0.0
    cfg = np.where(seated, np.where(pulls, SEATED, CAM_AND_SEAT), CAM_CONTACT)
    for number, (qc, vc, ac) in ((CAM_AND_SEAT, (q3, v3, a3)), (SEATED, (q4, v4, a4))):
        take = cfg == number
        q[take], v[take], a[take] = qc[take], vc[take], ac[take]
    return q, v, a, cfg.astype(np.int64)
