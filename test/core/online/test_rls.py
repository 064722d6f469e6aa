"""Recursive least squares (dampest_ros.core.online.rls) against filterpy, batch LS and known
truth."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from dampest_ros.core.online.rls.least_squares import RecursiveLeastSquares, RLSConfig
from dampest_ros.core.online.rls.monitors import CorrelationFactor, Cusum, InnovationMonitor
from dampest_ros.core.online.rls.update import forget, rls_update, scaled_trace
from dampest_ros.core.physics.rigid_body import ConfigError


def random_problem(seed: int, n: int, p: int, noise: float = 0.1
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n samples of 6 rows: Φ (n, 6, p), y (n, 6) and the true θ (p,)."""
    rng = np.random.default_rng(seed)
    theta = rng.normal(size=p) * 3.0
    Phi = rng.normal(size=(n, 6, p))
    y = Phi @ theta + noise * rng.normal(size=(n, 6))
    return Phi, y, theta


def test_equals_filterpy_fading_memory_kalman_filter() -> None:
    """F = I, Q = 0, alpha = 1/√λ: filterpy's KalmanFilter is exponentially weighted RLS."""
    p, lam = 20, 0.98
    Phi, y, _ = random_problem(1, 300, p, noise=0.5)
    R = np.random.default_rng(2).uniform(0.5, 2.0, 6)
    theta, P = np.zeros(p), 10.0 * np.eye(p)
    kf = KalmanFilter(dim_x=p, dim_z=6)
    kf.x, kf.P, kf.F, kf.Q, kf.R = theta.copy(), P.copy(), np.eye(p), np.zeros((p, p)), np.diag(R)
    kf.alpha = 1.0 / np.sqrt(lam)
    worst = 0.0
    for k in range(len(y)):
        theta, P, e = rls_update(theta, P, Phi[k], y[k], lam, R)
        kf.predict()
        kf.update(y[k], H=Phi[k])
        np.testing.assert_allclose(e, kf.y, rtol=1e-9, atol=1e-9)
        worst = max(worst, np.abs(theta - kf.x).max() / np.abs(kf.x).max(),
                    np.abs(P - kf.P).max() / np.abs(kf.P).max())
    assert worst < 1e-10


def test_lambda_one_diffuse_prior_reproduces_batch_least_squares() -> None:
    p = 12
    Phi, y, truth = random_problem(3, 300, p)
    theta, P = np.zeros(p), 1e6 * np.eye(p)
    for k in range(len(y)):
        theta, P, _ = rls_update(theta, P, Phi[k], y[k], 1.0, 1.0)
    ls = np.linalg.lstsq(Phi.reshape(-1, p), y.reshape(-1), rcond=None)[0]
    assert np.abs(theta - ls).max() / np.abs(ls).max() < 1e-8
    assert np.abs(ls - truth).max() < 0.01  # and LS itself finds the truth


def test_weighted_rls_equals_weighted_least_squares() -> None:
    """R = diag(r): the rows are weighted by 1/r_i, as in the batch WLS."""
    p = 8
    Phi, y, _ = random_problem(4, 200, p)
    r = np.array([1.0, 4.0, 0.25, 9.0, 1.0, 2.0])
    theta, P = np.zeros(p), 1e6 * np.eye(p)
    for k in range(len(y)):
        theta, P, _ = rls_update(theta, P, Phi[k], y[k], 1.0, r)
    w = 1.0 / np.sqrt(r)
    A = (Phi * w[None, :, None]).reshape(-1, p)
    b = (y * w).reshape(-1)
    ls = np.linalg.lstsq(A, b, rcond=None)[0]
    assert np.abs(theta - ls).max() / np.abs(ls).max() < 1e-8


@pytest.mark.parametrize("mode", ["exponential", "directional"])
def test_class_and_function_agree(mode: str) -> None:
    p = 10
    Phi, y, _ = random_problem(5, 250, p)
    cfg = RLSConfig(forgetting_factor=0.97, forgetting_mode=mode, adapt_noise=False,
                    noise_var=(0.5, 1.0, 2.0, 1.0, 1.0, 3.0), trace_max=4.0)
    P0 = np.full(p, 2.0)
    rls = RecursiveLeastSquares(np.zeros(p), P0, cfg)
    theta, P = np.zeros(p), np.diag(P0)
    for k in range(len(y)):
        e_cls = rls.update(Phi[k], y[k])
        theta, P, e = rls_update(theta, P, Phi[k], y[k], 0.97, np.array(cfg.noise_var),
                                 mode=mode, trace_max=4.0, scale=np.sqrt(P0))
        np.testing.assert_array_equal(e, e_cls)
    assert np.abs(rls.theta - theta).max() <= 1e-12 * np.abs(theta).max()
    assert np.abs(rls.P - P).max() <= 1e-12 * np.abs(P).max()


def test_converges_to_truth_with_known_noise() -> None:
    p = 12
    rng = np.random.default_rng(6)
    truth = rng.normal(size=p)
    sd = np.array([0.1, 0.2, 0.4, 0.05, 0.1, 0.3])
    Phi = rng.normal(size=(3000, 6, p))
    y = Phi @ truth + sd * rng.normal(size=(3000, 6))
    # every parameter acts on all six rows: weight them with the learnt noise (WLS)
    rls = RecursiveLeastSquares(np.zeros(p), np.full(p, 100.0), RLSConfig(
        forgetting_factor=1.0, noise_var=(0.01,) * 6, adapt_weights=True))
    rls.update_many(Phi, y)
    # with λ = 1 the error is at the Cramér–Rao level: all within 4σ
    assert np.all(np.abs(rls.theta - truth) < 4 * rls.std)
    d = rls.diagnostics()
    np.testing.assert_allclose(d.noise_std, sd, rtol=0.06)  # learnt per-DOF noise
    # innovations: noise plus the (small) parameter uncertainty Φ P Φᵀ
    assert np.all(d.innovation_rms > 0.95 * sd) and np.all(d.innovation_rms < 1.25 * sd)
    assert d.condition_number < 3.0  # white regressors: well conditioned
    assert not d.alarm


def test_trace_bound_stops_wind_up_without_excitation() -> None:
    """λ = 0.95 with zero regressors for 5000 samples: P would grow by 0.95⁻⁵⁰⁰⁰."""
    p = 6
    rls = RecursiveLeastSquares(np.ones(p), np.full(p, 4.0),
                                RLSConfig(forgetting_factor=0.95, trace_max=12.0))
    Phi, y, _ = random_problem(7, 200, p)
    rls.update_many(Phi, y)
    before = rls.diagnostics().covariance_trace
    noise = 0.1 * np.random.default_rng(70).normal(size=(5000, 6))
    rls.update_many(np.zeros((5000, 6, p)), noise)
    d = rls.diagnostics()
    assert before < d.covariance_trace <= 12.0 * (1 + 1e-12)
    assert rls.is_spd() and np.all(np.isfinite(rls.P))
    assert not d.excited.any()  # zero regressors: nothing excited


def test_directional_forgetting_only_forgets_excited_directions() -> None:
    """Only the first 3 parameters are excited after a rich start: exponential forgetting
    inflates the other variances to the bound, directional forgetting keeps them."""
    p = 6
    Phi, y, truth = random_problem(8, 300, p)
    Phi2 = Phi.copy()
    Phi2[:, :, 3:] = 0.0
    y2 = Phi2 @ truth
    out = {}
    for mode in ("exponential", "directional"):
        rls = RecursiveLeastSquares(np.zeros(p), np.full(p, 100.0), RLSConfig(
            forgetting_factor=0.98, forgetting_mode=mode, adapt_noise=False,
            noise_var=(0.01,) * 6))
        rls.update_many(Phi, y)
        var_rich = np.diagonal(rls.P).copy()
        rls.update_many(Phi2, y2)
        out[mode] = np.diagonal(rls.P) / var_rich
        assert rls.is_spd()
    assert np.all(out["exponential"][3:] > 400.0)  # λ⁻³⁰⁰ = 428
    np.testing.assert_allclose(out["directional"][3:], 1.0, rtol=0.05)  # frozen
    assert np.all(out["directional"][:3] < 1.5)  # the excited ones stay at their level


def test_directional_forgetting_tracks_a_change_in_excited_directions() -> None:
    p = 4
    rng = np.random.default_rng(9)
    truth = np.array([1.0, 2.0, 3.0, 4.0])
    rls = RecursiveLeastSquares(np.zeros(p), np.full(p, 100.0), RLSConfig(
        forgetting_factor=0.98, forgetting_mode="directional", noise_var=(0.01,) * 6,
        adapt_noise=False))
    for k in range(1500):
        th = truth * (1.3 if k >= 500 else 1.0)
        Phi = rng.normal(size=(6, p))
        rls.update(Phi, Phi @ th + 0.1 * rng.normal(size=6))
    np.testing.assert_allclose(rls.theta, 1.3 * truth, rtol=0.01)


def test_forget_exponential_is_p_over_lambda() -> None:
    P = np.diag([1.0, 2.0])
    np.testing.assert_allclose(forget(P, np.zeros((6, 2)), 0.8, np.eye(6)), P / 0.8)
    # bounded: the inflation stops at the scaled trace 3.3
    Pb = forget(P, np.zeros((6, 2)), 0.8, np.eye(6), trace_max=3.3)
    assert scaled_trace(Pb) == pytest.approx(3.3)


def test_cusum_detects_a_shift_and_not_noise() -> None:
    rng = np.random.default_rng(10)
    c = Cusum(2, drift=0.5, threshold=10.0)
    for _ in range(20000):
        c.update(rng.normal(size=2))
    assert not c.alarm.any()  # in-control run length ≫ 20000 at h = 10
    c.reset()
    steps = 0
    while not c.alarm[1]:
        c.update(np.array([0.0, -2.0]) + rng.normal(size=2))
        steps += 1
    # a 2σ shift: h / (δ − k) ≈ 6.7 steps
    assert 4 <= steps <= 12
    assert c.alarm_sign[1] == -1.0


def test_change_detector_fires_on_a_gain_change() -> None:
    """The damping force grows 30 % at sample 8000: the 'gain' channel of that DOF alarms
    within a few blocks, none before; the covariance reset lets θ re-converge."""
    p = 2
    rng = np.random.default_rng(11)
    rls = RecursiveLeastSquares(np.zeros(p), np.full(p, 1e4), RLSConfig(
        forgetting_factor=0.995))
    for k in range(10000):
        v = np.sin(0.01 * k) + 0.3 * rng.normal()
        Phi = np.zeros((6, p))
        Phi[0] = [v, v * abs(v)]
        gain = 1.3 if k >= 8000 else 1.0
        y = Phi @ np.array([10.0, 100.0]) * gain + 0.5 * rng.normal(size=6)
        rls.update(Phi, y, t=k / 50.0)
    assert rls.alarm_time is not None and 160.0 <= rls.alarm_time < 165.0
    assert "X gain+" in rls.diagnostics().alarm_channels
    assert rls.boosts >= 1
    np.testing.assert_allclose(rls.theta, [13.0, 130.0], rtol=0.05)


def test_innovation_monitor_ignores_correlated_noise() -> None:
    """AR(1) noise with ρ = 0.9 (slow residual structure): no alarm in 2000 blocks."""
    rng = np.random.default_rng(13)
    mon = InnovationMonitor(block=5)
    x = np.zeros(6)
    for _ in range(10000):
        x = 0.98 * x + 0.2 * rng.normal(size=6)
        mon.update(x, np.sign(rng.normal(size=6)))
    assert not mon.alarm
    for _ in range(100):  # then a shift of 2 (about 2σ of the process) in Y
        x = 0.98 * x + 0.2 * rng.normal(size=6)
        mon.update(x + np.array([0, 2.0, 0, 0, 0, 0]), np.ones(6))
    assert mon.alarm and all(c.startswith("Y ") for c in mon.channels())


def test_non_finite_samples_are_skipped() -> None:
    rls = RecursiveLeastSquares(np.zeros(3), np.ones(3))
    Phi = np.ones((6, 3))
    Phi[0, 0] = np.nan
    assert np.all(np.isnan(rls.update(Phi, np.zeros(6))))
    assert rls.skipped == 1 and rls.n == 0
    np.testing.assert_array_equal(rls.theta, 0.0)


def test_freeze_and_reset() -> None:
    Phi, y, _ = random_problem(12, 50, 3)
    rls = RecursiveLeastSquares(np.zeros(3), np.ones(3))
    rls.update_many(Phi[:20], y[:20])
    theta = rls.theta.copy()
    rls.frozen = True
    rls.update_many(Phi[20:], y[20:])
    np.testing.assert_array_equal(rls.theta, theta)
    rls.reset()
    np.testing.assert_array_equal(rls.theta, 0.0)
    np.testing.assert_array_equal(rls.P, np.eye(3))


def test_invalid_settings_are_rejected_with_a_reason() -> None:
    with pytest.raises(ConfigError, match="forgetting_factor"):
        RLSConfig(forgetting_factor=1.5)
    with pytest.raises(ConfigError, match="forgetting_mode"):
        RLSConfig(forgetting_mode="sideways")
    rls = RecursiveLeastSquares(np.zeros(2), np.ones(2))
    with pytest.raises(ConfigError, match=r"\[0.9, 1.0\]"):
        rls.set_forgetting_factor(0.5)


def test_block_updates_equal_the_sequential_recursion() -> None:
    """update_many (blocks of up to BLOCK samples) against update() sample by sample: a
    stretch without excitation (trace bound active: sample by sample), heavy-tailed noise
    (the noise estimate clips innovations), a gain change with an alarm and a covariance
    boost inside a block, a non-finite sample, chunks of odd sizes."""
    rng = np.random.default_rng(13)
    p, n = 12, 3000
    truth = rng.normal(size=p)
    Phi = rng.normal(size=(n, 6, p))
    Phi[1000:1400] = 0.0
    gain = np.where(np.arange(n) >= 2000, 1.4, 1.0)[:, None]
    y = gain * (Phi @ truth) + 0.1 * rng.standard_t(3, size=(n, 6))
    y[1700, 2] = np.nan
    t = 0.02 * np.arange(n)
    cfg = RLSConfig(forgetting_factor=0.99, noise_var=(0.02,) * 6, cusum_block=5,
                    cusum_warmup=4, cusum_threshold=6.0)
    seq = RecursiveLeastSquares(np.zeros(p), np.ones(p), cfg)
    blk = RecursiveLeastSquares(np.zeros(p), np.ones(p), cfg)
    e_seq = np.array([seq.update(Phi[k], y[k], t[k]) for k in range(n)])
    edges = np.r_[0, np.cumsum(rng.integers(1, 40, size=n))]
    edges = [*edges[edges < n].tolist(), n]
    e_blk = np.concatenate([blk.update_many(Phi[a:b], y[a:b], t[a:b])
                            for a, b in itertools.pairwise(edges)])
    assert seq.boosts >= 2 and seq.skipped == 1  # the cases above did occur
    assert (blk.boosts, blk.skipped, blk.n, blk.alarm_time) == \
        (seq.boosts, seq.skipped, seq.n, seq.alarm_time)
    np.testing.assert_allclose(e_blk, e_seq, rtol=1e-9, atol=1e-12)
    for a, b in ((blk.theta, seq.theta), (blk.P, seq.P), (blk.R, seq.R), (blk.std, seq.std),
                 (blk.monitor.cusum.statistic, seq.monitor.cusum.statistic)):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12 * np.abs(b).max())
    ds, db = seq.diagnostics(), blk.diagnostics()
    np.testing.assert_allclose(db.innovation_rms, ds.innovation_rms, rtol=1e-9)
    np.testing.assert_allclose(db.excitation, ds.excitation, rtol=1e-9)


def ar1(rng: np.random.Generator, rho: float, n: int) -> np.ndarray:
    """n samples of a unit-variance AR(1) process x_k = ρ x_{k−1} + √(1 − ρ²) w_k."""
    w = rng.normal(size=n) * np.sqrt(1.0 - rho**2)
    x = np.empty(n)
    x[0] = rng.normal()
    for k in range(1, n):
        x[k] = rho * x[k - 1] + w[k]
    return x


def test_correlation_factor_is_the_long_run_variance_ratio() -> None:
    """AR(1) residuals, ρ = 0.9, 400 blocks of L = 250: E[B_b²] / (L σ²) =
    1 + 2 Σ_{k<L} (1 − k/L) ρᵏ (≈ (1 + ρ)/(1 − ρ) = 19 for L ≫ 1/(1 − ρ)); white: 1."""
    rng = np.random.default_rng(21)
    L, rho = 250, 0.9
    u = rng.normal(size=(400 * L + 17, 6))
    u[:, 0] = ar1(rng, rho, len(u))
    k = np.arange(1, L)
    expected = 1.0 + 2.0 * np.sum((1.0 - k / L) * rho**k)  # 18.28
    c = CorrelationFactor(L)
    assert np.all(c.factor == 1.0)  # before any block: the floor
    for a, b in itertools.pairwise([0, 1, 300, 301, 5000, len(u)]):  # any chunking
        c.update(u[a:b])
    assert c.blocks == 400
    assert c.factor[0] == pytest.approx(expected, rel=0.15)
    np.testing.assert_allclose(c.factor[1:], 1.0, atol=0.15)  # white: ≈ 1, never below
    assert np.all(CorrelationFactor(L, prior=12.5).factor == 12.5)


def test_std_is_the_prior_at_the_start_and_the_sandwich_with_correlated_noise() -> None:
    """θ = the mean of y per DOF (Φ = I): the variance of a sample mean of N AR(1) samples is
    σ² (1 + ρ) / ((1 − ρ) N) to O(1/N²); the RLS P alone says σ² / N."""
    rng = np.random.default_rng(22)
    n, rho, sd = 40_000, 0.9, 0.3
    e = sd * rng.normal(size=(n, 6))
    e[:, 0] = sd * ar1(rng, rho, n)
    P0 = np.diag([4.0, 1.0, 9.0, 1.0, 1.0, 0.25]) + 0.1  # a full prior covariance
    rls = RecursiveLeastSquares(np.zeros(6), P0, RLSConfig(forgetting_factor=1.0))
    np.testing.assert_allclose(rls.std, np.sqrt(np.diagonal(P0)), rtol=1e-12)
    rls.update_many(np.broadcast_to(np.eye(6), (n, 6, 6)), 1.0 + e)
    white = sd / np.sqrt(n)
    np.testing.assert_allclose(rls.std[1:], white, rtol=0.1)
    # with the correlation factor of 250-sample blocks: 18.3 instead of 19
    assert rls.std[0] == pytest.approx(white * np.sqrt((1 + rho) / (1 - rho)), rel=0.1)
    assert np.sqrt(np.diagonal(rls.P)[0] * rls.R[0] / rls.R_w[0]) == \
        pytest.approx(white, rel=0.1)  # what P and the noise level alone give


def test_outlier_gate_rejects_a_gross_error_and_not_gaussian_innovations() -> None:
    """χ²(6) gate at p = 1e-6 on Gaussian innovations: of 20000 samples about 0.02 cross it
    by chance (none allowed here); a 1000σ spike after the warm-up is rejected and counted, a
    spike during the warm-up is not judged."""
    from scipy import stats

    from dampest_ros.core.online.rls.monitors import OutlierGate
    Phi, y, theta = random_problem(9, 20000, 4, noise=0.5)
    gate = OutlierGate(float(stats.chi2.isf(1e-6, 6)), warmup=200, window=500.0)
    P = np.eye(4) * 1e-6  # the estimate is the truth, well known
    y[100, 2] += 500.0  # in the warm-up: only initialises V (winsorised)
    y[5000, 3] += 500.0
    rejected = np.concatenate([gate(Phi[k:k + 10], y[k:k + 10], theta, P, np.ones(6))
                               for k in range(0, len(y), 10)])
    assert np.flatnonzero(rejected).tolist() == [5000]
    assert gate.rejected == 1
    np.testing.assert_allclose(np.sqrt(gate.v), 0.5, rtol=0.1)  # the innovation noise


def test_excitation_counts_terms_a_misfit_sets_against_each_other() -> None:
    """Surge flown hard, y = −61 u + 199 u|u| plus a misfit 10× the weighting noise (the
    MuJoCo torpedo's surge fit): the predicted force Φθ nearly cancels and the innovations
    are large, yet each term's force stands above the noise: u is excited; sway, not flown,
    is not."""
    rng = np.random.default_rng(4)
    n = 5000
    u = 0.3 * np.sin(np.linspace(0.0, 60.0, n)) + 0.1 * rng.normal(size=n)
    Phi = np.zeros((n, 6, 4))
    Phi[:, 0, 0], Phi[:, 0, 1] = u, u * np.abs(u)  # X_u, X_uu
    Phi[:, 1, 2], Phi[:, 1, 3] = 1e-4, 1e-8  # Y_v, Y_vv: sway barely moves
    theta = np.array([-61.0, 199.0, 5.0, 100.0])
    y = np.einsum("nip,p->ni", Phi, theta) + 5.0 * rng.normal(size=(n, 6))
    rls = RecursiveLeastSquares(np.array([1.0, 70.0, 5.0, 100.0]),
                                (10.0 * np.array([1.0, 70.0, 5.0, 100.0])) ** 2,
                                RLSConfig(forgetting_factor=1.0, noise_var=(0.25,) * 6))
    rls.update_many(Phi, y)
    d = rls.diagnostics(condition=False)
    assert d.noise_std[0] == pytest.approx(5.0, rel=0.1)  # the misfit, 10× the weights' 0.5
    # the former measure, RMS(Φθ) over the noise, called this DOF not excited
    force = Phi[:, 0] @ rls.theta
    assert np.sqrt(np.mean(force**2)) < rls.config.min_excitation * d.noise_std[0]
    # the larger term force (X_uu u|u| here, 3.1 noise standard deviations) over the noise
    terms = np.sqrt(np.mean((Phi[:, 0, :2] * rls.theta[:2]) ** 2, axis=0))
    assert d.excitation[0] == pytest.approx(terms.max() / d.noise_std[0], rel=0.02)
    assert d.excitation[0] > 2.5 and d.excited[0]
    assert not d.excited[1] and d.unexcited == ["v", "w", "p", "q", "r"]
