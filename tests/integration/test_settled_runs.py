"""Run length by convergence (``run.revolutions: auto``, ``campipe.engine.settle``): the
default study's metrics are the settled response's, checked against an independent long run.

The reference is the thesis's algorithm (campipe's newmark-linear: its own kernel, events at
step ends) run for 60 turns, its first 20 left out. Its own error at the seat is first order
in its step (no-follow at 9000 rpm with the seat at 0.1 in: 86.05, 84.94, 84.15° at 1, 0.5,
0.25 µs, toward modal-exact's 83.14°), so it runs at 0.25 µs.
"""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from study_helpers import INCH, STUDIES, write_spec

from campipe.constants import RPM
from campipe.engine import Case, RunSettings, run_batch
from campipe.engine.metrics import MAX_CAM_FORCE
from campipe.engine.settings import RunSettingsError
from campipe.model import thesis_train
from campipe.profiles.shapes import harmonic
from campipe.study import load_study
from campipe.study.run.execute import run_study

#: A sweep through the no-follow onset (about 9524 rpm without a seat), without a seat and
#: with one at 0.1 in: the default run settings (``run.revolutions`` left to ``auto``).
SWEEP = """
name: settled
profile: {kind: harmonic, lift: 1 in}
sweep:
  speed: [9000 rpm, 9700 rpm, 11000 rpm, 12000 rpm, 13000 rpm]
  seat: [none, 0.1 in]
"""


@pytest.fixture(scope="module")
def settled(tmp_path_factory) -> xr.Dataset:
    directory = tmp_path_factory.mktemp("settled")
    path = directory / "settled.nc"
    run_study(load_study(write_spec(directory, SWEEP)), path, scheduler="synchronous")
    return xr.load_dataset(path)


def long_reference(speed_rpm, seat) -> np.ndarray:
    """No-follow per turn [deg], mean over turns 21–60 of newmark-linear at 0.25 µs; ``seat``
    as the archive stores it [m] (−inf: none)."""
    cases = [
        Case(thesis_train(), harmonic(INCH), s * RPM, np.nan if np.isinf(z) else z)
        for s, z in zip(speed_rpm, seat, strict=True)
    ]
    run = RunSettings(revolutions=60, warmup=20, integrator="newmark-linear", dt=0.25e-6)
    return np.degrees(run_batch(cases, run).separation)


def test_the_default_study_gives_the_settled_no_follow_of_a_long_independent_run(settled):
    """Within 2 % of the long run on cases that settled, 3 % on those that never repeat
    (statistics over a window). Fails on a copy whose metrics average every turn from the
    start (``measured`` all turns run): the first turns' transient leaves the 11000 rpm case
    without a seat 15 % low (the issue's 174° against 219°)."""
    speed = settled.speed_rpm.values
    seat = settled.seat.values
    ours = settled.separation_deg_per_rev.values
    period = settled.period_turns.values
    reference = long_reference(speed, seat)
    off = ours > 0
    assert off.sum() >= 8  # past the onset: the cases the issue is about
    rel = np.abs(ours[off] / reference[off] - 1.0)
    limit = np.where(period[off] > 0, 0.02, 0.03)
    assert np.all(rel <= limit), list(
        zip(speed[off], seat[off], ours[off], reference[off], strict=True)
    )
    # below the onset without a seat the train follows the cam: no-follow 0 in both
    follows = (speed == 9000) & np.isinf(seat)
    assert ours[follows] == 0.0 and reference[follows] == 0.0


def test_period_turns_is_one_on_a_steady_case_and_two_on_an_alternating_one(settled):
    """11000 rpm without a seat leaves the cam the same every turn from its third; 12000 rpm
    alternates (275.1° and 295.1° in the long run). Fails on a copy that checks period 1
    only (12000 rpm then never repeats: period 0)."""
    no_seat = np.isinf(settled.seat.values)
    by_speed = dict(
        zip(settled.speed_rpm.values[no_seat], settled.period_turns.values[no_seat], strict=True)
    )
    assert by_speed[11000.0] == 1
    assert by_speed[12000.0] == 2
    # the alternating case's window is whole periods: an even number of turns
    i = np.flatnonzero(no_seat & (settled.speed_rpm.values == 12000.0))[0]
    measured = settled.measured.values[i].astype(bool)
    assert measured.sum() % 2 == 0
    per_rev = settled.separation_deg.values[i][measured]
    assert abs(per_rev[0] - per_rev[1]) > 10.0  # the two turns differ: it is a period of two


def test_a_case_that_follows_the_cam_settles_in_its_first_turn(settled):
    """From the periodic start, the 9000 rpm case without a seat repeats at once: one turn
    run (no slower than a fixed run where nothing happens). Fails on a copy whose check needs
    two differences before it accepts a repetition."""
    follows = (settled.speed_rpm.values == 9000) & np.isinf(settled.seat.values)
    assert settled.revolutions_run.values[follows] == 1
    assert settled.period_turns.values[follows] == 1


def test_histories_and_events_are_the_last_turn_of_the_settled_run(settled):
    """One turn stored per case (run.history_turns 1), the events on the same angles: every
    event's cam angle within 0–360°, its time that of the recorded turn. Fails on a copy that
    leaves the events' angles counted from the start of the run."""
    assert settled.cam_angle.values[-1] == 360.0
    angle = settled.event_cam_angle.values
    assert angle.size > 0 and angle.min() >= -1e-6 and angle.max() <= 360.0 + 1e-6
    first = settled.recorded_revolution.values - 1
    run = settled.revolutions_run.values
    assert np.all(first == run - 1)
    omega = settled.speed_rpm.values * RPM
    t0 = first * 2 * np.pi / omega
    assert np.allclose(settled.time.values[:, 0], t0)


def test_a_fixed_run_has_no_settling_variables(tmp_path):
    """``run.revolutions: 2`` keeps today's archive: no period_turns (the digest's study fixes
    its revolutions; tests/integration/test_digest.py holds its numbers)."""
    spec = write_spec(tmp_path, SWEEP.replace("sweep:", "run: {revolutions: 2}\nsweep:"))
    path = tmp_path / "fixed.nc"
    study = load_study(spec)
    assert not study.settle
    run_study(study, path, scheduler="synchronous")
    with xr.open_dataset(path) as ds:
        assert "period_turns" not in ds and ds.revolution.size == 2


def test_settling_settings_that_cannot_work_are_refused_naming_the_key():
    """A sample spacing that does not divide a turn; a cap below two of the longest period."""
    case = Case(thesis_train(), harmonic(INCH), 9000 * RPM)
    with pytest.raises(RunSettingsError) as info:
        run_batch([case], RunSettings(revolutions=None, output_every=np.radians(0.7)))
    assert info.value.key == "run.output_every"
    with pytest.raises(RunSettingsError) as info:
        run_batch([case], RunSettings(revolutions=None, max_revolutions=6, max_period=4))
    assert info.value.key == "run.max_revolutions"


@pytest.mark.parametrize(
    ("run", "key"),
    [("{output_every: 0.7 deg}", "run.output_every"), ("{warmup: 1}", "run.warmup")],
)
def test_a_spec_of_automatic_length_that_cannot_work_is_refused_at_its_key(tmp_path, run, key):
    """Refused when the spec is checked, before anything runs, naming the key. Fails on a
    copy that leaves the check to the engine (a worker would fail every case)."""
    from campipe.study.spec.check import SpecError

    spec = write_spec(tmp_path, f"name: bad\nprofile: {{kind: harmonic, lift: 1 in}}\nspeed: "
                      f"9000 rpm\nrun: {run}\n")  # fmt: skip
    with pytest.raises(SpecError) as info:
        load_study(spec)
    assert key in str(info.value)


def test_more_recorded_turns_than_it_took_to_settle_are_all_run_and_stored():
    """A case that follows the cam settles in one turn; with history_turns 3 it runs three,
    and its three recorded turns are equal (period 1). Fails on a copy that stops a case at
    its settling turn (its later recorded turns would be NaN)."""
    case = Case(thesis_train(), harmonic(INCH), 9000 * RPM)
    r = run_batch([case], RunSettings(revolutions=None, history_turns=3))
    assert r.turns_run[0] == 3 and r.period_turns[0] == 1 and r.recorded_from[0] == 0
    lift = r.valve_lift[0]
    assert np.isfinite(lift).all() and lift.size == 3 * 360 + 1
    turn = 360
    assert np.allclose(lift[:turn], lift[turn : 2 * turn], atol=1e-9 * np.ptp(lift))
    assert np.allclose(lift[:turn], lift[2 * turn : 3 * turn], atol=1e-9 * np.ptp(lift))


def test_newmark_linear_runs_until_settled_too():
    """The restart carries accelerations consistent with the configuration (newmark-linear
    steps from them): 11000 rpm without a seat repeats every turn, as the same integrator's
    long fixed run does, and leaves the cam as much. Fails on a copy that restarts with zero
    accelerations (a kick at each turn boundary: it finds a period of 2)."""
    case = Case(thesis_train(), harmonic(INCH), 11000 * RPM)
    run = dict(integrator="newmark-linear", dt=1e-6)
    r = run_batch([case], RunSettings(revolutions=None, **run))
    ref = run_batch([case], RunSettings(revolutions=30, warmup=15, **run))
    last = ref.separation_per_rev[0, -6:]
    assert np.ptp(last) < 5e-3 * last.mean()  # the long run repeats every turn (its grid)
    assert r.period_turns[0] == 1
    assert abs(r.separation[0] / ref.separation[0] - 1) < 0.005


@pytest.mark.parametrize("integrator", ["default", "compliant"])
def test_a_compliant_case_runs_on_from_its_own_state_at_each_turn(integrator):
    """A compliant case of automatic length goes turn by turn, each from the last one's end:
    that end is its compliant state (contacts compressed), taken as it is. The recorded last
    turn matches a continuous fixed run's same turn: the cam force at its first samples to
    1e-6 (found: 3e-9), the turn's peak cam force to 1e-7. Fails on a copy that compresses
    the contacts again at each turn's start as a rigid start's (the force there doubles:
    2183 against 1091 N on this case)."""
    train = thesis_train().replace(
        cam_contact="kelvin-voigt", cam_contact_stiffness=1e6 / INCH * 4.4482216152605,
        cam_contact_damping=10 * 4.4482216152605 / INCH,
    )  # fmt: skip
    case = Case(train, harmonic(1 * INCH), 6000 * RPM)
    fixed = run_batch([case], RunSettings(revolutions=4, integrator=integrator))
    auto = run_batch([case], RunSettings(revolutions=None, integrator=integrator))
    turns = int(auto.turns_run[0])
    assert 2 <= turns <= 4
    start = 360 * (turns - 1)  # the recorded turn's first sample in the fixed run
    np.testing.assert_allclose(
        auto.cam_force[0, :4], fixed.cam_force[0, start : start + 4], rtol=1e-6
    )
    peak = auto.per_rev[0, turns - 1, MAX_CAM_FORCE]
    assert peak == pytest.approx(fixed.per_rev[0, turns - 1, MAX_CAM_FORCE], rel=1e-7)


def test_a_short_chain_s_placeholders_do_not_set_its_period():
    """The bundled bucket (a two-mass chain: q2 … q6 are placeholders, at rest to rounding)
    past its onset, 4032.9 rpm with 0.2 mm and 0.1 mm of lash: a fixed run of 6 turns from
    the periodic start gives each turn the same no-follow (to 1e-8: its events located to
    1e-12 s), cam force and seating velocity (to 1e-9; an independent long run agrees:
    1.7181° a turn, every turn), so the response
    repeats every turn: `period_turns` 1 for both. Broken copy: the placeholders' rounding
    (1e-15 m/s against a floor of 4.2e-7 m/s) in the turn boundaries' comparison, 1.09e-8
    of the tolerance's 1e-8 at once: period 2 at 0.2 mm (found by a fresh pair of eyes)."""
    path = STUDIES / "bucket-tappet-lash.yaml"
    sets = {"sweep.speed": ["4032.9 rpm"], "sweep.model.lash": ["0.1 mm", "0.2 mm"]}
    cases = [c.case for c in load_study(path, sets).cases]
    fixed = run_batch(cases, RunSettings(revolutions=6, warmup=0))
    for key in ("separation", "max_cam_force", "max_seating_velocity"):
        per_turn = fixed.metric_per_rev(key)
        rtol = 1e-8 if key == "separation" else 1e-9
        assert np.allclose(per_turn, per_turn[:, :1], rtol=rtol, atol=0), key
    assert np.all(np.degrees(fixed.metric_per_rev("separation")) > 1.0)  # past the onset
    auto = run_batch(cases, RunSettings(revolutions=None))
    assert auto.period_turns.tolist() == [1, 1]
