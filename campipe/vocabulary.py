"""The engine's vocabulary, defined once: contact coordinates, contact configurations, event
kinds, the event record's columns and the status codes of a run.

Every kernel, the reference peer (``campipe.bench.ivp``), the study layer's archive variables
and replay import these names; nothing else spells a configuration number or a contact index.
Pure Python (the compiled kernels read the module-level integers as constants).

Thesis Ch. III and Table I: the follower may be on the cam or off it, the valve on its seat or
off it, so four configurations:

======  ======  ==========  ==========  ===========================================
number  roman   cam held    seat held   what it is
======  ======  ==========  ==========  ===========================================
1       I       yes         no          the cam drives the train (q1 prescribed)
2       II      no          no          free: the follower off the cam, valve open
3       III     yes         yes         cam and seat (q1 and q7 prescribed)
4       IV      no          yes         seated: the valve on its seat, follower off
======  ======  ==========  ==========  ===========================================
"""

from __future__ import annotations

from dataclasses import dataclass

#: Number of the thesis's generalised coordinates q1 … q7. A train with refined members has
#: more (``campipe.model.n_coordinates``): the internal nodes' coordinates come after these
#: seven, so the contact coordinates keep their indices whatever the refinement.
N_COORDINATES = 7
#: The two contact coordinates, 0-based: q1 (pushrod foot on the cam), q7 (valve foot on the
#: seat).
CAM, SEAT = 0, 6
CONTACTS = (CAM, SEAT)

#: Configuration numbers (thesis Table I).
CAM_CONTACT, FREE, CAM_AND_SEAT, SEATED = 1, 2, 3, 4


@dataclass(frozen=True)
class Configuration:
    """One contact configuration: which contacts hold, and its names."""

    number: int  # 1 … 4, as stored in the archive's contact_state
    roman: str  # I … IV, as the thesis names it
    cam: bool  # the follower is held on the cam (q1 prescribed)
    seat: bool  # the valve is held on its seat (q7 prescribed)
    meaning: str  # CF flag meaning

    @property
    def held(self) -> tuple[int, ...]:
        """Prescribed coordinates, 0-based."""
        return tuple(i for i, on in ((CAM, self.cam), (SEAT, self.seat)) if on)

    @property
    def free(self) -> tuple[int, ...]:
        """Free coordinates of the thesis's seven, 0-based, in order."""
        return free_coordinates(self.number, N_COORDINATES)


CONFIGURATIONS: dict[int, Configuration] = {
    CAM_CONTACT: Configuration(CAM_CONTACT, "I", True, False, "I_cam_contact"),
    FREE: Configuration(FREE, "II", False, False, "II_free"),
    CAM_AND_SEAT: Configuration(CAM_AND_SEAT, "III", True, True, "III_cam_and_seat"),
    SEATED: Configuration(SEATED, "IV", False, True, "IV_seat_only"),
}
ROMAN = {n: c.roman for n, c in CONFIGURATIONS.items()}


def free_coordinates(number: int, n_coordinates: int) -> tuple[int, ...]:
    """Free coordinates, 0-based, in order, of configuration ``number`` in a train of
    ``n_coordinates`` coordinates (seven, or more with refined members): all but the held
    contact coordinates, which are 0 and 6 for any refinement."""
    if n_coordinates < N_COORDINATES:
        raise ValueError(f"a train has at least {N_COORDINATES} coordinates, not {n_coordinates}")
    held = CONFIGURATIONS[number].held
    return tuple(i for i in range(n_coordinates) if i not in held)


def configuration(cam: bool, seat: bool) -> int:
    """The configuration number holding the given contacts (compiled for the kernels by
    ``campipe.engine.common``)."""
    if cam:
        return CAM_AND_SEAT if seat else CAM_CONTACT
    return SEATED if seat else FREE


def holds_cam(number: int) -> bool:
    """Configuration ``number`` holds the follower on the cam."""
    return number == CAM_CONTACT or number == CAM_AND_SEAT


def holds_seat(number: int) -> bool:
    """Configuration ``number`` holds the valve on its seat."""
    return number == CAM_AND_SEAT or number == SEATED


#: Event kinds.
CAM_SEPARATION, CAM_IMPACT, SEAT_SEPARATION, SEAT_IMPACT = 1, 2, 3, 4
#: A hydraulic lash adjuster's switches, where its plunger is a state of the run
#: (``campipe.engine.plunger``): its check valve opening or closing, its plunger reaching
#: the bottom or the top of its travel.
CHECK_VALVE_OPENS, CHECK_VALVE_CLOSES, PLUNGER_BOTTOMS, PLUNGER_TOPS = 5, 6, 7, 8
ADJUSTER_EVENTS = (CHECK_VALVE_OPENS, CHECK_VALVE_CLOSES, PLUNGER_BOTTOMS, PLUNGER_TOPS)
EVENT_KINDS = {
    CAM_SEPARATION: "cam_separation",
    CAM_IMPACT: "cam_impact",
    SEAT_SEPARATION: "seat_separation",
    SEAT_IMPACT: "seat_impact",
    CHECK_VALVE_OPENS: "check_valve_opens",
    CHECK_VALVE_CLOSES: "check_valve_closes",
    PLUNGER_BOTTOMS: "plunger_bottoms",
    PLUNGER_TOPS: "plunger_tops",
}
#: Columns of a run's event records: time [s], kind, configuration before and after, the
#: velocity jump or closing velocity [m/s], the impulse [N·s].
EV_TIME, EV_KIND, EV_FROM, EV_TO, EV_VELOCITY, EV_IMPULSE = range(6)
N_EVENT_FIELDS = 6

#: Status of a run: finished; its state became non-finite; more events than kept; events
#: recurring without time advancing (chatter); its motion left physical bounds (a valve lift
#: or a closing speed far beyond what the cam drives: a step too large for the integrator);
#: stopped at ``run.max_steps`` steps (``--max-steps``: an adaptive integration, a stiff
#: contact without damping, that would take longer than the cap allows).
OK, NONFINITE, EVENTS_TRUNCATED, CHATTER, UNBOUNDED, STEP_LIMIT = 0, 1, 2, 3, 4, 5
STATUS = {
    OK: "ok",
    NONFINITE: "nonfinite",
    EVENTS_TRUNCATED: "events_truncated",
    CHATTER: "chatter",
    UNBOUNDED: "unbounded",
    STEP_LIMIT: "step_limit",
}
#: The statuses of a case whose results cannot be used.
FAILURES = (NONFINITE, CHATTER, UNBOUNDED, STEP_LIMIT)


def flag_attributes(names: dict[int, str]) -> tuple[tuple[str, object], ...]:
    """CF ``flag_values`` and ``flag_meanings`` for a numbered vocabulary."""
    return (("flag_values", list(names)), ("flag_meanings", " ".join(names.values())))


CONTACT_FLAGS = flag_attributes({n: c.meaning for n, c in CONFIGURATIONS.items()})
EVENT_FLAGS = flag_attributes(EVENT_KINDS)
STATUS_FLAGS = flag_attributes(STATUS)
