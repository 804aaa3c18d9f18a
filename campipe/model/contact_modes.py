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
contact closed rings at, where the rigid model's are those of the train with q1 held.

Pure numerics: a train and its matrices in, numbers out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from campipe.model.assembly import SystemMatrices, normal_modes
from campipe.model.checks import PUSHROD_ROCKER
from campipe.model.contact import contact_law
from campipe.model.lash import lash_ratio
from campipe.model.layouts import mirror, used_coordinates
from campipe.model.levers import LEVERS, rest_ratio
from campipe.vocabulary import CAM, SEAT


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

    @property
    def valve_side_stiffness(self) -> float:
        """k / r² [N/m]: the stiffness the engine's coordinate feels."""
        return self.stiffness / self.ratio**2

    @property
    def valve_side_damping(self) -> float:
        """c / r² [N·s/m]."""
        return self.damping / self.ratio**2


def contact_modes(train, sm: SystemMatrices) -> list[ContactMode]:
    """Each compliant contact of ``train`` (none for rigid ones), linearised at its static
    load; a lever's cam contact at its roller, the lever ratio r the rest ratio
    (:func:`campipe.model.levers.rest_ratio`). A one-mass chain's valve is its follower: both
    contacts act on q1."""
    used = used_coordinates(train)
    cam_ratio = rest_ratio(train) if train.layout in LEVERS else 1.0
    arm = lash_ratio(sm) if train.layout == PUSHROD_ROCKER else cam_ratio
    seat = CAM if mirror(train) else SEAT
    out = []
    for contact, coordinate, ratio, through in (
        ("cam", CAM, cam_ratio, arm),
        ("seat", seat, 1.0, 1.0),
    ):
        law = contact_law(train, contact)
        if not law.compliant:
            continue
        load = train.spring_preload * through
        k, c = law.slopes(law.approach(load), 0.0)
        stiffness = sm.stiffness.copy()
        stiffness[coordinate, coordinate] += k / ratio**2
        sub = np.ix_(used, used)
        omega, _ = normal_modes(sm.mass[sub], stiffness[sub], np.ones(used.size, bool))
        out.append(ContactMode(contact, law.name, load, k, c, ratio, omega))
    return out
