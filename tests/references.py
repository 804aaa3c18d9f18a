"""Independent references the tests compare the engine with, written from the model's
matrices alone (never through the engine's own integrators)."""

import numpy as np

from campipe.engine.batch import train_matrices


def steady_state_cam_force(train, speed, lift, theta):
    """Contact force of the harmonic cam in configuration I once transients have decayed: the
    frequency response of the train with q1 prescribed, q1 = −h/2 + (h/2)·sin θ."""
    sm = train_matrices(train)
    M, C, K, f = sm.mass, sm.damping, sm.stiffness, sm.preload
    fr = np.arange(1, 7)
    q1_mean, q1_amp = -lift / 2, -1j * lift / 2  # (h/2) sin θ = Re(−i·h/2·e^{iθ})
    x0 = np.linalg.solve(K[np.ix_(fr, fr)], f[fr] - K[fr, 0] * q1_mean)

    def dyn(rows, cols):
        return (
            K[np.ix_(rows, cols)]
            - speed**2 * M[np.ix_(rows, cols)]
            + 1j * speed * C[np.ix_(rows, cols)]
        )

    x1 = np.linalg.solve(dyn(fr, fr), -dyn(fr, [0])[:, 0] * q1_amp)
    # F1 = row 1 of (K − ω²M + iωC) applied to the complex amplitude, plus the static part.
    static = K[0, fr] @ x0 + K[0, 0] * q1_mean - f[0]
    amp = dyn([0], fr)[0] @ x1 + dyn([0], [0])[0, 0] * q1_amp
    return static + np.real(amp * np.exp(1j * theta))
