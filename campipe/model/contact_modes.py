"""A compliant contact as the train feels it: its stiffness and damping at the static load it
carries, on the valve side, and the natural frequencies of the train it closes.

A contact law (:mod:`campipe.model.contact`) acts along its own approach δ: at the cam, the
roller's for a lever layout, whose engine coordinates are the valve side's. With the lever
ratio r (the valve's travel per unit of the roller's), δ = δ_valve / r and the valve side
feels F / r, so a stiffness k at the roller is k / r² at the valve (as
``engine.compliant``'s ``at_roller`` applies it). A nonlinear law (hertz) is linearised at
the static load, the spring's preload as the valve leaves its seat: the seat's that, the
cam's that through the train's ratio (a lever's rest ratio, the thesis's rocker's arm
ratio ``lash_ratio``, 1 for a chain); its tangent stiffness and damping there, dF/dδ and
dF/dδ̇ at δ̇ = 0.

The frequencies are the train's with that contact a spring to ground at its coordinate (q1
for the cam, q7 for the seat) and the other contact open: the frequencies a run with the
contact closed rings at, where the rigid model's are those of the train with q1 held. Each
has its modal damping ratio, φᵀCφ/(2ω) with the contact's dashpot in C (the damping
matrix's diagonal in those modes: exact for one mass, the usual estimate for more).

How hard a landing rebounds: the contact's own damping ratio against the mass an impulse at
its coordinate meets (the rest of the train free: M_pp − M_pf·M_ff⁻¹·M_fp, the rigid
model's impact mass), ζ = c/(2·√(k·m)) on the valve side, and for a linear law the
coefficient of restitution of that mass landing on it (:func:`released_restitution`: the
contact releases where its force reaches zero, not where δ does): the contact's own, as a
contact model defines it, the links' and the spring's forces during the contact left out (a
train's landing rebounds less where a preload acts over the contact's tens of µs); a hertz
law's depends on the landing's speed (Hunt and Crossley: e ≈ 1 − 2·α·v/3) and is not given.

Pure numerics: a train and its matrices in, numbers out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from campipe.model.assembly import SystemMatrices, normal_modes
from campipe.model.checks import PUSHROD_ROCKER
from campipe.model.contact import contact_law
from campipe.model.landing import released_restitution, struck_at
from campipe.model.lash import lash_ratio
from campipe.model.layouts import own_matrices, used_coordinates


@dataclass(frozen=True)
class ContactMode:
    """One compliant contact, linearised at its static load (see the module)."""

    contact: str  # "cam" or "seat"
    law: str  # the law's name
    load: float  # the static force it carries, at the contact [N]
    stiffness: float  # dF/dδ there, at the contact [N/m]
    damping: float  # dF/dδ̇ there [N·s/m]
    ratio: float  # r: the valve's travel per the contact's (1 but for a lever's cam)
    frequencies: np.ndarray  # the train's with the contact closed, ascending [rad/s]
    damping_ratios: np.ndarray  # their modal damping ratios, φᵀCφ/(2ω) [1]
    #: the mass an impulse at the contact's coordinate meets (a lever's cam: valve side) [kg]
    struck_mass: float
    linear: bool  # the law is linear (its restitution a number)

    @property
    def valve_side_stiffness(self) -> float:
        """k / r² [N/m]: the stiffness the engine's coordinate feels."""
        return self.stiffness / self.ratio**2

    @property
    def valve_side_damping(self) -> float:
        """c / r² [N·s/m]."""
        return self.damping / self.ratio**2

    @property
    def contact_damping_ratio(self) -> float:
        """ζ = c/(2·√(k·m)) of the struck mass on the contact alone (at its coordinate: k/r²,
        c/r² for a lever's cam)."""
        return self.valve_side_damping / (
            2.0 * math.sqrt(self.valve_side_stiffness * self.struck_mass)
        )

    @property
    def restitution(self) -> float:
        """The struck mass's coefficient of restitution on a linear law
        (:func:`released_restitution`); on a nonlinear one 1 undamped, else NaN (it depends
        on the landing's speed)."""
        if self.linear:
            return released_restitution(self.contact_damping_ratio)
        return 1.0 if self.damping == 0.0 else math.nan


def contact_modes(train, sm: SystemMatrices) -> list[ContactMode]:
    """Each compliant contact of ``train`` (none for rigid ones), linearised at its static
    load; a lever's cam contact at its roller, the lever ratio r the rest ratio
    (:func:`campipe.model.levers.rest_ratio`). A one-mass chain's valve is its follower: both
    contacts act on q1."""
    used = used_coordinates(train)
    mass, own_stiffness, own_damping = own_matrices(train, sm.mass, sm.stiffness, sm.damping)
    out = []
    for contact in ("cam", "seat"):
        law = contact_law(train, contact)
        if not law.compliant:
            continue
        struck_by, at, ratio = struck_at(train, mass, contact)
        through = 1.0
        if contact == "cam":  # the preload at the cam: through the train's ratio
            through = lash_ratio(sm) if train.layout == PUSHROD_ROCKER else ratio
        load = train.spring_preload * through
        k, c = law.slopes(law.approach(load), 0.0)
        stiffness, damping = own_stiffness.copy(), own_damping.copy()
        stiffness[at, at] += k / ratio**2
        damping[at, at] += c / ratio**2
        omega, phi = normal_modes(mass, stiffness, np.ones(used.size, bool))
        zeta = np.einsum("ij,ik,kj->j", phi, damping, phi) / (2.0 * omega)
        out.append(
            ContactMode(contact, law.name, load, k, c, ratio, omega, zeta, struck_by, law.linear)
        )
    return out
