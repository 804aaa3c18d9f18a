"""The force through a chain's link that holds a lash adjuster: k·(x₁ − x₂ + e), e the
plunger's extension at each sample, on every path that runs one."""

import numpy as np
import pytest
import xarray as xr
from study_helpers import write_spec

from campipe.study import load_study
from campipe.study.run.execute import run_study

#: A two-mass chain with its adjuster in the link, its plunger pumped up to 0.15 mm (the
#: lash less the check force's give): the link's stiffness times that is 1700 N.
SPEC = """
name: chain-hla-loads
model: {layout: lumped, masses: [50 g, 65 g], stiffnesses: [25000 N/mm],
        spring_rate: 36 N/mm, spring_preload: 230 N, damping_ratios: [0.05], lash: 0.15 mm,
        hla_stiffness: 20000 N/mm, hla_leak_down: 2000 N*s/mm, hla_check_force: 25 N,
        hla_pump_up: 20 N*s/mm, hla_travel: 1 mm, hla_extension: 0 mm}
profile: {kind: polydyne-4567, lift: 8 mm, rise: 110 deg, dwell: 20 deg, fall: 110 deg,
          ramp_height: 0.3 mm, ramp_duration: 30 deg, ramp_shape: constant-velocity}
speed: 100 rpm
run: {revolutions: 3, output_every: 1 deg, record: [lash_adjuster, member_loads]}
"""
COMPLIANT = {
    "model.cam_contact": "kelvin-voigt",
    "model.seat_contact": "kelvin-voigt",
    "model.cam_contact_stiffness": "200000 N/mm",
    "model.seat_contact_stiffness": "200000 N/mm",
}


@pytest.mark.parametrize(
    "overrides",
    [
        {},  # modal-exact, the plunger a coordinate of the train
        {"run.revolutions": "auto"},  # the same, turn by turn until it repeats
        COMPLIANT,  # the compliant integrator's state
        {"run.integrator": "newmark-linear", "run.dt": "2 us"},  # the per-turn model
    ],
    ids=["modal-exact", "auto", "compliant", "newmark-per-turn"],
)
def test_the_link_s_force_holds_the_plunger_s_extension(tmp_path, overrides):
    """At 100 rpm (the train's inertia and damping a few newtons at most) the force through the
    link next to the cam (``pushrod_force``, a two-mass chain's only link, so also
    ``stem_force``) is the cam's force while the follower is on the cam (within 3 N at 99 % of
    those samples, 10 N at all: a compliant contact's take-up rings for a sample or two), and no
    joint pulls (``min_joint_force`` above −2 N: the link unloads to 0 where the lash opens,
    ringing to −0.8 N with compliant contacts), on every path that runs a chain's adjuster.
    Broken copy: the link's force from the coordinates alone (k·(x₁ − x₂), the plunger's
    extension left out) reads 1700 N less: −1680 N on the base circle, a joint "pulled"."""
    spec = write_spec(tmp_path, SPEC)
    archive = tmp_path / "loads.nc"
    run_study(load_study(spec, overrides), archive, scheduler="synchronous")
    ds = xr.load_dataset(archive)
    extension = ds.hla_extension_by_rev.values[0]
    assert np.nanmax(extension) > 1e-4  # pumped up: the check matters
    on_cam = ds.cam_force.values[0] > 0
    link = ds.pushrod_force.values[0]
    gap = np.abs(link[on_cam] - ds.cam_force.values[0][on_cam])
    assert np.percentile(gap, 99) < 3.0 and gap.max() < 10.0
    np.testing.assert_array_equal(link, ds.stem_force.values[0])
    assert float(ds.min_joint_force.values[0]) > -2.0
