"""The default structure (:func:`misfit_terms`): a model's own terms, and in the DOFs where
they misfit the data, the library terms the data select.

The library search (:func:`.selection.select_terms` on top of the model's terms, all kept,
without memory) gives the held-out residual a sparse model reaches on the same data: our
estimate of the noise floor. A DOF whose held-out R² with the model's terms alone is below a
floor while its unexplained share is several times the library's misfits; the terms the search
added in those DOFs join the model's. Where the vehicle offers element drags
(:func:`element_drags`), :func:`with_element_drags` searches again with them first and each
misfit DOF takes the terms of the search that predicts it better. ``dampest identify``
chooses its structure so, and ``dampest gap`` again at the relative velocity once it has
named a current.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.selection import (
    Selection,
    added_terms,
    row_by_row,
    select_terms,
)
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.point_drag import PointSpec, candidate_points, point_library
from dampest_ros.core.physics.point_lift import candidate_lifts
from dampest_ros.core.physics.rigid_body import ConfigError, RigidBody
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.samples import Samples

FloatArray = NDArray[np.float64]

#: A DOF misfits when its unexplained share with the base's terms is more than this many
#: times the library's …
MISFIT_RATIO = 3.0
#: … and its held-out R² with the base's terms is below this.
MISFIT_FLOOR = 0.999


@dataclass
class Misfit:
    """What :func:`misfit_terms` found.

    Attributes
    ----------
    model : DampingModel
        The base's terms with the library terms added in the misfit DOFs (the base when
        none misfits).
    rows : list of int
        The misfit DOFs (force rows 0..5, X..N).
    added : dict of int to list of str
        The parameters added per misfit row.
    before, after : ndarray, shape (6,)
        Held-out R² per DOF (blocked cross-validation) with the base's terms and with the
        terms added (the library's in every row; after :func:`with_element_drags`, each
        row's chosen search).
    selection : Selection
        The library search itself (its terms in every row).
    drags : Selection or None
        The search with the element drags first (:func:`with_element_drags`), if it ran.
    taken : list of int
        The rows that take that search's terms.
    """

    model: DampingModel
    rows: list[int]
    added: dict[int, list[str]]
    before: FloatArray
    after: FloatArray
    selection: Selection
    drags: Selection | None = None
    taken: list[int] = field(default_factory=list)

    def ratio(self, i: int) -> float:
        """The unexplained share of DOF ``i`` with the base's terms over the library's."""
        return float((1.0 - self.before[i]) / max(1.0 - self.after[i], 1e-12))


def misfit_terms(samples: Samples, base: DampingModel, body: RigidBody, cutoff: float,
                 ratio: float = MISFIT_RATIO, floor: float = MISFIT_FLOOR) -> Misfit | None:
    """The base's terms, and where they misfit ``samples``, the library terms selected there.

    Parameters
    ----------
    samples : Samples
        The data (score nothing else on them: the R² are cross-validated within).
    base : DampingModel
        Terms always kept.
    body : RigidBody
    cutoff : float
        Parallel low-pass of the regression (Hz).
    ratio, floor : float
        A DOF misfits when its held-out R² with the base's terms is below ``floor`` and its
        unexplained share more than ``ratio`` times the library's.

    Returns
    -------
    Misfit or None
        None when the library search does not take the base (a term acting in several rows
        but the ``coriolis`` one: a ``residual`` term).
    """
    try:
        sel = select_terms(samples, base, body, cutoff=cutoff, memory_dofs=(), keep_base=True)
    except ConfigError:
        return None
    before, after = sel.cv_r2
    rows = [i for i in range(6) if before[i] < floor
            and 1.0 - before[i] > ratio * max(1.0 - after[i], 1e-12)]
    added = sel.added(base)
    model = sel.only_in(base, rows) if rows else base
    return Misfit(model, rows, {i: added[i] for i in rows}, before, after, sel)


def element_drags(vehicle: Vehicle) -> list[PointSpec]:
    """The candidate element forces of a vehicle: drags at its geoms off the origin, along
    each geom's own axes (the body axes unless the file rotates it), else at a generic set of
    points along the body axes (:func:`~dampest_ros.core.physics.point_drag.candidate_points`),
    and with a geometry the lift of each slender geom about its long axis and of each flat
    one about its normal, with a flat one's drag on its projected area
    (:func:`~dampest_ros.core.physics.point_lift.candidate_lifts`).

    The Magnus force of an element (``magnus@…``) is not offered: on ``bluerov2_heavy_mujoco``
    (seed 1, noiseless, ``--select``) its lever arm at the bottom geom entered, well determined
    (−3.97 ± 0.02 kg), and the final fit's cut of collinear directions (``max_vif``) then set a
    direction of the ``coriolis`` masses and the library's Coriolis-like products that carries
    the heave force: held-out Z .9785 (.9996 without it); ``frame_rov`` reaches ≥ .995 without
    it."""
    return point_library(candidate_points(vehicle.geometry, vehicle.length),
                         candidate_lifts(vehicle.geometry))


def with_element_drags(found: Misfit, samples: Samples, base: DampingModel, body: RigidBody,
                       cutoff: float, points: Sequence[PointSpec]) -> Misfit:
    """``found`` with the search run again, ``points``' element drags first, and each misfit
    row's terms taken from the search that predicts it better
    (:func:`~dampest_ros.core.identification.selection.row_by_row`).

    Parameters
    ----------
    found : Misfit
        What :func:`misfit_terms` found for ``base`` on ``samples`` (some rows misfit).
    samples, base, body, cutoff
        As given to :func:`misfit_terms`.
    points : sequence of PointSpec
        The candidate element drags (:func:`element_drags`).
    """
    drags = select_terms(samples, base, body, cutoff=cutoff, memory_dofs=(), keep_base=True,
                         points=points)
    chosen, taken = row_by_row(found.selection, drags, base, found.rows)
    # held-out R² of each row's chosen search (its own target's sum of squares)
    after = np.where(np.isin(np.arange(6), taken), drags.cv_r2[1], found.after)
    added = added_terms(chosen, base)
    return replace(found, model=chosen, added={i: added[i] for i in found.rows}, after=after,
                   drags=drags, taken=taken)
