"""Contact laws at the cam–follower and valve–seat contacts, a law per file behind one
interface (:class:`ContactLaw`), found by name (:func:`contact_law`).

The thesis's contacts are rigid (``rigid``: a contact holds its coordinate, an impact is
perfectly plastic). A compliant contact is a force element of the approach δ [m] (the
penetration of the undeformed surfaces, positive in contact) that never pulls:

- ``kelvin-voigt`` (:mod:`.kelvin_voigt`): F = k·δ + c·δ̇ while positive;
- ``hertz`` (:mod:`.hertz`): F = K·δ^(3/2)·(1 + α·δ̇), Hertz's point contact with Hunt and
  Crossley's damping.

Stiffness from the geometry (``contact_modulus`` E and ``contact_poisson`` ν of both bodies,
E* = E / (2(1 − ν²)), the plane-strain modulus of the pair): a line contact of length w,
k = (π/2)·E*·w; a point contact of relative radius R', K = (4/3)·E*·√R'. The peak contact
pressure (Hertz): a line contact p = √(F'·E*/(π·R')), F' = F/w the force per length; a point
contact p = (6·F·E*²/(π³·R'²))^(1/3). R' = ρ·r/(ρ + r) for a roller of radius r on a cam of
radius of curvature ρ, ρ for a flat-faced follower.
"""

from campipe.model.contact.base import ContactLaw, pair_modulus
from campipe.model.contact.hertz import Hertz, hertz_constant
from campipe.model.contact.kelvin_voigt import KelvinVoigt, line_contact_stiffness
from campipe.model.contact.registry import LAWS, contact_law, law_class, register_law
from campipe.model.contact.rigid import Rigid

__all__ = [
    "LAWS",
    "ContactLaw",
    "Hertz",
    "KelvinVoigt",
    "Rigid",
    "contact_law",
    "hertz_constant",
    "law_class",
    "line_contact_stiffness",
    "pair_modulus",
    "register_law",
]
