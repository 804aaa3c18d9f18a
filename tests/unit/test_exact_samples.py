"""modal-exact's output samples: the contact coordinates' accelerations (from block
coefficients computed once a segment) and the samples with and without the full state."""

import math

import numpy as np
from numpy.testing import assert_array_equal

from campipe.engine import Case, RunSettings, run_batch
from campipe.model import thesis_train
from campipe.profiles import harmonic
from campipe.vocabulary import CAM, CAM_CONTACT, FREE, SEAT, SEATED

INCH = 0.0254
#: Above the no-follow onset (9383 rpm): the follower leaves the cam (its coordinate free,
#: configuration II) on every turn; below it, the valve is free and the cam held.
SPEEDS_RPM = (6000.0, 16000.0)
STEP = math.radians(0.25)


def _run(full_state=True):
    cases = [Case(thesis_train(), harmonic(INCH), r * 2 * math.pi / 60) for r in SPEEDS_RPM]
    return run_batch(cases, RunSettings(revolutions=2, output_every=STEP), full_state=full_state)


def test_free_accelerations_are_the_velocities_derivatives():
    """A free contact coordinate's sampled acceleration (the cam follower's off the cam, the
    valve's) matches the central difference of its sampled velocity within 1 % of its range
    at 99 % of the samples whose neighbours are in the same configuration. Fails
    if a block's coefficients of the acceleration are stale, of the wrong row or not moved
    with its column when blocks are dropped."""
    res = _run()
    checked = {0: 0, 1: 0}
    for c in range(len(SPEEDS_RPM)):
        t = res.time[c]
        cfg = res.contact_state[c]
        for col, coord in ((0, CAM), (1, SEAT)):
            v = res.v[c, :, coord]
            a = res.acc[c, :, col]
            fd = (v[2:] - v[:-2]) / (t[2:] - t[:-2])
            same = (cfg[:-2] == cfg[1:-1]) & (cfg[2:] == cfg[1:-1])
            free = np.isin(cfg[1:-1], (FREE, SEATED) if coord == CAM else (CAM_CONTACT, FREE))
            keep = same & free
            checked[col] += int(keep.sum())
            if keep.any():
                err = np.abs(a[1:-1][keep] - fd[keep]) / np.ptp(a[1:-1][keep])
                # (An impact or a release between two samples of one configuration, a
                # bounce, leaves a few differences that are no derivative: the 99th
                # percentile.)
                assert np.quantile(err, 0.99) < 0.01, (c, col, np.quantile(err, 0.99))
    assert checked[0] > 50 and checked[1] > 1000  # both contacts were free at many samples


def test_contact_samples_do_not_depend_on_the_full_state():
    """The contact coordinates, their velocities and accelerations, the forces and the
    configurations are the same to the bit with and without the full state; without it the
    other coordinates are NaN, with it finite."""
    full = _run()
    part = _run(full_state=False)
    for coord in (CAM, SEAT):
        assert_array_equal(full.q[:, :, coord], part.q[:, :, coord])
        assert_array_equal(full.v[:, :, coord], part.v[:, :, coord])
    assert_array_equal(full.acc, part.acc)
    assert_array_equal(full.cam_force, part.cam_force)
    assert_array_equal(full.contact_state, part.contact_state)
    others = [i for i in range(full.q.shape[2]) if i not in (CAM, SEAT)]
    assert np.isnan(part.q[:, :, others]).all() and np.isnan(part.v[:, :, others]).all()
    assert np.isfinite(full.q[:, :, others]).all() and np.isfinite(full.v[:, :, others]).all()
