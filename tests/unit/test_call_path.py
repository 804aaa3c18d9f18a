"""A call's own work (issue 34: per-call overhead): the outputs as views of one block,
modal-exact's periodic start written into the batch's own start arrays, a train's hash computed
once, a kernel's state record cleared rather than allocated, the output angles copied from a
grid made once. Each must leave every number as before."""

from __future__ import annotations

import dataclasses
import math
import os
import pickle
import subprocess
import sys
import threading

import numpy as np
import pytest
from study_helpers import STUDIES

from campipe.engine import Case, CaseError, RunSettings, run_batch
from campipe.engine import batch as batch_module
from campipe.engine.closed_form import STATE, ExactRuns, make_state
from campipe.engine.common import make_outputs
from campipe.engine.metrics import N_ENGINE
from campipe.engine.settings import LIFT_BOUND, SPEED_BOUND, output_angles
from campipe.model import thesis_train, valve_train
from campipe.profiles import harmonic, polydyne
from campipe.profiles.packed import keyed
from campipe.study import load_study

INCH = 0.0254


def test_the_outputs_are_disjoint_zeroed_views_of_their_shapes():
    """Every output array has its shape, is C-contiguous (the kernels' compiled types), starts
    at zero and shares no element with another: each filled with its own number, each reads
    only its own back. Fails on an offset off by one (two views overlapping by an element),
    a view of the wrong length, or a block made with ``np.empty``."""
    n, n_out, n_rev, n_q = 3, 11, 2, 9
    out = make_outputs(n, n_out, n_rev, 5, n_q)
    expected = {
        "q": (n, n_out, n_q),
        "v": (n, n_out, n_q),
        "force": (n, n_out, 2),
        "cam": (n, n_out),
        "cfg": (n, n_out),
        "acc": (n, n_out, 2),
        "per_rev": (n, n_rev, N_ENGINE),
        "n_events": (n,),
        "status": (n,),
        "steps": (n,),
    }
    for name, shape in expected.items():
        array = getattr(out, name)
        assert array.shape == shape and array.flags.c_contiguous, name
        assert not array.any(), name
    for k, name in enumerate(expected):
        getattr(out, name)[...] = k + 1
    for k, name in enumerate(expected):
        assert np.all(getattr(out, name) == k + 1), name
    assert out.events.shape == (n, 5, 6)


def _cases() -> list[Case]:
    train = thesis_train()
    poly = polydyne("345", 0.4 * INCH, math.radians(80), math.radians(20), math.radians(80))
    return [
        Case(train, harmonic(INCH), 300.0),
        Case(train, poly, 900.0, seat=-0.001),
        Case(train, harmonic(INCH), 1800.0, seat=-0.0005),
    ]


def test_modal_exact_from_its_periodic_start_matches_the_start_handed_to_it():
    """``run_batch`` finds modal-exact's periodic start into the batch's own t0, q0, v0; the
    same cases started from ``start_states`` (the start handed in, through the other path)
    give the same bits: histories, metrics, steps and start times. Fails if the in-place start
    skipped a case (its run from rest at t = 0), wrote q0 for v0, or left accelerations that
    the handed start zeroes."""
    settings = RunSettings(revolutions=2)
    cases = _cases()
    own = run_batch(cases, settings)
    start = batch_module.start_states(cases, settings)
    handed = run_batch(cases, settings, start=start._replace(a0=np.zeros_like(start.a0)))
    assert own.start_time[2] < 0.0  # configuration I holds at θ = 0 for the others
    for name in ("start_time", "q", "v", "acc", "cam_force", "seat_force", "per_rev", "steps"):
        assert np.array_equal(getattr(own, name), getattr(handed, name), equal_nan=True), name
    assert np.array_equal(own.start_time, start.t0)


#: What a kernel that fills its outputs must overwrite starts as this instead of zero.
SENTINEL = 1.234e300


def _filled_variety() -> list[tuple[list[Case], RunSettings]]:
    """Batches whose samples the kernel reaches by every path: following (its first turn
    repeated), thrown off the cam, seated with plastic and bouncing impacts, a lash, form
    closure, trains of seven and of more coordinates in one batch (NaN beyond a train's own),
    a rigid one-mass chain (nothing free on the cam), a finger follower, a partial last turn,
    only the contacts' coordinates, and one case alone (``_prepare_one``)."""
    train = thesis_train()
    poly = polydyne("345", 0.4 * INCH, math.radians(80), math.radians(20), math.radians(80))
    one_mass = valve_train(
        "thesis-1971",
        {"layout": "lumped", "masses": ["0.1 kg"], "stiffnesses": [],
         "spring_rate": "40 N/mm", "spring_preload": "250 N", "damping_ratios": [0.05]},
    )  # fmt: skip
    finger = load_study(STUDIES / "finger-follower.yaml").cases[0].case.train
    mixed = [
        Case(train, harmonic(INCH), 300.0),
        Case(train, harmonic(INCH), 1200.0),
        Case(train, poly, 1000.0, seat=-0.001),
        Case(train.replace(seat_restitution=0.4, spring_elements=3), harmonic(INCH), 1150.0),
        Case(train.replace(lash=0.3e-3), poly, 700.0),
        Case(train, harmonic(INCH), 900.0, seat=0.0005, closure="form"),
    ]
    lever = harmonic(0.006)
    return [
        (mixed, RunSettings(revolutions=3)),
        (mixed, RunSettings(revolutions=2.5, output_every=math.radians(0.7))),
        ([Case(one_mass, lever, 200.0), Case(one_mass, lever, 900.0)], RunSettings(revolutions=2)),
        ([Case(finger, lever, 300.0), Case(finger, lever, 700.0)], RunSettings(revolutions=2)),
        (mixed[1:2], RunSettings(revolutions=2)),
        (mixed[3:4], RunSettings(revolutions=2)),
    ]  # fmt: skip


@pytest.mark.parametrize("full_state", [True, False])
def test_modal_exact_writes_every_sample_of_the_outputs_it_is_handed_uncleared(
    monkeypatch, full_state
):
    """modal-exact declares that its kernel writes every output sample (``fills_outputs``):
    ``run_batch`` then hands it its histories uncleared. Handed them filled with a number
    instead (poisoned through ``make_outputs``), every batch of :func:`_filled_variety` gives
    the bits of the run whose histories start at zero: nothing unwritten is read back. Fails
    if the kernel left a sample unwritten: its first turn repeated short of the last sample,
    a last sample at the run's end skipped, a coordinate beyond a train's own left as it was."""
    original = batch_module.make_outputs
    handed: list[bool] = []

    def poisoned(*args):
        out = original(*args)
        handed.append(args[-1])
        if not args[-1]:
            for history in (out.q, out.v, out.force, out.cam, out.acc):
                history.fill(SENTINEL)
        return out

    for cases, settings in _filled_variety():
        monkeypatch.setattr(batch_module, "make_outputs", original)
        cleared = run_batch(cases, settings, full_state=full_state)
        monkeypatch.setattr(batch_module, "make_outputs", poisoned)
        filled = run_batch(cases, settings, full_state=full_state)
        assert (cleared.status == 0).all()
        for name in ("q", "v", "acc", "cam_lift", "cam_force", "seat_force", "per_rev"):
            a, b = getattr(cleared, name), getattr(filled, name)
            assert np.array_equal(a, b, equal_nan=True), (name, len(cases), settings)
    assert handed and not any(handed)  # every run handed its histories uncleared


def test_a_case_without_a_periodic_start_is_refused_by_its_index():
    """A seat far above the valve's full lift (configuration I holds nowhere on the turn):
    the run refuses it as before the start moved, naming case 1 only. Fails if the in-place
    start ran the case from a NaN start instead."""
    cases = _cases()
    cases[1] = Case(thesis_train(), harmonic(INCH), 900.0, seat=5 * INCH)
    with pytest.raises(CaseError) as raised:
        run_batch(cases, RunSettings(revolutions=1))
    assert raised.value.key == "seat" and raised.value.found == [1]


def _field_hash(train) -> int:
    """The dataclass's own hash: of every field, in order (the cached one's definition)."""
    return hash(tuple(getattr(train, f.name) for f in dataclasses.fields(train)))


def test_a_trains_hash_is_its_fields_once_and_afresh_for_a_replaced_train():
    """Equal trains hash equal; the hash is the fields' (the dataclass's definition, computed
    here from the fields); a replaced train hashes as its own new fields, and the original
    keeps its own. Fails on a hash cached per class instead of per train, one copied into
    ``replace``'s train, or one left out of step with equality."""
    train, same = thesis_train(), thesis_train().replace()
    assert train == same and hash(train) == hash(same) == _field_hash(train)
    stiffer = train.replace(spring_rate=2 * train.spring_rate)
    assert hash(train) == _field_hash(train)  # read again, from the cache
    assert stiffer != train and hash(stiffer) == _field_hash(stiffer) != hash(train)
    assert hash(stiffer.replace(spring_rate=train.spring_rate)) == hash(train)


HASH_IN_ANOTHER_PROCESS = """
import pickle, sys
train = pickle.loads(sys.stdin.buffer.read())
print(hash(train) == hash(train.replace()), train == train.replace())
"""


def test_a_train_sent_to_another_process_is_hashed_there():
    """A train hashed here and pickled is hashed afresh in a process with another string hash
    seed: there it hashes as the trains equal to it (its ``replace()``). Fails if the pickle
    carried this process's cached hash (its strings' hashes differ there)."""
    train = thesis_train()
    hash(train)
    env = {**os.environ, "PYTHONHASHSEED": "12345"}
    done = subprocess.run(
        [sys.executable, "-c", HASH_IN_ANOTHER_PROCESS],
        input=pickle.dumps(train),
        capture_output=True,
        env=env,
        check=True,
    )
    assert done.stdout.split() == [b"True", b"True"]


def test_a_kernels_state_record_is_cleared_at_each_call_and_one_per_thread():
    """``make_state`` hands a thread the same record each call, all its bytes zero again (as
    ``np.zeros``) after a kernel wrote it; another thread gets its own. Fails on a record not
    cleared (a case would start from the last call's segment), or one shared between threads
    (two dask workers' kernels writing one record)."""
    record = make_state()
    record["w"], record["done"], record["bounced_cam"] = 5.0, True, -np.inf
    again = make_state()
    assert again is record and again.tobytes() == np.zeros(1, STATE).tobytes()
    other: list[np.ndarray] = []
    worker = threading.Thread(target=lambda: other.append(make_state()))
    worker.start()
    worker.join()
    assert other[0] is not record and not np.shares_memory(other[0], record)


def test_the_output_angles_are_a_fresh_array_each_call():
    """``output_angles`` copies a grid made once: the angles are k·output_every to the bit
    (as ``np.arange(n) * output_every``), and a caller writing into its copy leaves the next
    call's unchanged. Fails if the cached grid itself were handed out."""
    settings = RunSettings(revolutions=2.5, output_every=math.radians(0.7))
    first = output_angles(settings)
    n = int(math.floor(2.5 * 360 / 0.7 + 1e-9)) + 1
    assert np.array_equal(first, np.arange(n) * math.radians(0.7))
    first[:] = -1.0
    assert np.array_equal(output_angles(settings), np.arange(n) * math.radians(0.7))


def _one_case_variety() -> list[Case]:
    """Cases that differ in every number a one-case batch's preparation reads: seat or none,
    form closure, a lash's seat, restitution and a capture velocity, refined members (more
    coordinates), a rocker ratio above and below one, a fast and a slow speed."""
    train = thesis_train()
    short_arm = train.replace(rocker_valve_arm_length=0.7 * train.rocker_pushrod_arm_length)
    poly = polydyne("345", 0.4 * INCH, math.radians(80), math.radians(20), math.radians(80))
    return [
        Case(train, harmonic(INCH), 300.0),
        Case(train, poly, 1900.0, seat=-0.001),
        Case(train, harmonic(INCH), 900.0, seat=0.0005, closure="form"),
        Case(train.replace(lash=0.3e-3), poly, 700.0),
        Case(train.replace(seat_restitution=0.4, spring_elements=3), harmonic(INCH), 1200.0),
        Case(short_arm, poly, 450.0, seat=-0.0002),
    ]


@pytest.mark.parametrize("case", _one_case_variety())
def test_a_one_case_batch_is_prepared_as_a_row_of_the_vectorised_batch(case):
    """A one-case batch is prepared from scalars (``batch._prepare_one``); a batch of the case
    twice takes the vectorised path. Every per-case array of the one is row 0 of the other's,
    to the bit and of its dtype, C-contiguous and writeable (the kernels' compiled types), and
    so are the run's times and the stack, profiles and train index. Fails on a speed or lift
    bound without the ratio's clamp at 1, a seat taken without its absolute value, a sample spacing
    in turns instead of seconds, the seat and closure flags swapped, or a row that is a
    strided view (another type: a second compile)."""
    settings = RunSettings(revolutions=2.5, output_every=math.radians(0.7), capture_velocity=2e-3)
    one = batch_module._prepare_batch([case], settings, True)
    two = batch_module._prepare_batch([case, case], settings, True)
    assert one.which.tolist() == [0] and two.which.tolist() == [0, 0]
    for name in one.cases._fields:
        mine, row = getattr(one.cases, name), getattr(two.cases, name)[:1]
        assert mine.dtype == row.dtype and mine.shape == row.shape, name
        assert mine.tobytes() == row.tobytes(), name
        assert mine.flags.c_contiguous and mine.flags.writeable, name
    for name in ("train", "t_sample", "t_end"):
        mine, row = getattr(one.runs, name), getattr(two.runs, name)[:1]
        assert mine.dtype == row.dtype and mine.tobytes() == row.tobytes(), name
    assert one.runs.zeta.shape == (1, *two.runs.zeta.shape[1:]) and not one.runs.zeta.any()
    assert one.runs[4:7] == two.runs[4:7]  # dt_cap, tolerance, full_state
    for name in ExactRuns._fields[7:]:  # a carried plunger's rows (none here)
        mine, row = getattr(one.runs, name), getattr(two.runs, name)[:1]
        assert mine.dtype == row.dtype and mine.tobytes() == row.tobytes(), name
    assert one.stack is two.stack and one.modal_trains is two.modal_trains
    assert one.packed.breaks.tobytes() == two.packed.breaks[:1].tobytes()
    # The bounds, from the profile's peaks, the train's |ratio| and its flight (the height a
    # thrown valve rises per unit speed) as the docs state them.
    ratio = abs(batch_module.prepare(case.train, 0.0).valve_ratio)
    lift, rate = batch_module._peaks(keyed(case.profile))
    seat = case.seat if case.has_seat else 0.0
    thrown = case.speed * rate * batch_module.prepare(case.train, 0.0).flight
    assert one.cases.lift_bound[0] == LIFT_BOUND * max(lift, thrown) * max(ratio, 1.0) + abs(seat)
    assert one.cases.speed_bound[0] == SPEED_BOUND * case.speed * rate * max(ratio, 1.0)
    assert one.runs.t_end[0] == 2.5 * 2 * math.pi / case.speed


def test_the_run_kernels_structures_cross_as_plain_tuples_of_their_fields():
    """``kernel_call.plain`` hands a kernel each named structure as the tuple of its fields
    (the same arrays, in order) and everything else as it is; ``named_types`` gives back,
    from those types, the named tuples' own (as numba types them), which
    ``exact.ahead_signatures`` compiles the kernel's helpers for. Fails on a structure left
    named, fields reordered, or ``RUN_STRUCTURES`` out of the kernel's argument order (the
    helpers compiled for other types: a second compile at the run)."""
    from numba import typeof

    from campipe.engine.integrators.modal_exact import arguments
    from campipe.engine.kernel_call import RUN_STRUCTURES, named_types

    cases = _one_case_variety()[:2]
    settings = RunSettings(revolutions=1)
    b = batch_module._prepare_batch(cases, settings, True)
    named = (b.cases, b.modal_trains, b.packed, b.runs, batch_module._outputs(b, settings))
    args = arguments((b.modal_trains, b.packed, b.runs), b.cases, named[4])
    assert len(args) == len(RUN_STRUCTURES) + 2 and isinstance(args[-2], np.ndarray)
    assert args[-1] is None  # no case carries a plunger: the kernel without its code
    for structure, crossed, cls in zip(named, args, RUN_STRUCTURES, strict=False):
        assert type(structure) is cls and type(crossed) is tuple
        assert len(crossed) == len(structure)
        assert all(a is b for a, b in zip(crossed, structure, strict=True))
    kernel_types = tuple(typeof(a) for a in args)
    got = named_types(kernel_types)
    assert got[:5] == tuple(typeof(s) for s in named)
    assert got[5] == typeof(RUN_STRUCTURES[5](*args[5])) and got[6:] == kernel_types[6:]
