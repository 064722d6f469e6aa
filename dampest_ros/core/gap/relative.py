"""The believed model refitted at the relative velocity once a current is named
(:func:`refit_relative`): the current and the damping terms estimated in turn on ν_r, the terms
by the default structure of ``dampest identify`` (the believed ones, and library terms in the
DOFs where they misfit ν_r: :func:`~dampest_ros.core.identification.misfit.misfit_terms`), so
that neither the believed model's error away from the velocities it was fitted on biases the
current nor the written model lacks the terms ν_r needs; the gap it leaves is shown per DOF."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, optimize

from dampest_ros.core.gap.data import GapData, noise_weights
from dampest_ros.core.gap.effects import relative_motion
from dampest_ros.core.identification.batch import Fit, FitOptions, fit
from dampest_ros.core.identification.misfit import misfit_terms, with_element_drags
from dampest_ros.core.identification.regression import accumulate
from dampest_ros.core.identification.validate import force_scores
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.frames import matrix_from_euler
from dampest_ros.core.physics.point_drag import PointSpec
from dampest_ros.core.signals.samples import Samples

FloatArray = NDArray[np.float64]


@dataclass
class RelativeRefit:
    """The believed model refitted at ν_r with the current.

    Attributes
    ----------
    current : ndarray, shape (3,)
        The current (north, east, down; m/s) estimated jointly with the terms.
    model : DampingModel
        The terms refitted: the believed ones and those added at ν_r.
    added : dict of int to list of str
        The library terms added per force row (0..5, X..N) where the believed terms misfit
        ν_r (rows without a misfit absent).
    rounds : int
        Current–terms alternations run (:func:`refit_relative`).
    fit : Fit
        The fit of ``model`` at ν_r on the training part (θ, σ, what the data did not
        determine).
    r2_before, r2_after : ndarray, shape (6,)
        Held-out R² per DOF of the damping force: the believed model at the measured ν, the
        refit at ν_r.
    rms_before, rms_after : ndarray, shape (6,)
        Held-out residual RMS per DOF (N, N·m), same models.
    """

    current: FloatArray
    model: DampingModel
    added: dict[int, list[str]]
    rounds: int
    fit: Fit
    r2_before: FloatArray
    r2_after: FloatArray
    rms_before: FloatArray
    rms_after: FloatArray


def relative_samples(samples: Samples, v_c: FloatArray) -> Samples:
    """``samples`` as seen in water moving with the current ``v_c`` (north, east, down; m/s):
    ν_r = ν − [Rᵀv_c; 0] and ν̇_r = ν̇ − ν̇_c.

    The rigid-body terms M_RB ν̇ + C_RB(ν)ν are unchanged by this for a constant current
    (Fossen 2011, property 8.1), so the regression on these samples is the equation with
    M_A, C_A and D acting on ν_r."""
    nu_r, nu_c_dot = relative_motion(samples.nu, matrix_from_euler(samples.euler),
                                     np.asarray(v_c, dtype=float))
    return replace(samples, nu=nu_r, nu_dot=samples.nu_dot - nu_c_dot)


def _profile(data: GapData, model: DampingModel, v_c: FloatArray, w: FloatArray) -> float:
    """Σ_i log RSS_i of the weighted least-squares fit of ``model`` at ν_r on the training
    part (the stacked Gaussian likelihood, up to constants)."""
    train = relative_samples(data.samples.take(data.train), v_c)
    ne = accumulate(train, model, data.body, folds=1, chunk=data.chunk, cutoff=data.cutoff)
    A, b, _ = ne.total(w)
    d = np.sqrt(np.maximum(np.diag(A), 1e-300))
    theta = linalg.lstsq(A / np.outer(d, d), b / d, cond=1e-10)[0] / d
    return float(np.sum(np.log(np.maximum(ne.rss(theta), 1e-300))))


def _current(data: GapData, model: DampingModel, v_c: FloatArray, w: FloatArray,
             step: float, tol: float) -> FloatArray:
    """The horizontal current that minimises :func:`_profile` for ``model``, from ``v_c``
    (Nelder–Mead from a simplex of ``step`` m/s to ``tol`` m/s); the down component kept."""
    def cost(x: FloatArray) -> float:
        return _profile(data, model, np.array([x[0], x[1], v_c[2]]), w)

    simplex = v_c[:2] + np.array([[0.0, 0.0], [step, 0.0], [0.0, step]])
    res = optimize.minimize(cost, v_c[:2], method="Nelder-Mead",
                            options={"initial_simplex": simplex, "xatol": tol,
                                     "fatol": 1e-6, "maxfev": 80})
    return np.array([res.x[0], res.x[1], v_c[2]])


def _prior(model: DampingModel, theta: FloatArray, chosen: DampingModel) -> FloatArray:
    """θ of ``chosen``: ``model``'s values by name, 0 for a term ``model`` lacks."""
    values = dict(zip(model.parameter_names, theta.tolist(), strict=True))
    return np.array([values.get(n, 0.0) for n in chosen.parameter_names])


def refit_relative(data: GapData, model: DampingModel, theta: FloatArray, v_c: FloatArray,
                   r: FloatArray | None = None, step: float = 0.02, tol: float = 5e-4,
                   rounds: int = 3, points: Sequence[PointSpec] = ()) -> RelativeRefit:
    """Refit ``model`` at ν_r, its terms chosen again there, jointly with the horizontal
    current.

    In turn, up to ``rounds`` times: the current given the terms, by minimising the training
    profile likelihood Σ_i log RSS_i (θ solved by weighted least squares for every current;
    Nelder–Mead from a simplex of ``step`` m/s to ``tol`` m/s); the terms given the current,
    ``model``'s and library terms where they misfit the training rows at ν_r
    (:func:`~dampest_ros.core.identification.misfit.misfit_terms`, with ``points``' element
    drags as ``dampest identify`` chooses them). It stops when the terms
    repeat or the current moves less than 2 ``tol``. θ is then fitted at that current by the
    identification's batch fit (:func:`dampest_ros.core.identification.batch.fit`, default
    options at the gap's low-pass, ``theta`` as the value of what the data do not
    determine, 0 for an added term) and scored on the held-out part, which neither the
    current, the terms nor θ saw.

    Parameters
    ----------
    data : GapData
    model : DampingModel
        The damping terms to refit (the believed model's, with any the gap added).
    theta : ndarray, shape (p,)
        Their values before (the prior of what the data do not determine).
    v_c : ndarray, shape (3,)
        The current named (north, east, down; m/s); the down component is kept.
    r : ndarray, shape (N, 6), optional
        The residual the named effects leave (N, N·m): its training part sets the per-DOF
        weights 1/σ_i² of the profile (the noise, not the gap the current explains).
        Default: the believed model's residual.
    rounds : int
        Most choices of the terms (0: ``model``'s terms only).
    points : sequence of PointSpec
        The vehicle's candidate element drags
        (:func:`~dampest_ros.core.identification.misfit.element_drags`); none by default.

    Returns
    -------
    RelativeRefit
    """
    w = noise_weights(data.r0 if r is None else r, data.train)
    current = _current(data, model, np.asarray(v_c, dtype=float), w, step, tol)
    chosen, added, done = model, {}, 0
    while done < rounds:
        train = relative_samples(data.samples, current).take(data.train)
        found = misfit_terms(train, model, data.body, data.cutoff)
        if found is not None and found.rows and points:
            found = with_element_drags(found, train, model, data.body, data.cutoff, points)
        if found is None or found.model.parameter_names == chosen.parameter_names:
            break
        chosen, added, done = found.model, found.added, done + 1
        previous, current = current, _current(data, chosen, current, w, step, tol)
        if np.hypot(*(current - previous)[:2]) < 2 * tol:
            break
    rel = relative_samples(data.samples, current)
    result = fit(rel.take(data.train), chosen, data.body, FitOptions(cutoff=data.cutoff),
                 prior=_prior(model, theta, chosen))
    test = data.samples.take(data.test)
    before = force_scores(test, data.model, data.body, data.theta, data.cutoff)
    after = force_scores(rel.take(data.test), chosen, data.body, result.theta, data.cutoff)
    return RelativeRefit(current, chosen, added, done, result, before["nse"],
                         after["nse"], before["rmse"], after["rmse"])
