"""The mechanism sketch: pure geometry from q (campipe.replay.sketch)."""

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal

from campipe.model import thesis_train
from campipe.replay import sketch

GEOM = sketch.Geometry.from_train(thesis_train())
A, B = GEOM.pushrod_arm, GEOM.valve_arm  # 1 in, 1.5 in
L1, L5 = GEOM.pushrod_length, GEOM.valve_stem_length  # 9 in, 3 in


def test_zero_q_draws_the_reference_geometry():
    qd = np.zeros((1, 7))
    parts = sketch.moving_parts(qd, GEOM)
    assert_array_equal(parts["pushrod"][0], [[-A, -L1], [-A, 0.0]])
    rocker = parts["rocker"][0]
    assert_array_equal(rocker[:, 1], 0.0)
    assert rocker[0, 0] == -A and rocker[-1, 0] == B
    assert_array_equal(parts["stem"][0], [[B, 0.0], [B, -L5]])
    assert_array_equal(sketch.follower_position(qd, GEOM), [[-A, -L1]])
    # the cam's base circle touches the follower straight above its centre
    outline = sketch.cam_outline(np.radians(np.arange(360.0)), np.zeros(360), [0.0], GEOM)[0]
    top = outline[np.argmax(outline[:, 1])]
    assert_allclose(top, [-A, -L1], atol=1e-15)


def test_a_rigid_rocker_rotation_moves_both_ends_consistently():
    p = np.array([0.0, 0.004, 0.0254])  # follower lifts [m]
    q = sketch.rigid_coordinates(p, GEOM)
    # the rigid train: q2 = p up, the valve end down by the rocker ratio, q1 = -p, q7 = -q4
    assert_allclose(q[:, 3], -1.5 * p, rtol=1e-15)
    assert_array_equal(q[:, 0], -p)
    assert_array_equal(q[:, 6], -q[:, 3])
    for magnification in (1.0, 50.0):  # no deviation: nothing to magnify
        qd = sketch.displayed_coordinates(q, p, np.ones(3), GEOM, magnification)
        assert_allclose(qd, q, rtol=0, atol=1e-18)
    rocker = sketch.rocker(q, GEOM)
    # a straight line through the pivot: slope -p/a on both arms
    for k in range(3):
        x, y = rocker[k].T
        assert_allclose(y, -p[k] / A * x, atol=1e-17)
    assert_allclose(rocker[:, 0, 1], p)  # pushrod end up by p
    assert_allclose(rocker[:, -1, 1], -1.5 * p, rtol=1e-14)  # valve end down by 1.5 p
    assert_allclose(sketch.pushrod(q, GEOM)[:, 1, 1], rocker[:, 0, 1])  # pushrod meets rocker
    assert_allclose(sketch.stem(q, GEOM)[:, 0, 1], rocker[:, -1, 1])  # stem meets rocker


def test_deviation_from_the_rigid_motion_is_magnified():
    cam = np.array([0.01])
    q = sketch.rigid_coordinates(cam, GEOM)
    q[:, 1] -= 5e-5  # pushrod 0.05 mm shorter
    q[:, 4] += 2e-3  # rocker bent at the valve end
    qd = sketch.displayed_coordinates(q, cam, [1], GEOM, 20.0)
    assert_allclose(qd[0, 1], 0.01 - 20 * 5e-5, rtol=1e-14)
    assert_allclose(qd[0, 4], -0.01 / A + 20 * 2e-3, rtol=1e-14)
    assert qd[0, 0] == q[0, 0]  # on the cam: the follower stays where it is


def test_contacts_are_drawn_true_and_never_crossed():
    cam = np.array([0.002, 0.002, 0.0])
    seat_q7 = 0.0030  # valve on its seat at q7 = 3 mm
    gap = 0.0005
    q = sketch.rigid_coordinates(cam + gap, GEOM)  # train 0.5 mm off the cam
    q[2, 6] = seat_q7 - 0.0001  # elastic stretch past the seat in seat contact
    state = np.array([2, 1, 4])
    qd = sketch.displayed_coordinates(q, cam, state, GEOM, 10.0, seat_q7)
    # free: the gap drawn ten times over
    assert_allclose(-qd[0, 0] - cam[0], 10 * gap, rtol=1e-12)
    # cam contact (state I): the follower at its computed place
    assert qd[1, 0] == q[1, 0]
    # seat contact (state IV): the valve where it is; the sketch never puts it past the seat
    assert qd[2, 6] == q[2, 6]
    q[0, 6] = seat_q7 - 0.001
    qd = sketch.displayed_coordinates(q, cam, [2, 2, 2], GEOM, 10.0, seat_q7)
    assert qd[0, 6] == seat_q7
    assert np.all(-qd[:, 0] >= cam)  # never inside the cam


def test_rocker_arms_follow_the_beam_shape_functions():
    # a cubic deflection is reproduced exactly by the Hermite shape functions (thesis Eq. 8)
    def v(x):
        return 1e-4 * (x / A) ** 3 - 2e-4 * (x / A) ** 2 + 3e-5

    def dv(x):
        return 1e-4 * 3 * x**2 / A**3 - 2e-4 * 2 * x / A**2

    x = np.linspace(-A, 0.0, sketch.ARM_POINTS)
    shape = sketch.hermite([v(-A)], [dv(-A)], [v(0.0)], [dv(0.0)], A)[0]
    assert_allclose(shape, v(x), rtol=0, atol=1e-18)


def test_the_cam_turns_clockwise_with_the_lift_under_the_follower():
    phi = np.radians(np.arange(0.0, 360.0, 1.0))
    lift = 0.01 * (1 - np.cos(phi)) / 2  # a harmonic-like lift, 10 mm at 180°
    theta = np.radians([0.0, 90.0, 180.0])
    outline = sketch.cam_outline(phi, lift, theta, GEOM)
    assert outline.shape == (3, 361, 2)
    assert_array_equal(outline[:, 0], outline[:, -1])  # closed
    c = GEOM.cam_centre
    # the body angle θ sits straight above the centre at cam angle θ
    for k, deg in enumerate([0, 90, 180]):
        assert_allclose(outline[k, deg], [c[0], c[1] + GEOM.base_radius + lift[deg]], atol=1e-15)
    # clockwise: at 90°, body angle 0 has turned to the right of the centre
    assert_allclose(outline[1, 0], [c[0] + GEOM.base_radius, c[1]], atol=1e-15)
