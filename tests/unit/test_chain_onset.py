"""A lumped chain's no-follow onset (``campipe.engine.onset``) against a frequency-response
computation written here: two and three masses, the harmonic cam, no seat."""

import numpy as np
import pytest
from scipy.optimize import brentq

from campipe.constants import RPM
from campipe.engine import Case
from campipe.engine.onset import onset_speeds
from campipe.model import valve_train
from campipe.profiles import harmonic

LIFT = 0.010  # [m]
PRELOAD, RATE = 250.0, 40e3  # [N], [N/m]
CHAINS = {
    "two masses": ([0.05, 0.06], [20000e3], [0.05, 0.05]),
    "three masses": ([0.03, 0.04, 0.05], [30000e3, 15000e3], [0.04, 0.06, 0.08]),
    "two masses, undamped": ([0.05, 0.06], [20000e3], [0.0, 0.0]),
}


def frequency_response_onset(masses, links, zetas) -> float:
    """The onset [rad/s] from the chain's equations: the cam mass follows x1 = h/2·(1 − sin θ),
    the rest free on the links and the valve spring, modal damping ζ on the modes with every
    mass free (C = M·Φ·diag(2ζω)·Φᵀ·M). The cam's mean force is the spring's, preload and mean
    lift h/2 (P + ks·h/2), shared between the links in series (k_L) and the spring as
    k_L/(k_L + ks); less |G(iω)|·h/2, G the dynamic stiffness at the cam mass with the others
    free (a Schur complement): the onset is where its least value over the turn reaches
    zero."""
    m = np.asarray(masses)
    n = m.size
    K = np.zeros((n, n))
    for j, k in enumerate(links):
        K[j : j + 2, j : j + 2] += k * np.array([[1.0, -1.0], [-1.0, 1.0]])
    K[-1, -1] += RATE
    M = np.diag(m)
    s = np.diag(1.0 / np.sqrt(m))
    lam, v = np.linalg.eigh(s @ K @ s)
    phi = s @ v
    C = M @ phi @ np.diag(2.0 * np.asarray(zetas) * np.sqrt(lam)) @ phi.T @ M
    k_links = 1.0 / sum(1.0 / k for k in links)
    mean = (PRELOAD + RATE * LIFT / 2) * k_links / (k_links + RATE)

    def least_force(omega: float) -> float:
        D = K + 1j * omega * C - omega**2 * M
        g = D[0, 0] - D[0, 1:] @ np.linalg.solve(D[1:, 1:], D[1:, 0])
        return mean - abs(g) * LIFT / 2

    return brentq(least_force, 1000 * RPM, 30000 * RPM, xtol=1e-9)


@pytest.mark.parametrize("name", list(CHAINS))
def test_a_chain_s_onset_is_its_frequency_response(name):
    """The onset search's speed equals the frequency response's to 0.1 rpm (its tolerance; the
    issue asks 1 rpm), proven, on the bound (not by stepping the range at the tolerance).
    Fails on a copy whose chain puts the valve spring on the cam's mass, drops a link's give
    (the preload's share, 4 rpm for two masses), or damps the modes with the cam mass held
    instead of free; undamped, on the copy of ``slope_bound._tail`` that bounded the terms
    nearest an undamped pole by 1/(Re λ)² (infinite: the search stepped the range at its
    tolerance, ran out of steps and said "none", proven)."""
    masses, links, zetas = CHAINS[name]
    train = valve_train(
        "thesis-1971",
        {
            "layout": "lumped",
            "masses": [f"{x} kg" for x in masses],
            "stiffnesses": [f"{k} N/m" for k in links],
            "spring_rate": f"{RATE} N/m",
            "spring_preload": f"{PRELOAD} N",
            "damping_ratios": zetas,
        },
    )
    expected = frequency_response_onset(masses, links, zetas)
    found = onset_speeds([Case(train, harmonic(LIFT), 1.0)], 2000 * RPM, 20000 * RPM)
    assert found.status[0] == "found"
    assert found.proven[0] and found.evaluations[0] < 2000  # stepped at 0.1 rpm: 180 000
    assert found.speed[0] / RPM == pytest.approx(expected / RPM, abs=0.1)  # the search tolerance


def test_where_it_leaves_the_cam_is_where_no_follow_starts():
    """``leaves_cam_at_deg`` (``first_separation``) is where the train enters configuration
    II: on a rocker with 0.2 mm of lash just above its onset, the follower leaves the cam onto
    the lash with the valve seated at 285.8° every turn (III to IV: not no-follow), and the
    valve bounces off its seat at 296.35° (IV to II: the no-follow the onset counts). Events
    before the warm-up turn do not count; the follower leaving the cam with no seat (I to II)
    does. Broken copy: the first cam separation (285.8°)."""
    import math

    import numpy as np

    from campipe.engine.onset import first_separation
    from campipe.vocabulary import (
        CAM_AND_SEAT,
        CAM_CONTACT,
        CAM_SEPARATION,
        FREE,
        SEAT_SEPARATION,
        SEATED,
    )

    w = 2 * math.pi  # 1 rev/s: a time [s] is a fraction of a turn
    rows = [  # time, kind, from, to, velocity, impulse
        (296.0 / 360, SEAT_SEPARATION, SEATED, FREE, 0.0, 0.0),  # turn 0: warm-up
        (1 + 285.8 / 360, CAM_SEPARATION, CAM_AND_SEAT, SEATED, 0.0, 0.0),
        (1 + 296.35 / 360, SEAT_SEPARATION, SEATED, FREE, 0.0, 0.0),
    ]
    events = np.array(rows, float)
    assert math.degrees(first_separation(events, w, warmup=1)) == pytest.approx(296.35)
    free = np.array([(1.5, CAM_SEPARATION, CAM_CONTACT, FREE, 0.0, 0.0)], float)
    assert math.degrees(first_separation(free, w, warmup=1)) == pytest.approx(180.0)
    assert math.isnan(first_separation(events[1:2], w, warmup=1))
