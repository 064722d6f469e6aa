"""Frequency-domain identification of fluid memory (D_freq) from broadband data.

With a model of the static damping fitted, the force it leaves unexplained in DOF i is, for
fluid memory, F(ω) = Z(ω) ν_i(ω) with the impedance Z(ω) = Σ_m c_m / (λ_m + iω) (the Fourier
transform of K(t) = Σ_m c_m e^{−λ_m t}). Z is estimated from Welch cross-spectra,
Ẑ = S_{ν r} / S_{ν ν}, and a rational function is fitted to it by nonlinear least squares,
weighted by the coherence. Protocol C (multisine 0.1–10 Hz) is designed for this.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.regression import iter_regression
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import RigidBody
from dampest_ros.core.signals.samples import Samples

FloatArray = NDArray[np.float64]


@dataclass
class ImpedanceFit:
    """Rational fit of a memory impedance.

    Attributes
    ----------
    rate : float
        λ (1/s).
    gain : float
        c (N·s⁻¹ per m/s, or the DOF's units).
    offset : float
        Real constant d taken up by the static damping already in the model.
    f : ndarray, shape (F,)
        Frequencies used (Hz).
    z : ndarray of complex, shape (F,)
        Estimated impedance Ẑ at f.
    coherence : ndarray, shape (F,)
    """

    rate: float
    gain: float
    offset: float
    f: FloatArray
    z: NDArray[np.complex128]
    coherence: FloatArray


def memory_impedance(samples: Samples, model: DampingModel, body: RigidBody,
                     theta: FloatArray, dofs: Sequence[int], window: float = 40.0,
                     band: tuple[float, float] = (0.03, 1.0)) -> list[ImpedanceFit]:
    """Estimate Z(ω) of each DOF in ``dofs`` from the residual of ``model`` and fit
    c/(λ + iω) − d, in one pass over the regression.

    Parameters
    ----------
    samples : Samples
        Broadband data (protocol C), uniform segments.
    model, theta : DampingModel, ndarray shape (p,)
        The static model fitted to the same data (without the memory term).
    body : RigidBody
    dofs : sequence of int
        0..5.
    window : float
        Welch segment length (s).
    band : tuple of float
        Frequency range (Hz) of the fit.

    Returns
    -------
    list of ImpedanceFit
        One per DOF of ``dofs``.
    """
    idx = np.asarray(dofs, dtype=np.int64)
    rate = samples.rate
    r = np.empty((len(samples), len(idx)))
    for sl, Phi, y in iter_regression(samples, model, body):
        # residual force r = y − Φθ, unfiltered: the spectra do the band limiting
        r[sl] = y[:, idx] - Phi[:, idx, :] @ theta
    nper = min(int(window * rate), min(sl.stop - sl.start for sl in samples.segments()))
    return [_rational_fit(samples, samples.nu[:, d], r[:, k], nper, band)
            for k, d in enumerate(idx)]


def _rational_fit(samples: Samples, nu: FloatArray, r: FloatArray, nper: int,
                  band: tuple[float, float]) -> ImpedanceFit:
    """Welch estimate of Z(ω) = S_{ν r} / S_{ν ν} of one DOF and its fit c/(λ + iω) − d."""
    from scipy import optimize, signal  # slow to import: only where memory is tested

    rate = samples.rate
    s_vr = np.zeros(nper // 2 + 1, dtype=complex)
    s_vv = np.zeros(nper // 2 + 1)
    s_rr = np.zeros(nper // 2 + 1)
    for sl in samples.segments():
        if sl.stop - sl.start < nper:
            continue
        f, p_vr = signal.csd(nu[sl], r[sl], fs=rate, nperseg=nper)
        s_vr += p_vr
        s_vv += signal.welch(nu[sl], fs=rate, nperseg=nper)[1]
        s_rr += signal.welch(r[sl], fs=rate, nperseg=nper)[1]
    m = (f >= band[0]) & (f <= band[1]) & (s_vv > 0)
    z = s_vr[m] / s_vv[m]  # H1 estimate Ẑ = S_{v r} / S_{v v} (scipy: S_xy = E[X* Y])
    coh = np.abs(s_vr[m]) ** 2 / np.maximum(s_vv[m] * s_rr[m], 1e-300)
    w = 2 * np.pi * f[m]
    weight = np.sqrt(coh / np.maximum(1 - coh, 1e-3))

    def residual(x: FloatArray) -> FloatArray:
        c, log_lam, d = x
        model_z = c / (np.exp(log_lam) + 1j * w) - d
        e = (z - model_z) * weight
        return np.concatenate([e.real, e.imag])

    # start from the frequency where −Im Z peaks (at ω = λ for a single pole)
    k = int(np.argmax(-z.imag)) if np.any(z.imag < 0) else len(w) // 2
    lam0 = max(float(w[k]), 1e-2)
    x0 = np.array([-2 * float(z.imag[k]) * lam0, np.log(lam0), 0.0])
    sol = optimize.least_squares(residual, x0, method="lm")
    c, log_lam, d = sol.x
    return ImpedanceFit(float(np.exp(log_lam)), float(c), float(d), f[m], z, coh)
