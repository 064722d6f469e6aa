"""Damping terms (dampest_ros.core.physics.damping): regressor, names, dissipativity, memory,
scaling."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.physics.alpha import Alpha, AlphaBank
from dampest_ros.core.physics.damping import DampingModel, filter_memory, psd_project
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.terms import (
    CrossSpec,
    added_mass_term,
    coriolis_term,
    cross_term,
    library,
    linear_term,
    memory_term,
    quadratic_term,
    residual_term,
)
from dampest_ros.core.physics.vehicle import nondim_scales

CROSS = [
    CrossSpec(1, 1, Alpha.parse("|r|")),  # Y_vr: Y ← v |r|
    CrossSpec(5, 1, Alpha.parse("|r|")),  # N_vr: N ← v |r|
    CrossSpec(2, 2, Alpha.parse("u")),  # Z_wu: Z ← w u (lift-like)
    CrossSpec(5, 5, Alpha.parse("uv")),  # N_ruv: N ← r u v
    CrossSpec(0, 0, Alpha.parse("|U|")),  # X_uU: X ← u ‖(u, v, w)‖
    CrossSpec(4, 2, Alpha.parse("|uw|"), name="M_w_absuw"),  # M ← w |u w|
]
MEMORY = {"u": [1.5, 6.0], "r": [2.5]}


def full_model(residual: bool = True) -> DampingModel:
    """A model with every term kind: linear (+ two off-diagonals), quadratic, cross, freq,
    added and residual."""
    terms = [
        linear_term(off_diagonal=[("Y", "r"), ("N", "v")]),
        quadratic_term(),
        cross_term(CROSS),
        memory_term(MEMORY),
        added_mass_term(),
    ]
    if residual:
        terms.append(residual_term())
    return DampingModel(terms)


def samples(rng: np.random.Generator, model: DampingModel, n: int) -> tuple[np.ndarray, ...]:
    nu = rng.normal(size=(n, 6)) * [1.0, 0.5, 0.4, 0.8, 0.8, 0.6]
    theta = rng.normal(size=model.n_params) * 10.0
    z = rng.normal(size=(n, len(model.memory_rates)))
    return nu, theta, z


# --- names and layout ----------------------------------------------------------------------------


def test_parameter_names_as_documented() -> None:
    model = full_model()
    assert model.parameter_names == [
        "X_u", "Y_v", "Z_w", "K_p", "M_q", "N_r", "Y_r", "N_v",
        "X_uu", "Y_vv", "Z_ww", "K_pp", "M_qq", "N_rr",
        "Y_vr", "N_vr", "Z_wu", "N_ruv", "X_uU", "M_w_absuw",
        "freq.u.c1", "freq.u.c2", "freq.r.c1",
        "added.K_vw", "added.M_uw", "added.N_uv",
        "residual.s1", "residual.s2",
    ]
    assert model.n_params == 28
    assert model.kinds == ["linear", "quadratic", "cross", "freq", "added", "residual"]
    assert model.slice("freq") == slice(20, 23)
    assert model.term_rate_names() == ["freq.u.lambda1", "freq.u.lambda2", "freq.r.lambda1"]
    np.testing.assert_array_equal(model.memory_rates, [1.5, 6.0, 2.5])
    np.testing.assert_array_equal(model.memory_dofs, [0, 0, 5])
    for t in model.terms:
        assert t.meaning


def test_duplicate_kinds_and_names_rejected() -> None:
    with pytest.raises(ConfigError):
        DampingModel([linear_term(), linear_term()])
    with pytest.raises(ConfigError):
        DampingModel([cross_term([CrossSpec(0, 0, Alpha("one"), "X_u")]), linear_term()])


def test_theta_from_dict() -> None:
    model = full_model()
    theta = model.theta_from_dict({"X_u": 13.7, "N_rr": 1.5, "freq.r.c1": 4.0})
    assert theta[model.parameter_names.index("X_u")] == 13.7
    assert theta[model.parameter_names.index("freq.r.c1")] == 4.0
    assert np.count_nonzero(theta) == 3
    with pytest.raises(ConfigError, match="X_q"):
        model.theta_from_dict({"X_q": 1.0})


# --- regressor against forces ---------------------------------------------------------------------


def test_regressor_times_theta_equals_term_forces_and_force() -> None:
    model = full_model()
    rng = np.random.default_rng(0)
    nu, theta, z = samples(rng, model, 500)
    Phi = model.regressor(nu, z)
    assert Phi.shape == (500, 6, model.n_params)
    y = np.einsum("nap,p->na", Phi, theta)
    parts = model.term_forces(nu, theta, z)
    assert sorted(parts) == sorted(model.kinds)
    total = sum(parts.values())
    assert np.abs(y).max() > 10.0
    np.testing.assert_allclose(y, total, rtol=0, atol=1e-12 * np.abs(y).max())
    np.testing.assert_allclose(model.force(nu, theta, z), y, rtol=0,
                               atol=1e-12 * np.abs(y).max())


def test_term_forces_against_hand_written_physics() -> None:
    model = full_model()
    rng = np.random.default_rng(1)
    nu, theta, z = samples(rng, model, 50)
    names = model.parameter_names
    th = dict(zip(names, theta, strict=True))
    parts = model.term_forces(nu, theta, z)
    u, v, w, p, q, r = nu.T
    # linear: diag + Y ← Y_r r, N ← N_v v
    lin = np.column_stack([th["X_u"] * u, th["Y_v"] * v + th["Y_r"] * r, th["Z_w"] * w,
                           th["K_p"] * p, th["M_q"] * q, th["N_r"] * r + th["N_v"] * v])
    np.testing.assert_allclose(parts["linear"], lin, atol=1e-12)
    quad = np.column_stack([th[f"{f}_{d}{d}"] * x * np.abs(x)
                            for f, d, x in zip("XYZKMN", "uvwpqr", nu.T, strict=True)])
    np.testing.assert_allclose(parts["quadratic"], quad, atol=1e-12)
    speed = np.sqrt(u * u + v * v + w * w)
    cross = np.column_stack([
        th["X_uU"] * u * speed,
        th["Y_vr"] * v * np.abs(r),
        th["Z_wu"] * w * u,
        np.zeros_like(u),
        th["M_w_absuw"] * w * np.abs(u * w),
        th["N_vr"] * v * np.abs(r) + th["N_ruv"] * r * u * v,
    ])
    np.testing.assert_allclose(parts["cross"], cross, atol=1e-12)
    mem = np.zeros_like(nu)
    mem[:, 0] = th["freq.u.c1"] * z[:, 0] + th["freq.u.c2"] * z[:, 1]
    mem[:, 5] = th["freq.r.c1"] * z[:, 2]
    np.testing.assert_allclose(parts["freq"], mem, atol=1e-12)
    added = np.zeros_like(nu)
    added[:, 3] = th["added.K_vw"] * v * w
    added[:, 4] = th["added.M_uw"] * u * w
    added[:, 5] = th["added.N_uv"] * u * v
    np.testing.assert_allclose(parts["added"], added, atol=1e-12)
    # residual: s_k |m_kᵀν| m_k m_kᵀ ν with unit modes (u+w)/√2 and (v+r)/√2
    m1 = np.array([1, 0, 1, 0, 0, 0]) / np.sqrt(2)
    m2 = np.array([0, 1, 0, 0, 0, 1]) / np.sqrt(2)
    res = sum(th[f"residual.s{k}"] * np.abs(nu @ m)[:, None] * (nu @ m)[:, None] * m
              for k, m in ((1, m1), (2, m2)))
    np.testing.assert_allclose(parts["residual"], res, atol=1e-12)


def test_freq_term_needs_states() -> None:
    model = full_model()
    nu = np.zeros((3, 6))
    theta = np.ones(model.n_params)
    with pytest.raises(ValueError, match="memory states"):
        model.regressor(nu)
    with pytest.raises(ValueError, match="memory states"):
        model.force(nu, theta)


def test_alpha_bank_matches_alpha_call() -> None:
    alphas = [Alpha("one"), Alpha("abs", 5), Alpha("lin", 0), Alpha("norm"), Alpha("prod", 0, 1),
              Alpha("absprod", 2, 3), Alpha("absproj", w=(0.6, 0, 0.8, 0, 0, 0))]
    nu = np.random.default_rng(2).normal(size=(40, 6))
    bank = AlphaBank(alphas)(nu)
    for k, a in enumerate(alphas):
        np.testing.assert_allclose(bank[:, k], a(nu), rtol=0, atol=1e-15)


def test_a_bank_of_every_kind_is_each_alphas_own_call_bit_for_bit() -> None:
    """Each kind overwrites only its own columns of the bank (areas over one axis and over a
    pair, norms of both halves, pair norms, absolute values among them)."""
    alphas = [Alpha("one"), Alpha("abs", 5), Alpha("lin", 0), Alpha("norm"), Alpha("anorm"),
              Alpha("prod", 0, 1), Alpha("absprod", 2, 3), Alpha("pnorm", 1, 2),
              Alpha("area", 1, -1), Alpha("area", 3, 5), Alpha("area", 0, 2), Alpha("abs", 1),
              Alpha("absproj", w=(0.6, 0, 0.8, 0, 0, 0))]
    nu = np.random.default_rng(4).normal(size=(64, 6))
    nu[0] = 0.0  # at rest: every area is 0
    bank = AlphaBank(alphas)(nu)
    for k, a in enumerate(alphas[:-1]):
        assert bank[:, k].tobytes() == a(nu).tobytes(), a
    np.testing.assert_allclose(bank[:, -1], alphas[-1](nu), rtol=0, atol=1e-15)  # a product
    # known truth at ν = [3, 4, 0, 0, 0, 2]: |U| = 5, v²/|U| = 3.2, (u² + w²)/|U| = 1.8
    one = AlphaBank(alphas)(np.array([[3.0, 4.0, 0.0, 0.0, 0.0, 2.0]]))[0]
    assert one[[3, 4, 7, 8, 10]].tolist() == [5.0, 2.0, 4.0, 3.2, 1.8]


@pytest.mark.parametrize("kinds", [("one", "abs", "lin", "prod", "absprod"),
                                   ("one", "abs", "norm", "absproj")])
def test_alpha_bank_one_sample_is_the_row_of_the_whole_call(kinds: tuple[str, ...]) -> None:
    """Products on Python floats (the first bank), numpy for the rest: the same bits."""
    make = {"one": Alpha("one"), "abs": Alpha("abs", 5), "lin": Alpha("lin", 0),
            "prod": Alpha("prod", 0, 1), "absprod": Alpha("absprod", 2, 3),
            "norm": Alpha("norm"), "absproj": Alpha("absproj", w=(0.6, 0, 0.8, 0, 0, 0))}
    bank = AlphaBank([make[k] for k in kinds])
    nu = np.random.default_rng(3).normal(size=(50, 6))
    whole = bank(nu)
    for k in range(len(nu)):
        assert bank.one(nu[k].tolist()).tobytes() == whole[k].tobytes()
    # known truth: ν = [0.5, −2, 3, −4, 0, −1] gives 1, |r|, u, u v, |w p|
    if kinds[-1] == "absprod":
        assert bank.one([0.5, -2.0, 3.0, -4.0, 0.0, -1.0]).tolist() == [1.0, 1.0, 0.5, -1.0,
                                                                       12.0]


# --- Alpha text form ---------------------------------------------------------------------------


@pytest.mark.parametrize("text", ["1", "|r|", "u", "uv", "|uv|", "|U|", "|p|", "wq"])
def test_alpha_parse_round_trip(text: str) -> None:
    a = Alpha.parse(text)
    assert a.label() == text
    assert Alpha.parse(a.label()) == a


def test_alpha_parse_kinds() -> None:
    assert Alpha.parse("|r|") == Alpha("abs", 5)
    assert Alpha.parse("u") == Alpha("lin", 0)
    assert Alpha.parse("uv") == Alpha("prod", 0, 1)
    assert Alpha.parse("|uw|") == Alpha("absprod", 0, 2)
    assert Alpha.parse("|U|") == Alpha("norm")
    assert Alpha.parse(" | r | ") == Alpha("abs", 5)
    with pytest.raises(ConfigError):
        Alpha.parse("uvw")
    with pytest.raises(ConfigError):
        Alpha.parse("|s|")


# --- dissipativity and projection ----------------------------------------------------------------


def random_psd(rng: np.random.Generator, n: int, rank: int) -> np.ndarray:
    A = rng.normal(size=(n, rank))
    return A @ A.T


def test_psd_project_gives_psd_and_is_idempotent() -> None:
    rng = np.random.default_rng(3)
    for _ in range(50):
        A = rng.normal(size=(6, 6))
        S = A + A.T
        assert np.linalg.eigvalsh(S).min() < 0
        P = psd_project(S)
        np.testing.assert_allclose(P, P.T, atol=1e-12)
        assert np.linalg.eigvalsh(P).min() > -1e-12
        np.testing.assert_allclose(psd_project(P), P, atol=1e-12)
        # nearest in Frobenius norm: S − P is negative semi-definite and orthogonal to P
        assert np.linalg.eigvalsh(S - P).max() < 1e-12
        assert abs(np.sum((S - P) * P)) < 1e-10


def test_psd_project_leaves_psd_unchanged() -> None:
    rng = np.random.default_rng(4)
    for rank in (6, 3, 1):
        S = random_psd(rng, 6, rank)
        np.testing.assert_allclose(psd_project(S), S, rtol=0, atol=1e-12 * np.abs(S).max())


def test_psd_project_known_value() -> None:
    S = np.array([[1.0, 2.0], [2.0, 1.0]])  # eigenvalues 3 and −1
    np.testing.assert_allclose(psd_project(S), 1.5 * np.ones((2, 2)), atol=1e-15)


@pytest.mark.parametrize("off_diagonal", [[("Y", "r"), ("N", "v")], [("Y", "r")],
                                          [("Y", "r"), ("K", "v"), ("X", "w")]],
                         ids=["symmetric pattern", "single Y_r", "chain"])
def test_projected_linear_quadratic_model_is_dissipative(off_diagonal: list) -> None:
    model = DampingModel([linear_term(off_diagonal=off_diagonal), quadratic_term()])
    rng = np.random.default_rng(5)
    nu = rng.normal(size=(10_000, 6)) * [1.0, 0.5, 0.4, 0.8, 0.8, 0.6]
    scale = np.einsum("ni,ni->n", nu, nu)
    for _ in range(20):
        theta = rng.normal(size=model.n_params) * 5.0
        theta[:6] = np.abs(theta[:6])  # a plausible diagonal; the off-diagonals break it
        theta[6:6 + len(off_diagonal)] = 20.0
        theta[model.slice("quadratic")] = rng.normal(size=6) * 50.0
        assert model.dissipation(nu, theta).min() < 0  # not dissipative before projection
        proj = model.project(theta)
        P = model.dissipation(nu, proj)
        assert P.min() >= -1e-12 * np.abs(proj).max() * scale.max()
        # idempotent
        np.testing.assert_allclose(model.project(proj), proj, rtol=0, atol=1e-12)
        # quadratic weights clipped at zero, positive ones kept
        quad, quad_p = theta[model.slice("quadratic")], proj[model.slice("quadratic")]
        np.testing.assert_array_equal(quad_p, np.maximum(quad, 0.0))


def test_non_psd_linear_matrix_dissipates_negative_power_somewhere() -> None:
    model = DampingModel([linear_term(off_diagonal=[("Y", "r"), ("N", "v")])])
    theta = model.theta_from_dict({"X_u": 10, "Y_v": 2, "Z_w": 10, "K_p": 1, "M_q": 1, "N_r": 0.5,
                                   "Y_r": 3, "N_v": 3})
    # symmetric part in (v, r): [[2, 3], [3, 0.5]] has eigenvalue 1.25 − √9.5625 < 0
    nu = np.random.default_rng(6).normal(size=(10_000, 6))
    P = model.dissipation(nu, theta)
    assert P.min() < 0
    # along the negative eigenvector the power is exactly that eigenvalue
    lam, vec = np.linalg.eigh(np.array([[2.0, 3.0], [3.0, 0.5]]))
    e = np.zeros(6)
    e[[1, 5]] = vec[:, 0]
    np.testing.assert_allclose(model.dissipation(e, theta), [lam[0]], rtol=1e-12)
    assert lam[0] == pytest.approx(1.25 - np.sqrt(9.5625), rel=1e-12)
    # a symmetric off-diagonal pair keeps what the projection gives: the nearest PSD matrix
    proj = model.project(theta)
    D = model.matrix(np.zeros((1, 6)), proj)[0]
    D0 = model.matrix(np.zeros((1, 6)), theta)[0]
    np.testing.assert_allclose(D, psd_project(D0), atol=1e-12)


def test_projection_of_memory_and_residual_weights() -> None:
    model = full_model()
    theta = -np.ones(model.n_params)
    proj = model.project(theta)
    np.testing.assert_array_equal(proj[model.slice("freq")], 0.0)
    np.testing.assert_array_equal(proj[model.slice("residual")], 0.0)
    # indefinite bases (cross, added) are left alone
    np.testing.assert_array_equal(proj[model.slice("cross")], -1.0)
    np.testing.assert_array_equal(proj[model.slice("added")], -1.0)


# --- memory filter -------------------------------------------------------------------------------


def test_filter_memory_sine_matches_analytic_response() -> None:
    lam, omega, h = 1.5, 2.0, 1e-3
    t = np.arange(0.0, 40.0, h)
    z = filter_memory(t, np.sin(omega * t)[:, None], np.array([lam]))[:, 0]
    # ż = −λz + sin ωt, z(0) = 0
    d = lam * lam + omega * omega
    exact = (lam * np.sin(omega * t) - omega * np.cos(omega * t) + omega * np.exp(-lam * t)) / d
    np.testing.assert_allclose(z, exact, rtol=0, atol=1e-6)
    # steady state (transient e^{−λt} < 1e-13 after 20 s): amplitude and phase
    ss = t > 20.0
    basis = np.column_stack([np.sin(omega * t[ss]), np.cos(omega * t[ss])])
    a, b = np.linalg.lstsq(basis, z[ss], rcond=None)[0]
    assert np.hypot(a, b) == pytest.approx(1.0 / np.sqrt(d), abs=1e-6)
    assert np.arctan2(b, a) == pytest.approx(-np.arctan2(omega, lam), abs=1e-6)


def test_filter_memory_ramp_is_exact() -> None:
    # first-order hold is exact for piecewise-linear inputs, at any step
    rates = np.array([0.5, 2.0, 8.0])
    t = np.arange(0.0, 10.0, 0.05)
    z = filter_memory(t, np.repeat(t[:, None], 3, axis=1), rates)
    exact = t[:, None] / rates - 1 / rates**2 + np.exp(-rates * t[:, None]) / rates**2
    np.testing.assert_allclose(z, exact, rtol=0, atol=1e-12)


def test_model_memory_states_use_the_driving_dofs() -> None:
    model = full_model()
    t = np.arange(0.0, 5.0, 0.01)
    nu = np.zeros((len(t), 6))
    nu[:, 0] = t
    nu[:, 5] = 2.0 * t
    nu[:, 1] = 100.0  # not a driving dof
    z = model.memory_states(t, nu)
    rates = model.memory_rates
    x = np.column_stack([t, t, 2.0 * t])
    exact = x / rates - np.array([1, 1, 2]) * (1 - np.exp(-rates * t[:, None])) / rates**2
    np.testing.assert_allclose(z, exact, rtol=0, atol=1e-12)
    # and ż = −λz + ν_dof
    np.testing.assert_allclose(model.memory_derivative(z[3], nu[3]), -rates * z[3] + x[3])


# --- nondimensionalisation -----------------------------------------------------------------------


def scaled_force_identity(model: DampingModel, nu_scale: np.ndarray, force_scale: np.ndarray,
                          seed: int) -> None:
    rng = np.random.default_rng(seed)
    nu, theta, z = samples(rng, model, 200)
    s = model.param_scales(nu_scale, force_scale)
    assert s.shape == (model.n_params,)
    # memory states have the units of ν·s: scale them by ν_scale/λ
    z_scale = nu_scale[model.memory_dofs] / model.memory_rates
    f_prime = model.force(nu / nu_scale, s * theta, z / z_scale)
    f = model.force(nu, theta, z)
    np.testing.assert_allclose(f_prime, f / force_scale, rtol=1e-12,
                               atol=1e-12 * np.abs(f / force_scale).max())


def test_param_scales_make_force_dimensionless_consistently() -> None:
    # prime system of the BlueROV2 Heavy: v = 1.5 m/s, L = 0.457 m, ρ = 1000
    nu_scale, force_scale = nondim_scales(1.5, 0.457, 1000.0)
    scaled_force_identity(full_model(residual=False), nu_scale, force_scale, seed=7)


def test_param_scales_with_residual_modes() -> None:
    # a residual mode mixes v and r, so it is homogeneous only when they share a scale (L = 1)
    nu_scale, force_scale = nondim_scales(0.8, 1.0, 1025.0)
    scaled_force_identity(full_model(residual=True), nu_scale, force_scale, seed=8)


def test_param_scales_prime_values() -> None:
    v, L, rho = 1.5, 0.457, 1000.0
    nu_scale, force_scale = nondim_scales(v, L, rho)
    model = DampingModel([linear_term(), quadratic_term(), memory_term({"w": [3.0]})])
    s = dict(zip(model.parameter_names, model.param_scales(nu_scale, force_scale), strict=True))
    F = 0.5 * rho * L**2 * v**2
    # SNAME prime system: X'_u = X_u / (½ρL²U), N'_r = N_r / (½ρL⁴U), X'_uu = X_uu / (½ρL²)
    assert s["X_u"] == pytest.approx(1 / (0.5 * rho * L**2 * v), rel=1e-12)
    assert s["N_r"] == pytest.approx(1 / (0.5 * rho * L**4 * v), rel=1e-12)
    assert s["X_uu"] == pytest.approx(1 / (0.5 * rho * L**2), rel=1e-12)
    assert s["N_rr"] == pytest.approx(1 / (0.5 * rho * L**5), rel=1e-12)
    assert s["freq.w.c1"] == pytest.approx(v / 3.0 / F, rel=1e-12)


def test_regressor_column_is_alpha_times_basis_product() -> None:
    """Φ[:, :, j] = α_j(ν) B_j ν, bit for bit, for single-entry bases (the library, computed
    entry by entry), multi-atom ones (coriolis) and full matrices (a residual mode)."""
    rng = np.random.default_rng(5)
    nu = rng.normal(size=(200, 6))
    for model in (DampingModel([cross_term(library(rows=["X", "K"])), coriolis_term()]),
                  DampingModel([residual_term(rng.normal(size=(6, 2)))])):
        expected = np.zeros((200, 6, model.n_params))
        k = 0
        for term in model.terms:
            for b in term.bases:
                for B, alpha in b.atoms:
                    expected[:, :, k] += alpha(nu)[:, None] * (nu @ B.T)
                k += 1
        np.testing.assert_allclose(model.regressor(nu), expected, rtol=1e-14, atol=1e-14)
