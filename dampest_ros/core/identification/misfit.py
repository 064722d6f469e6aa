"""The default structure (:func:`misfit_terms`): a model's own terms, and in the DOFs where
they misfit the data, the library terms the data select.

The library search (:func:`.selection.select_terms` on top of the model's terms, all kept,
without memory) gives the held-out residual a sparse model reaches on the same data: our
estimate of the noise floor. A DOF whose held-out R² with the model's terms alone is below a
floor while its unexplained share is several times the library's misfits; the terms the search
added in those DOFs join the model's. ``dampest identify`` chooses its structure so, and
``dampest gap`` again at the relative velocity once it has named a current.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.selection import Selection, select_terms
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import ConfigError, RigidBody
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
        library terms added in every row.
    selection : Selection
        The library search itself (its terms in every row).
    """

    model: DampingModel
    rows: list[int]
    added: dict[int, list[str]]
    before: FloatArray
    after: FloatArray
    selection: Selection

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
