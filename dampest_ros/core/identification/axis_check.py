"""The pure-axis check: does the model's damping along each axis agree with what the samples
flown along that axis show?

Fossen's named coefficients (X_u, X_u|u|, …) are defined along one axis, ν = s e_k. A model
fitted to mixed motion carries a law along each axis, a_k s + b_k s|s|, that the mixed data
only extrapolate to: where the plant's force is not of the model's form near the axis (a
projected area that changes fastest there, a lift that vanishes on it), that law is off by
more than the noise σ says. Where the log flies an axis, this module measures the law there
directly and compares:

- the samples near axis k: |ν_k| ≥ :data:`MOVING` of the DOF's range and the other DOFs'
  speeds, as shares of their ranges, within :data:`CONE` of |ν_k|'s share;
- on them, the least-squares law of the target force y_k on X = [s, s|s|] (the same
  low-pass and decimation as the fit's regression: :func:`iter_entries`), and the model's
  law exactly on the axis, the least-squares law of Φ_k(s e_k) θ at the same samples'
  speeds: the coefficients the model reports, however its terms bend near the axis;
- their difference δ; its covariance: the samples' law's residual variance times (XᵀX)⁻¹
  and the samples' redundancy (n / n_eff), plus the model law's J Σ Jᵀ;
- the Birge ratio R_k = √(δᵀ V⁻¹ δ / 2): above 1 the samples along the axis disagree with
  the model beyond its σ, and the covariance of the parameters of row k is scaled by R_k
  (the Particle Data Group's scale factor: the model form's error, as the data show it, in
  the interval). A DOF flown along its axis by fewer than :data:`MIN_SAMPLES` samples is
  not checked: its pure-axis law is an extrapolation (:attr:`AxisCheck.flown`).

The statistics are sums over samples (:class:`AxisStatistics`): a pooled fit's logs join
them exactly.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.regression import decimation_step, iter_entries
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import RigidBody
from dampest_ros.core.signals.samples import CHUNK, Samples

FloatArray = NDArray[np.float64]

#: Largest speed of the other DOFs, as a share of their ranges, relative to the axis's share.
CONE = 0.05
#: Smallest |ν_k| (share of the DOF's range) of a sample along axis k.
MOVING = 0.05
#: Fewest samples (after the regression's decimation) along an axis for it to be checked.
MIN_SAMPLES = 50


@dataclass
class AxisStatistics:
    """Sums over the samples near each axis (all per DOF k).

    Attributes
    ----------
    XX : ndarray, shape (6, 2, 2)
        Σ x xᵀ, x = (s, s|s|) low-passed (m/s or rad/s, squared).
    Xy : ndarray, shape (6, 2)
        Σ x y_k (y the damping target force, N or N·m).
    yy : ndarray, shape (6,)
        Σ y_k².
    UU : ndarray, shape (6, 2, 2)
        Σ u uᵀ, u = (s, s|s|) as sampled (no low-pass).
    UAxis : ndarray, shape (6, 2, p)
        Σ u Φ_k(s e_k): the model's regressor on the axis itself at the samples' speeds
        (memory states at rest).
    n : ndarray, shape (6,)
        Samples.
    redundancy : float
        Samples per effective sample (n / n_eff ≥ 1) of these decimated, low-passed rows.
    """

    XX: FloatArray
    Xy: FloatArray
    yy: FloatArray
    UU: FloatArray
    UAxis: FloatArray
    n: FloatArray
    redundancy: float

    @staticmethod
    def join(parts: Sequence[AxisStatistics]) -> AxisStatistics:
        """The statistics of all parts' samples."""
        return AxisStatistics(sum((x.XX for x in parts), np.zeros((6, 2, 2))),
                              sum((x.Xy for x in parts), np.zeros((6, 2))),
                              sum((x.yy for x in parts), np.zeros(6)),
                              sum((x.UU for x in parts), np.zeros((6, 2, 2))),
                              np.sum([x.UAxis for x in parts], axis=0),
                              sum((x.n for x in parts), np.zeros(6)),
                              max(x.redundancy for x in parts))


def along_axes(nu: FloatArray, limits: FloatArray) -> NDArray[np.bool_]:
    """Which samples are near which axis, shape (N, 6).

    Parameters
    ----------
    nu : ndarray, shape (N, 6)
        Velocities (m/s, rad/s).
    limits : ndarray, shape (6,)
        Each DOF's range (m/s, rad/s).
    """
    share = np.abs(nu) / limits
    total = np.einsum("ni,ni->n", share, share)
    # ‖others‖² = ‖all‖² − own², within CONE² of own²
    off = np.maximum(total[:, None] - share ** 2, 0.0)
    return np.asarray((share >= MOVING) & (off <= CONE ** 2 * share ** 2))


def axis_statistics(samples: Samples, model: DampingModel, body: RigidBody, cutoff: float,
                    limits: FloatArray, chunk: int = CHUNK) -> AxisStatistics:
    """:class:`AxisStatistics` of ``samples`` (one pass, in chunks).

    Parameters
    ----------
    samples : Samples
    model : DampingModel
    body : RigidBody
    cutoff : float
        The fit's parallel low-pass (Hz; 0: none).
    limits : ndarray, shape (6,)
        Each DOF's range (m/s, rad/s) that :func:`along_axes` takes shares of.
    chunk : int
    """
    p = model.n_params
    out = AxisStatistics(np.zeros((6, 2, 2)), np.zeros((6, 2)), np.zeros(6),
                         np.zeros((6, 2, 2)), np.zeros((6, 2, p)), np.zeros(6), 1.0)
    rest = len(model.memory_rates)

    def columns(nu: FloatArray, states: FloatArray | None) -> FloatArray:
        # s and s|s| of every DOF, low-passed as the target is
        return np.concatenate([nu, nu * np.abs(nu)], axis=1)

    for rows, E, y in iter_entries(samples, model, body, chunk, cutoff, decimate=True,
                                   entries=columns):
        nu = samples.nu[rows]
        near = along_axes(nu, limits)
        for k in np.flatnonzero(near.any(axis=0)):
            m = near[:, k]
            X = E[m][:, [k, 6 + k]]
            out.XX[k] += X.T @ X
            out.Xy[k] += X.T @ y[m, k]
            out.yy[k] += y[m, k] @ y[m, k]
            out.n[k] += m.sum()
            # the model along the axis itself: ν = s e_k at the samples' s
            speed = nu[m, k]
            on_axis = np.zeros((len(speed), 6))
            on_axis[:, k] = speed
            U = np.c_[speed, speed * np.abs(speed)]
            out.UU[k] += U.T @ U
            out.UAxis[k] += U.T @ model.regressor(
                on_axis, np.zeros((len(speed), rest)) if rest else None)[:, k]
    if cutoff > 0:
        # decimated rows come every step samples; the low-pass leaves 2·cutoff per second
        step = decimation_step(samples, cutoff, True)
        out.redundancy = max(1.0, samples.rate / step / (2 * cutoff))
    return out


@dataclass
class AxisCheck:
    """The pure-axis laws the samples show against the model's (per DOF k).

    Attributes
    ----------
    n : ndarray, shape (6,)
        Samples near the axis.
    measured, modelled : ndarray, shape (6, 2)
        (a, b) of a s + b s|s| from the samples' target force and from the model's force on
        the axis at the samples' speeds; NaN where the DOF is not :attr:`flown`.
    std : ndarray, shape (6, 2)
        Standard deviation of their difference.
    ratio : ndarray, shape (6,)
        Birge ratio R_k (NaN where not flown).
    """

    n: FloatArray
    measured: FloatArray
    modelled: FloatArray
    std: FloatArray
    ratio: FloatArray

    @property
    def flown(self) -> NDArray[np.bool_]:
        """DOFs with at least :data:`MIN_SAMPLES` samples along their axis, shape (6,)."""
        return np.asarray(self.n >= MIN_SAMPLES)

    @property
    def scale(self) -> FloatArray:
        """Factor on the σ of each row's parameters: max(1, R_k), 1 where not flown."""
        return np.where(self.flown, np.fmax(self.ratio, 1.0), 1.0)

    def scaled(self, cov: FloatArray, model: DampingModel) -> FloatArray:
        """``cov`` with the parameters of every row k scaled by :attr:`scale` (a parameter
        in several rows by the largest), shape (p, p): D Σ D."""
        rows, params = model.pattern
        d = np.ones(model.n_params)
        np.maximum.at(d, params, self.scale[rows])
        return np.asarray(cov * d[:, None] * d[None, :])


def axis_check(stats: AxisStatistics, theta: FloatArray, cov: FloatArray) -> AxisCheck:
    """Compare the model θ (covariance ``cov``, NaN where held) along each flown axis with
    the law its samples show.

    Parameters
    ----------
    stats : AxisStatistics
    theta : ndarray, shape (p,)
    cov : ndarray, shape (p, p)

    Returns
    -------
    AxisCheck
    """
    nan2 = np.full((6, 2), np.nan)
    out = AxisCheck(stats.n.copy(), nan2.copy(), nan2.copy(), nan2.copy(), np.full(6, np.nan))
    sigma = np.nan_to_num(cov)
    for k in np.flatnonzero(out.flown):
        inv = np.linalg.pinv(stats.XX[k])
        # the samples' law: (XᵀX)⁻¹ Xᵀy; the model's on the axis: J θ, J = (UᵀU)⁻¹ UᵀΦ_k(s e_k)
        direct = inv @ stats.Xy[k]
        J = np.linalg.pinv(stats.UU[k]) @ stats.UAxis[k]
        out.measured[k], out.modelled[k] = direct, J @ theta
        # residual variance of the samples' own law, over the effective samples
        s2 = max(stats.yy[k] - direct @ stats.Xy[k], 0.0) / max(stats.n[k] - 2, 1.0)
        V = s2 * stats.redundancy * inv + J @ sigma @ J.T
        delta = direct - out.modelled[k]
        out.std[k] = np.sqrt(np.diag(V))
        # χ² of δ on its 2 components, over 2: the squared Birge ratio
        out.ratio[k] = np.sqrt(max(float(delta @ np.linalg.pinv(V) @ delta), 0.0) / 2.0)
    return out
