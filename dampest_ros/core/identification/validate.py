"""Validation of an identified damping model on data.

Everything here compares the model M ν̇ + C(ν)ν + D(ν)ν + g(η) = τ (FRD body, NED world)
with measured :class:`~dampest_ros.core.signals.samples.Samples`:

- force domain: the damping force the data demand, y = τ − M ν̇ − C(ν)ν − g(η), against
  the model's Φ(ν)θ, with the same parallel low-pass as the fit (:func:`predicted_force`),
  summarised by :func:`metrics`, :func:`residual_whiteness`, :func:`residual_spectrum` and
  :func:`frf_error`;
- velocity domain: a free-run simulation driven by the measured τ and attitude
  (:func:`free_run`, :func:`free_run_error`), which accumulates every force error into a
  velocity error the way a controller or simulator using the model would see it;
- physics: dissipated power νᵀD(ν)ν ≥ 0 on the data (:func:`energy_consistency`).

numpy/scipy only; loops over samples are either chunked (memory flat in the data length)
or, for the free run, a cheap fixed-step RK4 step per sample.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import fft

from dampest_ros.core.identification.regression import iter_regression
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.frames import matrix_from_euler
from dampest_ros.core.physics.rigid_body import ConfigError, RigidBody
from dampest_ros.core.signals.samples import CHUNK, Samples

FloatArray = NDArray[np.float64]

#: z-value of the two-sided 95 % whiteness bound ±1.96/√N.
Z95 = 1.959963984540054


# --- force domain ----------------------------------------------------------------------------


def predicted_force(samples: Samples, model: DampingModel, body: RigidBody,
                    theta: FloatArray, cutoff: float = 0.0, chunk: int = CHUNK
                    ) -> tuple[FloatArray, FloatArray]:
    """Measured and predicted damping force per sample.

    y = τ − M ν̇ − C(ν)ν − g(η) and ŷ = Φ(ν)θ, both from
    :func:`dampest_ros.core.identification.batch.iter_regression`, so with the fit's ``cutoff`` they
    are filtered exactly as the fit saw them (parallel zero-phase low-pass per segment).

    Parameters
    ----------
    samples : Samples
        N samples (FRD/NED).
    model : DampingModel
    body : RigidBody
        M (rigid body + added mass) and restoring data.
    theta : ndarray, shape (p,)
        Damping parameters.
    cutoff : float
        Parallel low-pass (Hz); 0: none.
    chunk : int
        Samples per chunk (memory ∝ chunk · 6 · p).

    Returns
    -------
    y : ndarray, shape (N, 6)
        Damping force demanded by the data (N, N·m).
    y_hat : ndarray, shape (N, 6)
        Model damping force Φθ (N, N·m).
    """
    theta = np.asarray(theta, dtype=float)
    y = np.zeros((len(samples), 6))
    y_hat = np.zeros((len(samples), 6))
    for sl, Phi, yc in iter_regression(samples, model, body, chunk=chunk, cutoff=cutoff):
        y[sl] = yc
        y_hat[sl] = Phi @ theta
    return y, y_hat


def force_scores(samples: Samples, model: DampingModel, body: RigidBody, theta: FloatArray,
                 cutoff: float) -> dict[str, FloatArray]:
    """:func:`metrics` of the damping force on (held-out) samples: y = τ − M ν̇ − C(ν)ν − g(η)
    against the model's D(ν)ν, low-passed as in the fit (``cutoff``, Hz; 0: none).

    Returns
    -------
    dict of str to ndarray, each shape (6,)
        ``nse`` is the per-DOF R², ``rmse`` in N and N·m; see :func:`metrics`.
    """
    y, y_hat = predicted_force(samples, model, body, theta, cutoff)
    return metrics(y, y_hat)


def steady_mask(nu_dot: FloatArray, rate: float, level: float = 0.1,
                min_duration: float = 1.0) -> NDArray[np.bool_]:
    """Samples inside quasi-steady stretches, per DOF.

    Sample n is steady in DOF i when it lies in a run of at least ``min_duration`` seconds
    over which |ν̇_i| ≤ ``level`` · RMS(ν̇_i): the velocity of that DOF is (nearly) constant
    for a while, so the force balance there is damping against thrust and restoring only,
    and inertia (M, hence errors in the added mass) plays no part.

    Parameters
    ----------
    nu_dot : ndarray, shape (N, 6)
        Accelerations (m/s², rad/s²).
    rate : float
        Sample rate (Hz).
    level : float
        Threshold as a fraction of the RMS acceleration of each DOF.
    min_duration : float
        Shortest stretch (s).

    Returns
    -------
    ndarray of bool, shape (N, 6)
    """
    a = np.abs(np.asarray(nu_dot, dtype=float))
    N = a.shape[0]
    rms = np.sqrt(np.mean(a * a, axis=0)) if N else np.zeros(a.shape[1])
    small = a <= level * rms
    L = max(1, round(min_duration * rate))
    if N < L:
        return np.zeros_like(small)
    # window k (samples k..k+L−1) is all small ⇔ its count of small samples is L
    c = np.concatenate([np.zeros((1, a.shape[1]), dtype=np.int64),
                        np.cumsum(small, axis=0, dtype=np.int64)])
    full = (c[L:] - c[:-L]) == L  # (N − L + 1, 6)
    # sample n is covered when a full window starts in [n − L + 1, n]
    cf = np.concatenate([np.zeros((1, a.shape[1]), dtype=np.int64),
                         np.cumsum(full, axis=0, dtype=np.int64)])
    n = np.arange(N)
    hi = np.minimum(n, N - L) + 1
    lo = np.maximum(n - L + 1, 0)
    return np.asarray((cf[hi] - cf[lo]) > 0)


def metrics(y: FloatArray, y_hat: FloatArray, nu_dot: FloatArray | None = None,
            rate: float = 0.0, steady_level: float = 0.1, min_steady: float = 1.0
            ) -> dict[str, FloatArray]:
    """Fit metrics per DOF of a measured series ``y`` and its prediction ``y_hat``.

    With residual r = y − ŷ:

    - ``rmse``: √mean(r²) (units of y);
    - ``nrmse``: RMSE / std(y) (dimensionless; 0 is perfect, 1 is as good as predicting
      the mean);
    - ``nse``: Nash–Sutcliffe efficiency 1 − Σr² / Σ(y − ȳ)², i.e. R² (1 is perfect);
    - ``peak_error``: max |r|, the largest absolute error (units of y);
    - ``bias``: mean(r) over all samples;
    - ``steady_bias``: mean(r) over the quasi-steady stretches of :func:`steady_mask`
      (|ν̇_i| ≤ ``steady_level`` · RMS(ν̇_i) for at least ``min_steady`` s), where the
      force balance excludes inertia; NaN without ``nu_dot`` or when fewer than 10
      samples qualify;
    - ``steady_fraction``: share of samples in such stretches.

    Parameters
    ----------
    y, y_hat : ndarray, shape (N, 6)
        Measured and predicted series (e.g. force in N, N·m, or velocity).
    nu_dot : ndarray, shape (N, 6), optional
        Accelerations that define the steady stretches.
    rate : float
        Sample rate (Hz); needed with ``nu_dot``.
    steady_level, min_steady : float
        See :func:`steady_mask`.

    Returns
    -------
    dict of str to ndarray, each shape (6,)
    """
    y = np.asarray(y, dtype=float)
    r = y - np.asarray(y_hat, dtype=float)
    k = y.shape[1]
    ss = np.einsum("ni,ni->i", r, r)
    dev = y - y.mean(axis=0)
    var = np.einsum("ni,ni->i", dev, dev)
    with np.errstate(invalid="ignore", divide="ignore"):
        rmse = np.sqrt(ss / len(y))
        nrmse = rmse / np.sqrt(var / len(y))
        nse = 1.0 - ss / var
    steady_bias = np.full(k, np.nan)
    steady_fraction = np.zeros(k)
    if nu_dot is not None:
        if rate <= 0:
            raise ConfigError("rate", "metrics need the sample rate with nu_dot")
        m = steady_mask(nu_dot, rate, steady_level, min_steady)
        count = m.sum(axis=0)
        steady_fraction = count / max(len(y), 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            sb = np.where(m, r, 0.0).sum(axis=0) / count
        steady_bias = np.where(count >= 10, sb, np.nan)
    return {"rmse": rmse, "nrmse": nrmse, "nse": nse,
            "peak_error": np.abs(r).max(axis=0) if len(r) else np.full(k, np.nan),
            "bias": r.mean(axis=0), "steady_bias": steady_bias,
            "steady_fraction": np.asarray(steady_fraction, dtype=float)}


@dataclass
class Whiteness:
    """Sample autocorrelation of residuals with the 95 % whiteness bound.

    Attributes
    ----------
    lags : ndarray, shape (L + 1,)
        Lags (s), 0 … max_lag.
    acf : ndarray, shape (L + 1, 6)
        Autocorrelation per DOF (acf[0] = 1).
    bound : float
        ±1.96/√N: for white residuals about 95 % of acf[1:] lie inside.
    fraction_outside : ndarray, shape (6,)
        Share of lags 1 … L with |acf| > bound (≈ 0.05 for white residuals).
    """

    lags: FloatArray
    acf: FloatArray
    bound: float
    fraction_outside: FloatArray


def residual_whiteness(r: FloatArray, rate: float, max_lag: float = 2.0) -> Whiteness:
    """Autocorrelation test of residual whiteness (FFT-based, all DOFs at once).

    Residuals that were low-passed at ``cutoff`` are correlated over ≈ 1/(2 cutoff) by
    construction; decimate them to about 2 · cutoff first (``r[::k]``, ``rate / k``) to test
    whether what remains is white.

    Parameters
    ----------
    r : ndarray, shape (N, 6)
        Residuals.
    rate : float
        Sample rate of ``r`` (Hz).
    max_lag : float
        Largest lag (s).

    Returns
    -------
    Whiteness
    """
    r = np.asarray(r, dtype=float)
    N = r.shape[0]
    if N < 3:
        raise ConfigError("r", f"need at least 3 residual samples, got {N}")
    L = int(min(max(1, round(max_lag * rate)), N - 1))
    x = r - r.mean(axis=0)
    n = fft.next_fast_len(N + L)
    X = fft.rfft(x, n, axis=0)
    # biased autocovariance: acov[k] = Σ_n x_n x_{n+k} / N, no wrap-around since n ≥ N + L
    acov = fft.irfft(X * np.conj(X), n, axis=0)[:L + 1] / N
    with np.errstate(invalid="ignore", divide="ignore"):
        acf = acov / acov[0]
    bound = Z95 / np.sqrt(N)
    outside = np.mean(np.abs(acf[1:]) > bound, axis=0)
    return Whiteness(np.arange(L + 1) / rate, acf, float(bound), np.asarray(outside))


def residual_spectrum(r: FloatArray, rate: float, window: float = 20.0
                      ) -> tuple[FloatArray, FloatArray]:
    """Welch power spectral density of residuals per DOF.

    Parameters
    ----------
    r : ndarray, shape (N, 6)
        Residuals (N or N·m).
    rate : float
        Sample rate (Hz).
    window : float
        Welch segment length (s); frequency resolution ≈ 1/window. Shortened to N samples.

    Returns
    -------
    f : ndarray, shape (F,)
        Frequencies (Hz).
    psd : ndarray, shape (F, 6)
        One-sided PSD ((N)²/Hz, (N·m)²/Hz).
    """
    from scipy import signal  # ~0.4 s to import: only where a spectrum is asked for

    r = np.asarray(r, dtype=float)
    nper = int(min(r.shape[0], max(8, round(window * rate))))
    f, p = signal.welch(r, fs=rate, nperseg=nper, axis=0, detrend="constant")
    return np.asarray(f, dtype=float), np.asarray(p, dtype=float)


@dataclass
class FrfError:
    """Frequency-response comparison of predicted and measured damping force.

    G_i(f) = S_{τ_i ŷ_i}(f) / S_{τ_i y_i}(f): the ratio of the FRFs from thrust to predicted
    and to measured force of DOF i (Welch cross-spectra, thrust as the instrument, so noise
    on y that is uncorrelated with τ averages out). G = 1 is a perfect match.

    Attributes
    ----------
    f : ndarray, shape (F,)
        Frequencies (Hz).
    gain_db : ndarray, shape (F, 6)
        20 log10 |G| (dB); > 0: the model predicts too much force.
    phase_deg : ndarray, shape (F, 6)
        arg G (deg); > 0: the prediction leads the measurement.
    coherence : ndarray, shape (F, 6)
        Coherence γ² between τ_i and y_i.
    band : ndarray of bool, shape (F, 6)
        The excited band: f > 0, f ≤ f_max, τ_i's PSD ≥ 1e-3 of its peak, γ² ≥ the threshold.
    median_gain_db, median_phase_deg : ndarray, shape (6,)
        Medians over the band (NaN where the band is empty).
    """

    f: FloatArray
    gain_db: FloatArray
    phase_deg: FloatArray
    coherence: FloatArray
    band: NDArray[np.bool_]
    median_gain_db: FloatArray
    median_phase_deg: FloatArray


def frf_error(samples: Samples, y: FloatArray, y_hat: FloatArray, rate: float,
              window: float = 20.0, min_coherence: float = 0.5,
              f_max: float | None = None) -> FrfError:
    """Gain and phase error of the predicted damping force in the frequency domain.

    Cross-spectra are averaged over the segments of ``samples`` (each at least one Welch
    window long; with none that long, the window shrinks to the longest segment).

    Parameters
    ----------
    samples : Samples
        Source of τ (N, 6) and of the segments.
    y, y_hat : ndarray, shape (N, 6)
        Measured and predicted damping force (:func:`predicted_force`).
    rate : float
        Sample rate (Hz).
    window : float
        Welch segment length (s).
    min_coherence : float
        γ² threshold of the excited band.
    f_max : float, optional
        Upper end of the band (Hz), e.g. the fit's cutoff.

    Returns
    -------
    FrfError
    """
    from scipy import signal  # ~0.4 s to import: only where a response is asked for

    tau = samples.tau
    segs = list(samples.segments())
    longest = max((s.stop - s.start for s in segs), default=0)
    nper = int(min(longest, max(8, round(window * rate))))
    if nper < 8:
        raise ConfigError("samples", "too few samples for a frequency response")
    S_ty = S_th = S_tt = S_yy = None
    weight = 0.0
    for s in segs:
        if s.stop - s.start < nper:
            continue
        kw = {"fs": rate, "nperseg": nper, "axis": 0, "detrend": "constant"}
        f, a = signal.csd(tau[s], y[s], **kw)
        _, b = signal.csd(tau[s], y_hat[s], **kw)
        _, c = signal.welch(tau[s], **kw)
        _, d = signal.welch(y[s], **kw)
        w = float(s.stop - s.start)
        if S_ty is None:
            S_ty, S_th, S_tt, S_yy = w * a, w * b, w * c, w * d
        else:
            S_ty, S_th, S_tt, S_yy = S_ty + w * a, S_th + w * b, S_tt + w * c, S_yy + w * d
        weight += w
    assert S_ty is not None and S_th is not None and S_tt is not None and S_yy is not None
    f = np.asarray(f, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        G = S_th / S_ty
        coh = np.abs(S_ty) ** 2 / (S_tt * S_yy)
        gain = 20.0 * np.log10(np.abs(G))
    phase = np.degrees(np.angle(G))
    coh = np.nan_to_num(np.real(coh), nan=0.0)
    band = ((f[:, None] > 0) & (S_tt >= 1e-3 * S_tt.max(axis=0)) & (coh >= min_coherence)
            & np.isfinite(gain))
    if f_max is not None:
        band &= f[:, None] <= f_max
    med_g = np.full(6, np.nan)
    med_p = np.full(6, np.nan)
    for i in range(6):  # six DOFs, not samples
        if band[:, i].any():
            med_g[i] = np.median(gain[band[:, i], i])
            med_p[i] = np.median(phase[band[:, i], i])
    return FrfError(f, np.asarray(gain), np.asarray(phase), np.asarray(coh), band, med_g, med_p)


# --- velocity domain: free run ---------------------------------------------------------------


def longest_segment(samples: Samples, max_duration: float | None = None) -> slice:
    """Rows of the longest segment, cut to its first ``max_duration`` seconds."""
    segs = list(samples.segments())
    if not segs:
        raise ConfigError("samples", "no samples")
    s = max(segs, key=lambda x: (x.stop or 0) - (x.start or 0))
    start, stop = s.start or 0, s.stop or 0
    if max_duration is not None and samples.rate > 0:
        stop = min(stop, start + round(max_duration * samples.rate) + 1)
    return slice(start, stop)


def _rows(samples: Samples, segment: int | slice | None) -> slice:
    """Rows of a segment index, a slice inside one segment, or the longest segment."""
    if segment is None:
        return longest_segment(samples)
    if isinstance(segment, slice):
        start, stop, step = segment.indices(len(samples))
        if step != 1 or stop - start < 2:
            raise ConfigError("segment", "need a contiguous slice of at least 2 samples")
        if samples.segment[start] != samples.segment[stop - 1]:
            raise ConfigError("segment", "the rows span a gap between segments")
        return slice(start, stop)
    segs = list(samples.segments())
    if not 0 <= segment < len(segs):
        raise ConfigError("segment", f"index {segment} out of range 0..{len(segs) - 1}")
    return segs[segment]


def free_run(samples: Samples, model: DampingModel, body: RigidBody, theta: FloatArray,
             segment: int | slice | None = None, tau_hold: str = "linear") -> FloatArray:
    """Simulate the velocity the model predicts from the measured thrust and attitude.

    Integrates M ν̇ = τ − C(ν)ν − D(ν)ν − Σ c_m z_m − g(η), ż = −λ z + ν[dof] by RK4,
    sub-stepped where the sample step is too long for the model's stiffness there
    (:func:`rk4_substeps`; a stiff yaw or a fast memory state would otherwise make the
    integration itself diverge), driven by the measured τ and by g(η) of the measured attitude
    (``samples.euler``), from the measured ν at the first row. Memory states start at their
    steady value z = ν[dof]/λ. No current: ν is taken as relative to the water. Nothing
    feeds the measured ν back, so force errors accumulate as velocity errors (damped by the
    dissipation of the model itself).

    Parameters
    ----------
    samples : Samples
    model : DampingModel
    body : RigidBody
    theta : ndarray, shape (p,)
    segment : int or slice, optional
        Segment index, or a slice of rows within one segment (e.g.
        :func:`longest_segment` with ``max_duration``); default: the longest segment.
    tau_hold : {'linear', 'zero'}
        τ between samples: ``linear`` interpolation (τ sampled at the instants, as the
        preprocessing gives it), or ``zero``-order hold of τ_n over [t_n, t_{n+1})
        (τ_n the mean over the step, as :class:`~dampest_ros.core.simulation.trajectory.Trajectory`
        logs it). g(η) is always interpolated linearly.

    Returns
    -------
    ndarray, shape (n, 6)
        Simulated ν (m/s, rad/s) at the n rows of the segment; rows after a divergence
        (non-finite or > 1e6) are NaN.
    """
    if tau_hold not in ("linear", "zero"):
        raise ConfigError("tau_hold", f"use 'linear' or 'zero', got {tau_hold!r}")
    rows = _rows(samples, segment)
    t = samples.t[rows]
    n = len(t)
    theta = np.asarray(theta, dtype=float)
    # precomputed: forcing F = τ − g(η) at the samples and at the midpoints
    g = body.restoring(matrix_from_euler(samples.euler[rows]))
    F = samples.tau[rows] - g
    if tau_hold == "zero":
        F_mid = samples.tau[rows][:-1] - 0.5 * (g[:-1] + g[1:])
        F_end = samples.tau[rows][:-1] - g[1:]
        F_start = F[:-1]
    else:
        F_mid = 0.5 * (F[:-1] + F[1:])
        F_end = F[1:]
        F_start = F[:-1]
    M = body.M
    M_inv = np.linalg.inv(body.M_inertial)
    # the vehicle's added-mass switches: C(ν)ν by the fast form below only when all act
    full_coriolis = body.added_mass_terms.all
    K = model.static_gain(theta)
    c_mem = model.memory_gain(theta)
    lam = model.memory_rates
    dofs = model.memory_dofs
    nm = len(lam)
    alphas = model.alphas

    def rhs(x: FloatArray, Fk: FloatArray) -> FloatArray:
        nu = x[:6]
        a = (M @ nu).tolist()
        u, v, w, p, q, r = nu.tolist()
        # C(ν)ν = [ω × a1, v × a1 + ω × a2] with a = M ν (Fossen 6.43), on Python floats
        cor = np.array([
            q * a[2] - r * a[1], r * a[0] - p * a[2], p * a[1] - q * a[0],
            v * a[2] - w * a[1] + q * a[5] - r * a[4],
            w * a[0] - u * a[2] + r * a[3] - p * a[5],
            u * a[1] - v * a[0] + p * a[4] - q * a[3]]) if full_coriolis \
            else body.coriolis_force(nu)
        # D(ν)ν = (α(ν) K) ν
        d = (alphas(nu[None, :]) @ K).reshape(6, 6) @ nu
        out = np.empty_like(x)
        if nm:
            z = x[6:]
            np.add.at(d, dofs, c_mem * z)
            out[6:] = -lam * z + nu[dofs]
        out[:6] = M_inv @ (Fk - cor - d)
        return out

    def rk4(x: FloatArray, h: float, f0: FloatArray, fm: FloatArray, f1: FloatArray
            ) -> FloatArray:
        k1 = rhs(x, f0)
        k2 = rhs(x + 0.5 * h * k1, fm)
        k3 = rhs(x + 0.5 * h * k2, fm)
        k4 = rhs(x + h * k3, f1)
        return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

    steps = rk4_substeps(samples.nu[rows], np.diff(t), model, body, theta)
    nu0 = samples.nu[rows.start]
    x = np.concatenate([nu0, nu0[dofs] / lam if nm else np.zeros(0)])
    out = np.full((n, 6), np.nan)
    out[0] = nu0
    limit = 1e6
    with np.errstate(over="ignore", invalid="ignore"):  # a divergence is caught below
        _integrate(rk4, x, t, steps, (F_start, F_mid, F_end), out, limit)
    return out


def _integrate(rk4: Callable[[FloatArray, float, FloatArray, FloatArray, FloatArray],
                             FloatArray],
               x: FloatArray, t: FloatArray, steps: NDArray[np.int64],
               forcing: tuple[FloatArray, FloatArray, FloatArray], out: FloatArray,
               limit: float) -> None:
    """The free run's steps from state ``x``, ν written into ``out`` (n, 6) row by row up to
    the first row whose |ν|₁ reaches ``limit`` (or is NaN)."""
    F_start, F_mid, F_end = forcing
    for k in range(len(t) - 1):
        m = int(steps[k])
        h = float(t[k + 1] - t[k]) / m
        if m == 1:  # the forcing at the step's start, middle and end as precomputed
            x = rk4(x, h, F_start[k], F_mid[k], F_end[k])
        else:  # F(s) = F_start + s (F_end − F_start) over the step, s ∈ [0, 1], both holds
            dF = F_end[k] - F_start[k]
            for j in range(m):
                x = rk4(x, h, F_start[k] + (j / m) * dF, F_start[k] + ((j + 0.5) / m) * dF,
                        F_start[k] + ((j + 1) / m) * dF)
        s = float(np.abs(x[:6]).sum())
        if not s < limit:  # also catches NaN
            break
        out[k + 1] = x[:6]


#: Largest h·ρ a sub-step of the free run may take: RK4 is stable on the negative real axis
#: up to h·ρ ≈ 2.785; 2 leaves room for the simulated ν straying from the measured one.
STABLE_STEP = 2.0
#: Most sub-steps per sample step (a model stiffer than this is reported as diverging).
MAX_SUBSTEPS = 256


def rk4_substeps(nu: FloatArray, dt: FloatArray, model: DampingModel, body: RigidBody,
                 theta: FloatArray, chunk: int = CHUNK) -> NDArray[np.int64]:
    """How many RK4 sub-steps each sample step of the free run needs to stay stable.

    The stiffness at a sample is the spectral radius ρ of M⁻¹ ∂(D(ν)ν)/∂ν (static terms, at
    the measured ν; the Jacobian by forward differences, vectorised) and the fastest memory
    rate λ; a step of length h needs ⌈h·max(ρ_k, ρ_k+1)/:data:`STABLE_STEP`⌉ sub-steps, at
    most :data:`MAX_SUBSTEPS`.

    Parameters
    ----------
    nu : ndarray, shape (n, 6)
        Measured ν (m/s, rad/s) at the rows of the run.
    dt : ndarray, shape (n - 1,)
        Sample steps (s).
    model : DampingModel
    body : RigidBody
    theta : ndarray, shape (p,)
    chunk : int
        Rows evaluated at once (memory).

    Returns
    -------
    ndarray of int, shape (n - 1,)
        Sub-steps per sample step, ≥ 1.
    """
    K = model.static_gain(np.asarray(theta, dtype=float))
    M_inv = np.linalg.inv(body.M_inertial)

    def force(x: FloatArray) -> FloatArray:
        # D(ν)ν = (α(ν) K) ν, rows of (N, 6)
        return np.einsum("nij,nj->ni", (model.alphas(x) @ K).reshape(-1, 6, 6), x)

    rho = np.empty(len(nu))
    for a in range(0, len(nu), chunk):
        v = nu[a:a + chunk]
        eps = 1e-6 * np.maximum(1.0, np.abs(v))  # (N, 6), per component
        base = force(v)
        J = np.empty((len(v), 6, 6))
        for j in range(6):
            e = np.zeros(6)
            e[j] = 1.0
            J[:, :, j] = (force(v + eps[:, j:j + 1] * e) - base) / eps[:, j:j + 1]
        rho[a:a + chunk] = np.abs(np.linalg.eigvals(M_inv @ J)).max(axis=1)
    lam = model.memory_rates
    if lam.size:
        rho = np.maximum(rho, float(np.abs(lam).max()))
    # the stiffer end of each step decides
    need = np.asarray(dt) * np.maximum(rho[:-1], rho[1:]) / STABLE_STEP
    return np.clip(np.ceil(need), 1, MAX_SUBSTEPS).astype(np.int64)


def free_run_error(samples: Samples, model: DampingModel, body: RigidBody, theta: FloatArray,
                   segment: int | slice | None = None, tau_hold: str = "linear"
                   ) -> dict[str, FloatArray]:
    """:func:`metrics` of the free-run velocity against the measured ν on one segment.

    Parameters are those of :func:`free_run`. ``rmse`` (m/s, rad/s) and ``nrmse``
    (RMSE / std of the measured ν) are the headline numbers; a diverged run gives inf, and
    ``diverged_after`` says when (s after the run's start, NaN if it did not; the same in
    every DOF).

    Returns
    -------
    dict of str to ndarray, each shape (6,)
    """
    rows = _rows(samples, segment)
    sim = free_run(samples, model, body, theta, rows, tau_hold)
    finite = np.isfinite(sim).all(axis=1)
    after = np.nan if finite.all() else float(samples.t[rows][np.argmin(finite) - 1]
                                              - samples.t[rows.start])
    sim = np.where(np.isfinite(sim), sim, np.inf)
    scores = metrics(samples.nu[rows], sim, samples.nu_dot[rows], samples.rate)
    scores["diverged_after"] = np.full(6, after)
    return scores


# --- physics -------------------------------------------------------------------------------


def energy_consistency(samples: Samples, model: DampingModel, theta: FloatArray,
                       chunk: int = CHUNK) -> tuple[float, float]:
    """Check νᵀD(ν)ν ≥ 0 (dissipated power, W) of the static terms on the data.

    Parameters
    ----------
    samples : Samples
    model : DampingModel
    theta : ndarray, shape (p,)
    chunk : int
        Samples per chunk (memory ∝ chunk · 36).

    Returns
    -------
    fraction_negative : float
        Share of samples where the model generates energy (νᵀD(ν)ν < 0).
    min_power : float
        Smallest νᵀD(ν)ν (W); negative values show where the model is not passive.
    """
    theta = np.asarray(theta, dtype=float)
    N = len(samples)
    if N == 0:
        return 0.0, float("nan")
    neg = 0
    lowest = np.inf
    for start in range(0, N, chunk):
        P = model.dissipation(samples.nu[start:start + chunk], theta)
        neg += int(np.count_nonzero(P < 0))
        lowest = min(lowest, float(P.min()))
    return neg / N, lowest
