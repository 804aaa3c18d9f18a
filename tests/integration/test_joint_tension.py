"""The valve stem's least force (``min_joint_force``, ``run.record: member_loads``) and the
summary's line on a stem that pulled: the model's links are two-sided, a tappet on the stem's
tip is not (docs/model.md, "Joints that pull")."""

import math

import xarray as xr
from click.testing import CliRunner
from numpy.testing import assert_allclose
from study_helpers import BUCKET_RING, write_spec

from campipe.cli import main
from campipe.engine import Case
from campipe.engine.batch import initial_state, train_matrices, valve_reference
from campipe.engine.loads import member_loads, pushing_joints
from campipe.model import thesis_train
from campipe.profiles import harmonic

TAPPET, STEM, CONTACT, PRELOAD = 0.045, 30000e3, 60000e3, 220.0
RAMP, RAMP_ANGLE, RPM = 0.3e-3, math.radians(30.0), 1000.0


def test_the_thesis_train_s_joints_carry_the_hand_s_static_forces():
    """The quasi-static state at θ = 0 (mid-lift: 0.75 in of valve travel), no seat: the
    pushrod's two cups carry the rocker ratio times the spring's force and the rocker's tip
    the spring's force (the stem carries nothing), each compressive (positive). Broken
    copies: the rocker's tip read at its pivot end, or a cup's sign turned."""
    train = thesis_train()
    sm = train_matrices(train)
    q, _, _, _ = initial_state(Case(train, harmonic(0.0254), 2 * math.pi / 60), sm,
                               valve_reference(sm))  # fmt: skip
    spring = member_loads(train, q)["spring_force"]
    ratio = train.rocker_valve_arm_length / train.rocker_pushrod_arm_length
    assert_allclose(spring, train.spring_preload + train.spring_rate * 0.75 * 0.0254, rtol=0.01)
    assert_allclose(pushing_joints(train, q), [ratio * spring, ratio * spring, spring], rtol=1e-6)


def test_a_seated_bucket_s_tappet_rings_on_its_stem_with_the_closed_form_s_force(tmp_path):
    """An undamped bucket tappet with lash at 1000 rpm: on the closing ramp (constant velocity
    v = h·ω/θ) the valve seats, the tappet retreats with the cam until the link's force
    reaches zero and the cam lets go, and the tappet then swings on the link alone (the valve
    held by its seat): the link's force is −m·v·ω_t·sin ω_t·t, ω_t = √(k/m), k the stem and
    the tappet's contact in series. So the least stem force is −m·v·ω_t (a pull no tappet can
    give) and the seat's largest force P₀ + m·v·ω_t, each turn, to the samples' resolution
    (0.01°: ω_t·Δt/2 = 0.018 rad, 2e-4 of the peak). The summary names the pull.
    Broken copies: the metric taking the turn's largest; the per-turn split off by a turn
    (its first turn NaN); the summary's line missing."""
    spec = write_spec(
        tmp_path,
        BUCKET_RING + "run: {revolutions: 2, output_every: 0.01 deg, record: [member_loads]}\n"
        f"sweep: {{speed: [{RPM} rpm]}}\n",
    )
    archive = tmp_path / "ring.nc"
    out = CliRunner().invoke(main, ["study", str(spec), "-o", str(archive)])
    assert out.exit_code == 0, out.output
    k = 1.0 / (1.0 / STEM + 1.0 / CONTACT)
    ring = TAPPET * (RAMP * RPM * math.pi / 30.0 / RAMP_ANGLE) * math.sqrt(k / TAPPET)  # 56.9 N
    with xr.open_dataset(archive) as ds:
        assert ds.min_joint_force.attrs["units"] == "N"
        per_rev = ds.min_joint_force_by_rev.values[0]
        seat = ds.max_seat_force_by_rev.values[0]
    assert per_rev.shape == (2,)
    for turn in range(2):
        assert abs(per_rev[turn] + ring) < 2e-4 * ring, (per_rev, -ring)
        assert abs(seat[turn] - (PRELOAD + ring)) < 2e-4 * ring, (seat, PRELOAD + ring)
    summary = CliRunner().invoke(main, ["query", str(archive), "--summary", "--units", "si"])
    assert summary.exit_code == 0, summary.output
    assert (
        "a joint pulled (min_joint_force below 0) in 1 of 1 cases, least -56.92" in summary.output
    )
    assert '(docs/model.md, "Joints that pull")' in summary.output
