"""The model's parameter error, and the rules across parameters that name a layout: which
layout a key belongs to, what each layout needs, and the named-parameter layouts built over
the lumped chain (``direct-acting``).

Pure Python; :mod:`campipe.model.parameters` calls :func:`resolve_layout` on every train it
resolves (its table and :class:`~campipe.model.parameters.ValveTrain` are its own: this module
reads a train by its attributes only).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from campipe.model.declared import ModelParameterError
from campipe.model.hla import NEEDED as HLA_NEEDED
from campipe.model.levers import CENTRE_PIVOT_ROCKER, LEVER_KEYS, LEVERS, lever_chain

#: Layouts (:mod:`campipe.model.layouts`): the thesis's train from its members' geometry; a
#: chain of masses given directly; a bucket tappet on its valve from named masses and
#: stiffnesses, built as a two-mass chain.
#: The lever layouts (:mod:`campipe.model.levers`), from named geometry and masses, built as
#: two-mass chains in valve-side coordinates driven by their kinematic valve lift.
PUSHROD_ROCKER, LUMPED, DIRECT_ACTING = "pushrod-rocker", "lumped", "direct-acting"
LAYOUTS = (PUSHROD_ROCKER, LUMPED, DIRECT_ACTING, *LEVERS)
#: The layouts that are chains of masses (the lumped chain's coordinates and numerics).
CHAINS = (LUMPED, DIRECT_ACTING, *LEVERS)
#: A direct-acting train's keys, in the order its chain takes them.
DIRECT_ACTING_KEYS = ("tappet_mass", "valve_mass", "stem_stiffness", "tappet_contact_stiffness")
#: The thesis's members' keys end so (with ``ELEMENTS``' names before).
_MEMBER_ENDS = ("_length", "_diameter", "_elements", "_loss_factor", "_mass")


#: Keys more than one layout reads.
_SHARED = {
    "valve_mass": (DIRECT_ACTING, *LEVERS),
    "stem_stiffness": (DIRECT_ACTING, *LEVERS),
}


def layouts_of_key(name: str, members: tuple[str, ...]) -> tuple[str, ...]:
    """The layouts a parameter belongs to (empty: every layout's): the thesis's ``members``'
    geometry, refinement and loss factors and its material to pushrod-rocker, ``masses`` and
    ``stiffnesses`` to lumped, :data:`DIRECT_ACTING_KEYS` to direct-acting, the levers' keys
    (:data:`~campipe.model.levers.LEVER_KEYS`) to both lever layouts; ``valve_mass`` and
    ``stem_stiffness`` to direct-acting and the levers."""
    thesis = name.startswith(members) and name.endswith(_MEMBER_ENDS)
    if thesis or name in ("elastic_modulus", "specific_weight"):
        return (PUSHROD_ROCKER,)
    if name in ("masses", "stiffnesses"):
        return (LUMPED,)
    if name in _SHARED:
        return _SHARED[name]
    if name in DIRECT_ACTING_KEYS:
        return (DIRECT_ACTING,)
    return LEVERS if name in LEVER_KEYS else ()


def layout_of_key(name: str, members: tuple[str, ...]) -> str | None:
    """The first layout a parameter belongs to (None: every layout's; see
    :func:`layouts_of_key`)."""
    owners = layouts_of_key(name, members)
    return owners[0] if owners else None


def resolve_layout(
    train: Any, overrides: Mapping[str, object], members: tuple[str, ...], key_prefix: str = ""
) -> Any:
    """``train`` checked against its layout, and a direct-acting train built as its chain
    (``masses`` and ``stiffnesses`` from its named keys: :func:`direct_acting_chain`).

    Refuses, naming the key: another layout's keys given in ``overrides`` (``damping_kind:
    loss-factor`` on a chain: it needs members), a direct-acting key not given, a chain of one
    mass with lash (its seat and cam would hold one body), ``stiffnesses`` not one fewer than
    ``masses``."""
    for name in overrides:
        owners = layouts_of_key(name, members)
        if name == "damping_kind" and overrides[name] == "loss-factor":
            owners = (PUSHROD_ROCKER,)
        if owners and train.layout not in owners:
            owner = " or ".join(owners)
            raise ModelParameterError.at(
                key_prefix + name,
                f"is a key of layout {owner} but layout is {train.layout}: leave it out or "
                f"set {key_prefix}layout: {owners[0]}",
                found=overrides[name],
                expected=f"no {name} with layout {train.layout}",
            )
    if train.layout == DIRECT_ACTING:
        train = train.replace(**direct_acting_chain(train, key_prefix))
    if train.layout in LEVERS:
        train = train.replace(**lever_chain(train, key_prefix))
    if train.layout in CHAINS:
        _check_chain(train, key_prefix)
    _check_adjuster(train, key_prefix)
    return train


def _check_adjuster(train: Any, key_prefix: str) -> None:
    """A hydraulic lash adjuster (:mod:`campipe.model.hla`) sits in a chain's link next to
    the cam (two masses or more) or under a finger follower's pivot (not a centre-pivot
    rocker's: its pivot is a shaft), with all of its keys and the dry lash it takes up."""
    given = [k for k in HLA_NEEDED if getattr(train, k) == getattr(train, k)]  # not NaN
    if not given:
        if train.hla_extension != 0.0:
            given = ["hla_extension"]
        else:
            return
    key = key_prefix + given[0]
    if train.layout not in CHAINS or len(train.masses) < 2 or train.layout == CENTRE_PIVOT_ROCKER:
        raise ModelParameterError.at(
            key,
            "a hydraulic lash adjuster sits in a chain's link next to the cam or under a finger "
            "follower's pivot: give layout lumped (two masses or more), direct-acting or "
            "finger-follower",
            found=train.layout,
            expected="a chain of two masses or more, or a finger follower",
        )
    for name in (*HLA_NEEDED, "lash"):
        if getattr(train, name) != getattr(train, name):  # NaN: not given
            raise ModelParameterError.at(
                key_prefix + name,
                f"a train with a hydraulic lash adjuster needs {name} ("
                + ", ".join(HLA_NEEDED)
                + ", and lash: the dry lash, the plunger bottomed)",
                found=None,
                expected=f"a value for {name}",
            )
    if train.hla_extension > train.hla_travel:
        raise ModelParameterError.at(
            key_prefix + "hla_extension",
            f"the plunger's extension {train.hla_extension:.6g} m is beyond its travel "
            f"{train.hla_travel:.6g} m",
            found=train.hla_extension,
            expected=f"0 to hla_travel ({train.hla_travel:.6g} m)",
        )


def direct_acting_chain(train: Any, key_prefix: str = "") -> dict[str, tuple[float, ...]]:
    """A bucket tappet on its valve as a two-mass chain: the tappet (with its shim) rides the
    cam, the valve (with its retainer, keepers and the spring's share of mass) meets the seat,
    and between them the tappet's contact on the stem tip and the stem in series,
    k = 1/(1/k_contact + 1/k_stem)."""
    values = [getattr(train, name) for name in DIRECT_ACTING_KEYS]
    for name, value in zip(DIRECT_ACTING_KEYS, values, strict=True):
        if not value > 0.0:  # NaN: not given
            raise ModelParameterError.at(
                key_prefix + name,
                f"layout {DIRECT_ACTING} needs {name} (" + ", ".join(DIRECT_ACTING_KEYS) + ")",
                found=None,
                expected=f"a positive {name}",
            )
    tappet, valve, stem, contact = values
    return {"masses": (tappet, valve), "stiffnesses": (1.0 / (1.0 / contact + 1.0 / stem),)}


def _check_chain(train: Any, key_prefix: str) -> None:
    n = len(train.masses)
    if n < 1:
        raise ModelParameterError.at(
            key_prefix + "masses",
            "found no masses; a lumped chain needs one or more (the first on the cam, the "
            "last the valve; one mass is a rigid direct-acting follower)",
            found=train.masses,
            expected="one or more masses",
        )
    if len(train.stiffnesses) != n - 1:
        raise ModelParameterError.at(
            key_prefix + "stiffnesses",
            f"found {len(train.stiffnesses)} stiffnesses for {n} masses: give one fewer than "
            "masses, the links between neighbours from the cam side",
            found=train.stiffnesses,
            expected=f"{n - 1} stiffnesses",
        )
    if n == 1 and train.lash == train.lash:  # not NaN
        raise ModelParameterError.at(
            key_prefix + "lash",
            "a one-mass chain (a rigid follower that is its valve) has no lash: its cam and "
            "its seat would hold one body; leave lash out (it runs without a seat)",
            found=train.lash,
            expected="no lash with one mass",
        )
