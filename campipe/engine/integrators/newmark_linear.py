"""newmark-linear: the thesis's algorithm (Appendix B), linear acceleration over a fixed
step, contacts switched at the step ends (``campipe.engine.newmark``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from campipe.constants import TWO_PI
from campipe.engine.case import (
    Case,
    RunSettingsError,
    configuration_omega_max,
    visited_configurations,
)
from campipe.engine.integrators.base import RunLike
from campipe.model.assembly import NEWMARK_LINEAR_OMEGA_DT
from campipe.vocabulary import N_COORDINATES


class NewmarkLinear:
    name = "newmark-linear"
    description = "the thesis's linear-acceleration algorithm at a fixed step (1 µs default)"
    contacts = "rigid"
    default_step: float | None = 1e-6
    fixed_step = True
    unbounded_advice: str | None = (
        "the step is too large for this case (use a smaller run.dt or modal-exact)"
    )
    fills_outputs = False

    def check(self, cases: Sequence[Case], run: RunLike) -> None:
        """Refuse, naming modal-exact, which runs both: a train of refined members
        (``<member>_elements`` > 1; it integrates the thesis's seven coordinates only), and
        one with a coefficient of restitution (it applies the thesis's plastic impacts
        only)."""
        refined = sorted({c.train.n_coordinates for c in cases} - {N_COORDINATES})
        if refined:
            raise RunSettingsError.at(
                "run.integrator",
                f"newmark-linear integrates the thesis's {N_COORDINATES} coordinates only, "
                f"found a train of {refined[-1]} (refined members, <member>_elements > 1); "
                "integrate it with run.integrator: modal-exact",
                found=refined,
                expected=f"{N_COORDINATES} coordinates, or run.integrator: modal-exact",
            )
        for c in cases:
            for name in ("cam_restitution", "seat_restitution"):
                e = getattr(c.train, name)
                if e > 0.0:
                    raise RunSettingsError.at(
                        "run.integrator",
                        f"newmark-linear applies the thesis's plastic impacts only, found "
                        f"{name} {e:g}; integrate it with run.integrator: modal-exact, or set "
                        f"model.{name}: 0",
                        found=e,
                        expected=f"{name} 0, or run.integrator: modal-exact",
                    )

    def stability_limit(self, case: Case) -> tuple[float, int]:
        """√12/ω_max over the configurations a case can visit (thesis Appendix B)."""
        omega_max = configuration_omega_max(case.train)
        worst = max(visited_configurations(case), key=lambda c: omega_max[c - 1])
        return float(NEWMARK_LINEAR_OMEGA_DT / omega_max[worst - 1]), worst

    def kernels(self) -> dict[str, Any]:
        """Its step, and the quasi-static state its first run compiles through (a short
        quasi-static run, ``campipe.engine.kernels.compile_kernels``)."""
        from campipe.engine import contact, newmark

        return {
            "quasi-static state": contact.quasi_static_batch,
            "newmark-linear": newmark.newmark_linear_batch,
        }

    def prepare(self, batch: Any, run: RunLike) -> Any:
        from campipe.engine import newmark  # the compiled kernel, loaded when first run

        preps, which = batch.preps, batch.which
        trains = newmark.NewmarkTrains(
            M=np.stack([p.matrices.mass for p in preps])[which],
            C=np.stack([p.matrices.damping for p in preps])[which],
            K=np.stack([p.matrices.stiffness for p in preps])[which],
            load=np.stack([p.matrices.preload for p in preps])[which],
            step_A=np.stack([p.step_A for p in preps])[which],
            step_G=np.stack([p.step_G for p in preps])[which],
        )
        omega = batch.cases.omega
        dt = np.full(len(which), run.step)
        t_end = run.recorded_revolutions * TWO_PI / omega
        n_steps = np.ceil(t_end / dt - 1e-9)
        runs = newmark.NewmarkRuns(dt, n_steps.astype(np.int64), float(run.output_every), t_end)
        return trains, batch.packed, runs

    def run(self, prepared: Any, cases: Any, out: Any) -> None:
        from campipe.engine import newmark

        trains, packed, runs = prepared
        contact = np.zeros(1, newmark.CONTACT_STATE)
        newmark.newmark_linear_batch(cases, trains, packed, runs, out, newmark.make_work(), contact)
