"""The valve spring's element forces and its coil-clash margin from the coordinates.

A spring of n elements (``spring_elements``) is a chain from the cylinder head (ground) up to
the rocker valve end (q4); each element carries the installed preload plus its own
compression, so with n > 1 the force varies along the spring while it surges. Coils clash
when an element has used up its share of ``spring_travel_to_solid``. Pure functions over
arrays of any leading shape.
"""

from __future__ import annotations

import numpy as np

from campipe.model.assembly import assemble, preload_vector
from campipe.model.elements import elements
from campipe.model.lash import reference_preload
from campipe.model.parameters import ValveTrain
from campipe.model.seated import static_state
from campipe.vocabulary import CAM


def spring_extensions(train: ValveTrain, q: np.ndarray) -> np.ndarray:
    """Each spring element's extension (upper node's displacement minus its lower's) [m].

    Parameters
    ----------
    q : (..., n) array
        Coordinates [m, rad] of ``train`` (n = ``train.n_coordinates``).

    Returns
    -------
    (..., n_s) array
        Element 0 sits on the cylinder head, element n_s − 1 under the rocker (q4).
    """
    difference = np.array([e.beta[1] - e.beta[0] for e in elements(train) if e.name == "spring"])
    return np.asarray(q, dtype=float) @ difference.T


def spring_element_forces(train: ValveTrain, q: np.ndarray) -> np.ndarray:
    """Compressive force in each spring element [N]: preload − n·``spring_rate``·extension.

    The last element's is the force on the rocker (the thesis's spring force, preload −
    rate·q4 with one element); the first element's the force on the cylinder head.

    Parameters
    ----------
    q : (..., n) array
        Coordinates [m, rad] of ``train``.

    Returns
    -------
    (..., n_s) array, element 0 on the cylinder head.
    """
    rate = train.spring_rate * train.spring_elements
    return reference_preload(train) - rate * spring_extensions(train, q)


def spring_clash_margin(train: ValveTrain, q: np.ndarray) -> np.ndarray:
    """Coil-clash margin [m]: how far the most compressed element is from solid, as a length
    of the whole spring, n·min_j(travel/n + extension_j) = travel + n·min_j extension_j.

    With one element it is ``spring_travel_to_solid`` − (F − ``spring_preload``)/rate, F the
    spring's force, the travel left before the spring goes solid from its installed length
    (seated: with lash the valve on its seat, without the train's unstressed reference, q4 =
    0); with n elements it is the travel left if every element were as compressed
    as the most compressed one, so a surging spring's local clash shows before the
    average compression reaches solid. Zero or below: the coils clash.

    Parameters
    ----------
    q : (..., n) array
        Coordinates [m, rad] of ``train``.

    Returns
    -------
    array of q's leading shape
    """
    extension = spring_extensions(train, q)
    # with lash, seated the spring stands compressed from the train's unstressed reference by
    # (spring_preload − reference_preload)/rate: its travel is counted from there (installed)
    seated = (train.spring_preload - reference_preload(train)) / train.spring_rate
    return train.spring_travel_to_solid + seated + train.spring_elements * extension.min(axis=-1)


def base_circle_force(train: ValveTrain) -> float:
    """The spring's force [N] on the valve (its element under the rocker or on the valve)
    with the train at rest on the cam's base circle, off any seat: the static state under
    the model's preload with the cam's coordinate held at 0. With lash it is the seated
    train's business (``spring_preload`` is then the seated force); without, the train's
    links give under the preload, so the spring pushes less than ``spring_preload``, the
    force at the unstressed reference: by k/(k + k_spring), k the train's stiffness at the
    valve (a two-link chain's in series)."""
    q = static_state(assemble(train)[1], preload_vector(train), {CAM: 0.0})  # no modes needed
    return float(spring_element_forces(train, q)[-1])
