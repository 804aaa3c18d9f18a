"""Member loads and the valve spring's histories from the coordinates, and their per-turn
extremes.

Element end forces are Kₑ·β·q (thesis Eqs. 2, 7, 8); these are the histories a scene asks for
(thesis Figures 37–39). A refined member's load is taken from the element at the thesis's
place: the pushrod's and the stem's at their upper ends (q2, q4), the spring's on the rocker,
the rocker's moment at the pivot on the valve side. Pure functions over arrays of any leading
shape.
"""

from __future__ import annotations

import numpy as np

from campipe.constants import TWO_PI
from campipe.model import ValveTrain, spring_clash_margin, spring_element_forces
from campipe.model.elements import Element, elements
from campipe.model.lash import reference_preload

#: name → (long name, units)
MEMBER_LOADS = {
    "pushrod_force": ("pushrod axial force, compressive positive", "N"),
    "stem_force": ("valve stem axial force, compressive positive", "N"),
    "spring_force": ("valve spring force on the rocker, compressive positive", "N"),
    "rocker_moment": ("rocker arm bending moment at the pivot, valve side", "N m"),
}
#: The spring's histories besides ``spring_force`` (name → (long name, units)): with one
#: element the largest element force is the spring force.
SPRING_HISTORIES = {
    "max_spring_element_force": (
        "largest compressive force along the valve spring (its most loaded element)",
        "N",
    ),
    "spring_clash_margin": (
        "valve spring coil-clash margin: travel left before the most compressed element goes "
        "solid, as a length of the whole spring",
        "m",
    ),
}
#: Turns [-] by which an output angle may fall short of a turn's start and still count to it
#: (as the kernels' ``common.TURN_GUARD``).
TURN_GUARD = 1e-9


def _own(train: ValveTrain, q: np.ndarray) -> np.ndarray:
    """q's first ``train.n_coordinates`` coordinates: a batch of larger trains pads the rest."""
    return np.asarray(q, dtype=float)[..., : train.n_coordinates]


def _members(train: ValveTrain) -> dict[str, list[Element]]:
    """``train``'s elements by member, each member's in order from its first end."""
    members: dict[str, list[Element]] = {}
    for e in elements(train):
        members.setdefault(e.name, []).append(e)
    return members


def _end_forces(q: np.ndarray, e: Element) -> np.ndarray:
    """(..., n_e): the forces on element ``e``'s ends, Kₑ·β·q."""
    return q @ (e.stiffness @ e.beta).T


def _link_forces(q: np.ndarray, links: list[Element], extension) -> list[np.ndarray]:
    """A chain's links' compressive forces, its adjuster's plunger at ``extension`` [m] (each
    sample's, or None): the adjuster in series with the link next to the cam lengthens it,
    its force k·(x₁ − x₂ + e), k the link's stiffness with the adjuster's in series."""
    forces = [-_end_forces(q, e)[..., 1] for e in links]
    if extension is not None and links:
        forces[0] = forces[0] + float(links[0].stiffness[0, 0]) * np.asarray(extension)
    return forces


def member_loads(train: ValveTrain, q: np.ndarray, extension=None) -> dict[str, np.ndarray]:
    """Member loads for coordinates ``q`` (..., n) [m, rad] of ``train`` (n ≥ its
    coordinates, any beyond them ignored), a chain's adjuster's plunger at ``extension`` [m]
    (q's leading shape, or None: none in its link; ``BatchResult.extension``).

    Returns
    -------
    dict
        ``pushrod_force``, ``stem_force``, ``spring_force`` [N] and ``rocker_moment`` [N·m],
        each of q's leading shape; for a lumped chain the pushrod's and the stem's are its
        links' next to the cam and to the valve, and it has no rocker (NaN).
    """
    q = _own(train, q)
    members = _members(train)

    def end_forces(e: Element) -> np.ndarray:
        return _end_forces(q, e)

    # Axial elements use (lower, upper) measured upward: the upper end force is the tension.
    if train.chain:  # its links next to the cam and to the valve (none: one mass)
        none = np.full(q.shape[:-1], np.nan)
        links = _link_forces(q, members.get("link", []), extension)
        return {
            "pushrod_force": links[0] if links else none,
            "stem_force": links[-1] if links else none,
            "spring_force": reference_preload(train) - end_forces(members["spring"][-1])[..., 1],
            "rocker_moment": none,
        }
    return {
        "pushrod_force": -end_forces(members["pushrod"][-1])[..., 1],
        "stem_force": -end_forces(members["valve_stem"][-1])[..., 1],
        "spring_force": reference_preload(train) - end_forces(members["spring"][-1])[..., 1],
        # The rocker's valve arm starts at the pivot: its first element's θ1 end moment.
        "rocker_moment": end_forces(members["rocker_valve_arm"][0])[..., 2],
    }


def pushing_joints(train: ValveTrain, q: np.ndarray, extension=None) -> np.ndarray:
    """(..., n_joints) the forces [N], compressive positive, through the joints of ``train``
    that in the hardware can only push, for coordinates ``q`` (..., n): a chain's links (a
    tappet's, a finger's or a rocker's contact on the valve's tip, in series with what the
    link lumps); the thesis train's pushrod at both ends (each sits in a cup) and its rocker
    on the valve's tip (the valve arm's end force at q4, where the stem and the spring meet
    it). The model's joints are two-sided: a value below 0 is a pull the hardware would not
    give (docs/model.md, "Joints that pull"). Not the thesis's stem: it holds the valve's head
    on its seat against the spring, in tension."""
    q = _own(train, q)
    members = _members(train)

    def end_forces(e: Element) -> np.ndarray:
        return _end_forces(q, e)

    # Axial elements use (lower, upper) measured upward: the upper end force is the tension,
    # the lower end's the compression.
    if train.chain:
        joints = _link_forces(q, members.get("link", []), extension)
    else:
        rod = members["pushrod"]
        joints = [
            end_forces(rod[0])[..., 0],
            -end_forces(rod[-1])[..., 1],
            end_forces(members["rocker_valve_arm"][-1])[..., 1],  # v at the valve end: down
        ]
    if not joints:  # a one-mass chain: its only contact is the cam's
        return np.full((*q.shape[:-1], 0), np.nan)
    return np.stack(joints, axis=-1)


def spring_histories(train: ValveTrain, q: np.ndarray) -> dict[str, np.ndarray]:
    """The spring's largest element force [N] and its coil-clash margin [m]
    (``campipe.model.spring_element_forces``, ``spring_clash_margin``) for coordinates ``q``
    (..., n) of ``train``, each of q's leading shape."""
    q = _own(train, q)
    return {
        "max_spring_element_force": spring_element_forces(train, q).max(axis=-1),
        "spring_clash_margin": spring_clash_margin(train, q),
    }


def per_turn(history: np.ndarray, cam_angle: np.ndarray, n_rev: int, how: str) -> np.ndarray:
    """Each turn's largest (``how`` "max") or least ("min") value of a history sampled at the
    output angles ``cam_angle`` (n_out,) [rad]: (..., n_out) → (..., n_rev). A sample on a
    turn's start counts to that turn; the run's last sample (the end of its last turn) to the
    last turn. NaN where a turn has no sample or a failed case's history is NaN."""
    turn = np.minimum(np.floor(cam_angle / TWO_PI + TURN_GUARD).astype(np.int64), n_rev - 1)
    reduce = np.max if how == "max" else np.min
    out = np.full((*history.shape[:-1], n_rev), np.nan)
    for r in range(n_rev):
        take = turn == r
        if take.any():
            out[..., r] = reduce(history[..., take], axis=-1)
    return out


def sample_turns(theta: np.ndarray, first: int = 0) -> np.ndarray:
    """(n_out,) the turn (from 0) of each sample at cam angle ``theta`` [rad] from the recorded
    window's start, turn ``first``: a turn's end sample is its own, not the next's."""
    n_hist = max(int(np.ceil(theta[-1] / TWO_PI - 1e-9)), 1)
    return first + np.minimum(np.floor(theta / TWO_PI + 1e-9).astype(np.int64), n_hist - 1)


def turn_maxima(
    force: np.ndarray, ratio: np.ndarray, theta: np.ndarray, largest: np.ndarray, first: int = 0
) -> np.ndarray:
    """(n_turns,) each turn's largest force × ratio, a force [N] weighted by a ``ratio`` that
    changes over the turn (a lever's ratio: the roller's normal force,
    ``engine.levers.at_the_cam``; 1/R': the Hertz pressure's F/R'), to the samples'
    resolution: the larger of the samples' largest ``force`` × ``ratio`` and the engine's
    per-turn ``largest`` force (exact, between the samples) × the ratio at the sample of the
    turn's largest sampled force. ``force`` and ``ratio`` at the samples' cam angles
    ``theta`` [rad] from the recorded window's start, turn ``first``; a turn with no samples
    takes the ratio at the window's largest force. The largest F·r may sit on another hump
    of F than F's largest, and r changes by |dr/dθ|·Δθ between samples."""
    out = np.asarray(largest, float).copy()
    valid = np.isfinite(force)
    if not valid.any():
        return out
    turn = sample_turns(theta, first)
    overall = ratio[np.nanargmax(np.where(valid, force, -np.inf))]
    for k in range(out.size):
        if not out[k] > 0.0:  # never on the cam, or a failed case's NaN
            continue
        here = (turn == k) & valid
        if not here.any():
            out[k] = largest[k] * overall
            continue
        j = np.argmax(np.where(here, force, -np.inf))
        # (NaN in a ratio carries: an undercut cam's pressure; the builtin max would drop it)
        out[k] = np.maximum(largest[k] * ratio[j], np.max((force * ratio)[here]))
    return out
