"""compliant: contacts as force elements (Kelvin–Voigt, Hertz), each case through SciPy's
error-controlled integration with the contacts' opening and closing located as events
(``campipe.engine.compliant``). The default integrator's choice for a compliant case."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from campipe.engine.case import Case, CaseError, output_angles
from campipe.engine.integrators.base import CarriedPlungers, RunLike
from campipe.vocabulary import holds_cam, holds_seat

#: Its relative tolerance is run.tolerance, but no finer than this (the default 1e-12,
#: modal-exact's event-time tolerance, is finer than Radau can reach).
RTOL_FLOOR = 1e-10


class Compliant:
    name = "compliant"
    description = "compliant contacts as force elements, error-controlled (SciPy)"
    contacts = "compliant"
    default_step: float | None = None
    fixed_step = False
    unbounded_advice: str | None = None
    fills_outputs = False

    def check(self, cases: Sequence[Case], run: RunLike) -> None:
        """Refuse, for each compliant case, a rigid contact beside a compliant one, and form
        closure."""
        for i, case in enumerate(cases):
            if not case.compliant:
                continue  # another integrator's, in a batch under the default
            law = "cam_contact" if case.train.cam_contact != "rigid" else "seat_contact"
            if case.train.cam_contact == "rigid" or (
                case.has_seat and case.train.seat_contact == "rigid"
            ):
                rigid = "cam_contact" if case.train.cam_contact == "rigid" else "seat_contact"
                raise CaseError.at(
                    rigid,
                    f"case {i} has a rigid {rigid.split('_')[0]} contact beside a compliant "
                    f"{law.split('_')[0]} one: the compliant integrator takes both contacts "
                    f"compliant; set {rigid} to kelvin-voigt or hertz",
                    found="rigid",
                    expected="kelvin-voigt or hertz",
                )
            if case.closure == "form":
                raise CaseError.at(
                    "closure",
                    f"case {i} has form closure with a compliant cam contact: a compliant "
                    "contact never pulls, so the follower is held by the spring: use force",
                    found="form",
                    expected="force",
                )

    def stability_limit(self, case: Case) -> tuple[float, int]:
        return math.inf, 0

    def kernels(self) -> dict[str, Any]:
        return {}  # SciPy's integration: nothing to compile

    def prepare(self, batch: Any, run: RunLike) -> Any:
        rtol = max(float(run.tolerance), RTOL_FLOOR)
        return batch.case_list, output_angles(run), rtol, run.step or math.inf, run.max_steps

    def run(self, prepared: Any, cases: Any, out: Any) -> CarriedPlungers | None:
        """As the protocol's; returns the carried plungers (``engine.plunger``: their table,
        NaN for a case without one, and their extension at the samples), None where no case
        carries one."""
        from campipe.engine import compliant  # SciPy's integration, loaded when first run

        case_list, angles, rtol, max_step, max_steps = prepared
        c = cases
        carried: CarriedPlungers | None = None  # made with the first case that has one
        for i, case in enumerate(case_list):
            seat = float(c.seat_q[i]) if case.has_seat else None
            system = compliant.compliant_system(case.train, case.profile, case.speed, seat)
            held = (holds_cam(int(c.cfg0[i])), holds_seat(int(c.cfg0[i])))
            m = system.load.size  # the train's coordinates of the batch's
            if np.isnan(c.a0[i, 0]):  # the end of its last turn (``settle.run_settled``)
                z0 = np.concatenate([c.q0[i, :m], c.v0[i, :m]])
            else:  # a rigid start, its held contacts compressed
                z0 = compliant.compliant_start(
                    system, c.q0[i, :m], c.v0[i, :m], c.a0[i, :m], *held, float(c.t0[i])
                )
            one = compliant.CaseOutputs(
                out.q[i], out.v[i], out.force[i], out.cam[i], out.cfg[i], out.acc[i],
                out.per_rev[i], out.events[i],
            )  # fmt: skip
            if system.plunger is not None:  # its state starts at 0 in the run's frame
                z0 = np.append(z0, 0.0)
                if carried is None:  # NaN where a case has none, or none in a link
                    carried = CarriedPlungers(
                        np.full((len(case_list), *out.per_rev.shape[1:2], 3), np.nan),
                        np.full(out.cam.shape, np.nan),
                    )
                one.adjuster = carried.table[i]
                one.adjuster[:, 1:] = 0.0
                if system.plunger.gains is None:  # in a chain's link: e₀ + u at the samples
                    one.extension = carried.extension[i]
                    one.extension_start = case.train.hla_extension
            compliant.integrate(
                system, float(c.t0[i]), z0, held, angles / case.speed, one,
                rtol=rtol, max_step=max_step, max_steps=max_steps, capture=float(c.capture[i]),
                lift_bound=float(c.lift_bound[i]), valve_ref=float(c.valve_ref[i]),
            )  # fmt: skip
            out.n_events[i], out.status[i], out.steps[i] = one.n_events, one.status, one.steps
        return carried
