"""A case and what refuses one: the valve train, cam and drive of one run; the errors every
check of a run raises; the turns and samples a run covers; the configurations a case visits.

Plain Python and NumPy, below the run settings and the integrators (which check cases).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from campipe.constants import TWO_PI
from campipe.errors import CampipeError
from campipe.model import ValveTrain, system_matrices, train_lash_seat
from campipe.model.assembly import configuration_frequencies
from campipe.model.layouts import mirror
from campipe.profiles import Profile
from campipe.profiles.levers import valve_side
from campipe.vocabulary import CAM_AND_SEAT, CAM_CONTACT, CONFIGURATIONS, FREE

CLOSURES = ("force", "form")


class RunSettingsError(CampipeError, ValueError):
    """Run settings the engine refuses; ``key`` is the spec key (``run.integrator``,
    ``run.fidelity``, ``run.dt``, ``run.tolerance``)."""


class StabilityError(RunSettingsError):
    """A step beyond the integrator's stability limit (``key`` ``run.dt``, ``found`` the
    step [s]); its ``reason`` leaves out which case of the batch set the limit."""


class CaseError(CampipeError, ValueError):
    """A case the engine refuses; ``key`` is ``closure`` or ``speed``."""


class IntegrationError(CampipeError, RuntimeError):
    """A run that produced a non-finite state, or chattered; ``found`` lists the cases."""


def turn_count(revolutions: float) -> int:
    """The turns a run of ``revolutions`` covers, a partial last turn included: the length of
    its per-turn metrics (the archive's ``revolution`` axis)."""
    return int(math.ceil(revolutions - 1e-12))


def sample_count(revolutions: float, output_every: float) -> int:
    """The output samples of a run of ``revolutions`` turns, every ``output_every`` [rad] from
    θ = 0 (the last within 2π·revolutions)."""
    return int(math.floor(revolutions * TWO_PI / output_every + 1e-9)) + 1


class Sampled(Protocol):
    """What fixes a run's output samples (``RunSettings``)."""

    @property
    def recorded_revolutions(self) -> float: ...  # cam turns the histories cover

    @property
    def output_every(self) -> float: ...  # output spacing in cam angle [rad]


def output_angles(settings: Sampled) -> np.ndarray:
    """Sample angles 0 … 2π·revolutions at ``output_every`` [rad] (the recorded turns')."""
    n_out = sample_count(settings.recorded_revolutions, settings.output_every)
    return _angles(n_out, settings.output_every).copy()


@functools.lru_cache(maxsize=64)
def _angles(n_out: int, every: float) -> np.ndarray:
    # Made once per grid and copied (a third of making it: every run_batch call takes one).
    return np.arange(n_out) * every


def compliant_contacts(train: ValveTrain, has_seat: bool) -> bool:
    """A train whose cam contact, or seat contact where there is a seat, is compliant."""
    return train.cam_contact != "rigid" or (has_seat and train.seat_contact != "rigid")


@functools.lru_cache(maxsize=256)
def _lash_seat(train: ValveTrain) -> float:
    """The seat a train's lash places (``campipe.model.lash_seat``, on the train's
    ``lash_side``), once per train."""
    return train_lash_seat(train)


@dataclass(frozen=True)
class Case:
    """One run: a valve train, a cam and how it is driven."""

    train: ValveTrain  # model parameters [SI]
    #: cam lift over one turn, defects applied; a lever layout's is its kinematic valve lift
    #: (``campipe.profiles.levers.valve_side``, derived on construction)
    profile: Profile
    speed: float  # cam speed [rad/s]
    #: seat position as a valve lift from the valve's static position on the base circle
    #: with no seat [m]; NaN: no seat. A train with lash places it (``lift_zero``).
    seat: float = math.nan
    closure: str = "force"  # "force": spring-held, may separate; "form": never leaves the cam

    def __post_init__(self) -> None:
        object.__setattr__(self, "profile", valve_side(self.profile, self.train))
        if not math.isnan(self.seat) and mirror(self.train):
            raise CaseError.at(
                "seat",
                "a one-mass chain (a rigid follower that is its valve) runs without a seat: "
                "its cam and its seat would hold one body",
                found=self.seat,
                expected="no seat (NaN) with one mass",
            )
        lash = getattr(self.train, "lash", math.nan)
        if math.isnan(lash):
            return
        seat = _lash_seat(self.train)
        if not math.isnan(self.seat) and self.seat != seat:
            side = getattr(self.train, "lash_side", "valve")
            raise CaseError.at(
                "seat",
                f"a seat at {self.seat:.6g} m beside a train's lash of {lash:.6g} m on the "
                f"{side} side, which places the seat at {seat:.6g} m; give one of them",
                found=self.seat,
                expected="no seat (NaN), or a train without lash",
            )
        object.__setattr__(self, "seat", seat)  # the lash places the seat

    @property
    def has_seat(self) -> bool:
        return not math.isnan(self.seat)

    @property
    def lift_zero(self) -> float:
        """Where the case's valve lift reads 0, as a valve lift from the valve's static
        position on the base circle with no seat [m]: the seat in a train with lash (the
        valve's closed position: valve lift 0 on the seat), else 0 (that static position,
        the thesis's)."""
        return self.seat if not math.isnan(getattr(self.train, "lash", math.nan)) else 0.0

    @property
    def compliant(self) -> bool:
        """A compliant law at a contact the case can touch (``engine.compliant``)."""
        return compliant_contacts(self.train, self.has_seat)


@functools.lru_cache(maxsize=256)
def configuration_omega_max(train: ValveTrain) -> np.ndarray:
    """(4,) the highest natural frequency of each configuration I–IV [rad/s]."""
    sm = system_matrices(train)
    return np.array(
        [configuration_frequencies(sm.mass, sm.stiffness, c).max() for c in CONFIGURATIONS]
    )


def visited_configurations(case: Case) -> tuple[int, ...]:
    """The configurations a case can reach: no seat keeps it in I/II; form closure in I/III."""
    if case.closure == "form":
        return (CAM_CONTACT, CAM_AND_SEAT) if case.has_seat else (CAM_CONTACT,)
    return tuple(CONFIGURATIONS) if case.has_seat else (CAM_CONTACT, FREE)
