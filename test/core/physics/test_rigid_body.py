"""Rigid body (dampest_ros.core.physics.rigid_body): M, C(ν), g(η) and configuration checks."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from dampest_ros.core.physics.frames import matrix_from_euler
from dampest_ros.core.physics.rigid_body import (
    CA_ENTRIES,
    MUNK_ENTRIES,
    AddedMassTerms,
    ConfigError,
    RigidBody,
    added_coriolis_force,
    coriolis_force,
    coriolis_matrix,
    munk_moment,
    rigid_body_mass,
    skew,
)
from dampest_ros.core.physics.vehicle import Vehicle

PRESET_DIR = Path(__file__).resolve().parents[3] / "config" / "vehicles"
PRESETS = sorted(PRESET_DIR.glob("*.yaml"))


def load(path: Path) -> dict[str, Any]:
    with path.open() as f:
        return dict(yaml.safe_load(f))


def preset_body(path: Path) -> RigidBody:
    return Vehicle.from_dict(load(path)).body


def random_nu(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.normal(size=(n, 6)) * [1.0, 0.5, 0.5, 1.0, 1.0, 1.0]


def test_presets_found() -> None:
    names = {p.stem for p in PRESETS}
    assert {"bluerov2_heavy", "platform_a", "platform_b"} <= names


# --- mass matrix -----------------------------------------------------------------------------


@pytest.mark.parametrize("path", PRESETS, ids=lambda p: p.stem)
def test_mass_matrices_of_presets_are_spd(path: Path) -> None:
    body = preset_body(path)
    for M in (body.M_RB, body.M):
        np.testing.assert_array_equal(M, M.T)
        assert np.linalg.eigvalsh(M).min() > 0
    assert np.linalg.eigvalsh(body.added_mass).min() >= 0


def test_rigid_body_mass_structure() -> None:
    # Fossen eq. 3.44 with the parallel-axis theorem written out for r_g = (x, y, z)
    m, x, y, z = 12.0, 0.05, -0.02, 0.1
    inertia = np.array([[0.3, 0.01, 0.0], [0.01, 0.4, -0.02], [0.0, -0.02, 0.5]])
    M = rigid_body_mass(m, inertia, np.array([x, y, z]))
    expected = np.array([
        [m, 0, 0, 0, m * z, -m * y],
        [0, m, 0, -m * z, 0, m * x],
        [0, 0, m, m * y, -m * x, 0],
        [0, -m * z, m * y, 0, 0, 0],
        [m * z, 0, -m * x, 0, 0, 0],
        [-m * y, m * x, 0, 0, 0, 0],
    ], dtype=float)
    expected[3:, 3:] = inertia + m * np.array([
        [y * y + z * z, -x * y, -x * z],
        [-x * y, x * x + z * z, -y * z],
        [-x * z, -y * z, x * x + y * y],
    ])
    np.testing.assert_allclose(M, expected, rtol=0, atol=1e-15)


def test_skew_is_cross_product() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(100, 3)), rng.normal(size=(100, 3))
    np.testing.assert_allclose(np.einsum("nij,nj->ni", skew(a), b), np.cross(a, b), atol=1e-15)


# --- Coriolis ----------------------------------------------------------------------------------


@pytest.mark.parametrize("path", PRESETS, ids=lambda p: p.stem)
def test_coriolis_skew_symmetric_for_every_preset(path: Path) -> None:
    body = preset_body(path)
    nu = random_nu(np.random.default_rng(1), 100)
    for M in (body.M_RB, body.added_mass, body.M):
        C = coriolis_matrix(M, nu)
        assert C.shape == (100, 6, 6)
        scale = np.abs(C).max()
        assert scale > 0
        np.testing.assert_allclose(C + np.swapaxes(C, 1, 2), 0.0, atol=1e-12 * scale)
        # C(ν)ν computed without forming C
        np.testing.assert_allclose(np.einsum("nij,nj->ni", C, nu), coriolis_force(M, nu),
                                   rtol=0, atol=1e-12 * scale)
        # no power: νᵀ C(ν) ν = 0
        np.testing.assert_allclose(np.einsum("ni,ni->n", nu, coriolis_force(M, nu)), 0.0,
                                   atol=1e-12 * scale)


def test_coriolis_rigid_body_against_fossen_6_43() -> None:
    # C_RB(ν) = [[m S(ν2), −m S(ν2) S(r_g)], [m S(r_g) S(ν2), −S(I_o ν2)]] (Fossen 2011,
    # eq. 3.57, the form without ν1) is another parametrisation of the same force C_RB(ν)ν.
    rng = np.random.default_rng(2)
    m = 20.0
    r_g = np.array([0.02, -0.01, 0.05])
    inertia = np.diag([0.5, 0.7, 0.9])
    M = rigid_body_mass(m, inertia, r_g)
    I_o = M[3:, 3:]
    for nu in random_nu(rng, 20):
        S2, Sg = skew(nu[3:]), skew(r_g)
        C = np.block([[m * S2, -m * S2 @ Sg], [m * Sg @ S2, -skew(I_o @ nu[3:])]])
        np.testing.assert_allclose(coriolis_force(M, nu), C @ nu, rtol=0, atol=1e-13)


def test_coriolis_added_mass_munk_moment() -> None:
    # diagonal M_A = diag(A_11 … A_66), pure u and w: no force, and the Munk pitch moment
    # (ν1 × M_A ν1)_y = (A_11 − A_33) u w (Fossen 2011, eq. 6.50 with C_A on the left).
    MA = np.diag([2.0, 3.0, 11.0, 0.1, 0.2, 0.3])
    u, w = 0.7, -0.3
    f = coriolis_force(MA, np.array([u, 0, w, 0, 0, 0]))
    np.testing.assert_allclose(f, [0, 0, 0, 0, (2.0 - 11.0) * u * w, 0], atol=1e-15)


def test_rigid_body_coriolis_with_current() -> None:
    body = preset_body(PRESET_DIR / "bluerov2_heavy.yaml")
    rng = np.random.default_rng(3)
    nu, nu_r = random_nu(rng, 10), random_nu(rng, 10)
    np.testing.assert_allclose(
        body.coriolis_force(nu, nu_r),
        coriolis_force(body.M_RB, nu) + coriolis_force(body.added_mass, nu_r), atol=1e-14)
    np.testing.assert_allclose(body.coriolis_force(nu), coriolis_force(body.M, nu), atol=1e-13)


# --- restoring ----------------------------------------------------------------------------------


def fossen_4_6(W: float, B: float, r_g: np.ndarray, r_b: np.ndarray, phi: float,
               theta: float) -> np.ndarray:
    """g(η) of Fossen (2011) eq. 4.6, written out term by term."""
    xg, yg, zg = r_g
    xb, yb, zb = r_b
    cf, sf, ct, st = np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta)
    return np.array([
        (W - B) * st,
        -(W - B) * ct * sf,
        -(W - B) * ct * cf,
        -(yg * W - yb * B) * ct * cf + (zg * W - zb * B) * ct * sf,
        (zg * W - zb * B) * st + (xg * W - xb * B) * ct * cf,
        -(xg * W - xb * B) * ct * sf - (yg * W - yb * B) * st,
    ])


def test_restoring_matches_fossen_4_6() -> None:
    rng = np.random.default_rng(4)
    body = RigidBody(mass=30.0, inertia=np.diag([1.0, 1.2, 1.5]),
                     r_g=np.array([0.01, -0.02, 0.03]), r_b=np.array([-0.015, 0.01, -0.04]),
                     volume=0.0285, rho=1025.0)
    W, B = body.weight, body.buoyancy
    assert W != pytest.approx(B)
    angles = np.column_stack([rng.uniform(-np.pi, np.pi, 200), rng.uniform(-1.5, 1.5, 200),
                              rng.uniform(-np.pi, np.pi, 200)])
    g = body.restoring(matrix_from_euler(angles))
    assert g.shape == (200, 6)
    for k, (phi, theta, _) in enumerate(angles):
        np.testing.assert_allclose(g[k], fossen_4_6(W, B, body.r_g, body.r_b, phi, theta),
                                   rtol=0, atol=1e-12 * W)


def test_restoring_level_heavy_vehicle_sinks() -> None:
    # level attitude: g(η) = [0, 0, −(W − B), 0, 0, 0]; on the left-hand side, so a heavy
    # vehicle (W > B) is pushed down (+z in NED): M ν̇ = −g has ẇ > 0.
    body = RigidBody(mass=10.0, inertia=np.eye(3), volume=0.009, rho=1000.0, gravity=9.81)
    g = body.restoring(np.eye(3))
    W_minus_B = 10.0 * 9.81 - 1000.0 * 9.81 * 0.009
    np.testing.assert_allclose(g, [0, 0, -W_minus_B, 0, 0, 0], atol=1e-12)
    assert (-np.linalg.solve(body.M, g))[2] > 0


def test_restoring_moment_rights_a_pitched_vehicle() -> None:
    # buoyancy above gravity (z_b < z_g in FRD): nose-up pitch θ > 0 gives g_M > 0 on the left,
    # i.e. a nose-down restoring moment.
    body = RigidBody(mass=10.0, inertia=np.eye(3), r_b=np.array([0, 0, -0.05]), volume=0.01,
                     rho=1000.0)
    g = body.restoring(matrix_from_euler([0.0, 0.2, 0.0]))
    assert g[4] == pytest.approx(0.05 * body.buoyancy * np.sin(0.2), rel=1e-12)


def test_restoring_independent_of_heading() -> None:
    body = preset_body(PRESET_DIR / "platform_a.yaml")
    a = body.restoring(matrix_from_euler([0.3, -0.2, 0.0]))
    b = body.restoring(matrix_from_euler([0.3, -0.2, 2.1]))
    np.testing.assert_allclose(a, b, atol=1e-12)


# --- configuration errors --------------------------------------------------------------------


def base_vehicle() -> dict[str, Any]:
    return copy.deepcopy(load(PRESET_DIR / "bluerov2_heavy.yaml")["vehicle"])


def edit(**changes: Any) -> dict[str, Any]:
    d = base_vehicle()
    d.update(changes)
    return d


BAD_CONFIGS = {
    "negative mass": (edit(mass=-13.5), "mass"),
    "zero mass": (edit(mass=0.0), "mass"),
    "NaN inertia": (edit(inertia=[0.26, float("nan"), 0.37]), "inertia"),
    "non-SPD inertia": (edit(inertia=[0.26, -0.23, 0.37]), "inertia"),
    "non-symmetric inertia": (edit(inertia=[[0.26, 0.1, 0], [0, 0.23, 0], [0, 0, 0.37]]),
                              "inertia"),
    "added_mass wrong shape": (edit(added_mass=[6.36, 7.12, 18.68, 0.189, 0.135]), "added_mass"),
    "added_mass 5x5": (edit(added_mass=np.eye(5).tolist()), "added_mass"),
    "non-symmetric added_mass": (
        edit(added_mass=(np.diag([6.36, 7.12, 18.68, 0.189, 0.135, 0.222])
                         + 0.5 * np.eye(6, k=1)).tolist()), "added_mass"),
    "indefinite added_mass": (edit(added_mass=[6.36, 7.12, -18.68, 0.189, 0.135, 0.222]),
                              "added_mass"),
    "NaN r_g": (edit(r_g=[0.0, float("nan"), 0.0]), "r_g"),
    "r_b wrong length": (edit(r_b=[0.0, 0.0]), "r_b"),
    "negative volume": (edit(volume=-0.01), "volume"),
    "missing mass": ({k: v for k, v in base_vehicle().items() if k != "mass"}, "mass"),
}


@pytest.mark.parametrize("case", BAD_CONFIGS, ids=list(BAD_CONFIGS))
def test_bad_vehicle_config_names_the_field(case: str) -> None:
    d, field = BAD_CONFIGS[case]
    with pytest.raises(ConfigError) as info:
        RigidBody.from_dict(d)
    assert info.value.field == field
    assert str(info.value).startswith(f"{field}:")


def test_non_spd_total_mass_matrix() -> None:
    # M_A passes the PSD check (its negative eigenvalue is inside the 1e-9·max tolerance)
    # but the tiny yaw inertia cannot make M = M_RB + M_A positive definite.
    added = np.diag([1e6, 1.0, 1.0, 1.0, 1.0, -1e-4])
    with pytest.raises(ConfigError) as info:
        RigidBody(mass=1.0, inertia=np.eye(3) * 1e-6, added_mass=added)
    assert info.value.field == "mass matrix M_RB + M_A"


def test_good_config_accepts_full_matrices() -> None:
    d = edit(inertia=np.diag([0.26, 0.23, 0.37]).tolist(),
             added_mass=np.diag([6.36, 7.12, 18.68, 0.189, 0.135, 0.222]).ravel().tolist())
    body = RigidBody.from_dict(d)
    np.testing.assert_array_equal(body.M, RigidBody.from_dict(base_vehicle()).M)


def test_bad_preset_section_names_it() -> None:
    d = load(PRESET_DIR / "bluerov2_heavy.yaml")
    del d["damping"]
    with pytest.raises(ConfigError) as info:
        Vehicle.from_dict(d)
    assert info.value.field == "damping"


def test_thrusters_are_optional_and_asked_for_where_needed() -> None:
    """A vehicle without a thrusters section loads; what needs thrusters names them in one
    line; the force scale then comes from the measured τ (99th percentile of |τ_i|)."""
    d = load(PRESET_DIR / "bluerov2_heavy.yaml")
    del d["thrusters"]
    v = Vehicle.from_dict(d)
    assert v.thrusters is None
    with pytest.raises(ConfigError, match=r"^thrusters: simulating needs the vehicle's "
                                          r"thrusters, and vehicle 'bluerov2_heavy' has none: "
                                          r"add a thrusters: section .*, or give X$"):
        v.need_thrusters("simulating", "give X")
    tau = np.zeros((1000, 6))
    tau[:, 0] = np.linspace(-50.0, 50.0, 1000)   # X: |τ| up to 50 N
    tau[:, 5] = np.linspace(0.0, 4.0, 1000)      # N: up to 4 N·m; Y, Z, K, M never pushed
    force = np.percentile(np.abs(tau), 99, axis=0)  # an extent's
    scale = v.wrench_scale(force)
    np.testing.assert_allclose(scale[[0, 5]], [np.percentile(np.abs(tau[:, 0]), 99),
                                               np.percentile(tau[:, 5], 99)])
    # unpushed DOFs: 1 % of the largest of their group (forces, moments)
    np.testing.assert_allclose(scale[[1, 2]], 0.01 * scale[0])
    np.testing.assert_allclose(scale[[3, 4]], 0.01 * scale[5])
    with pytest.raises(ConfigError, match="no measured τ"):
        v.wrench_scale()
    heavy = Vehicle.from_dict(load(PRESET_DIR / "bluerov2_heavy.yaml"))
    assert heavy.thrusters is not None
    np.testing.assert_array_equal(heavy.wrench_scale(force), heavy.thrusters.max_wrench)


@pytest.mark.parametrize("value", [np.int64(13), np.float32(13.5), np.float64(13.5), 13, 13.5],
                         ids=["int64", "float32", "float64", "int", "float"])
def test_numpy_scalars_accepted_as_positive_numbers(value: Any) -> None:
    body = RigidBody(mass=value, inertia=np.eye(3), rho=np.float32(1025.0),
                     gravity=np.int64(10))
    assert type(body.mass) is float and body.mass == float(value)
    assert type(body.rho) is float and body.rho == 1025.0
    assert type(body.gravity) is float and body.gravity == 10.0
    np.testing.assert_array_equal(body.M_RB[:3, :3], float(value) * np.eye(3))


@pytest.mark.parametrize("value", [np.float64(-1.0), np.int64(0), np.float32("nan"),
                                   np.float64("inf"), True, "13.5", None],
                         ids=["negative", "zero", "nan", "inf", "bool", "str", "None"])
def test_non_positive_or_non_numbers_rejected(value: Any) -> None:
    with pytest.raises(ConfigError) as info:
        RigidBody(mass=value, inertia=np.eye(3))
    assert info.value.field == "mass"


# --- added-mass switches -------------------------------------------------------------------

def _body(terms: dict[str, Any] | None = None) -> RigidBody:
    d: dict[str, object] = {"mass": 30.0, "inertia": [1.0, 1.2, 1.5], "volume": 0.03,
                            "rho": 1000.0,
                            "added_mass": [5.0, 12.0, 14.0, 0.2, 0.9, 0.8]}
    if terms is not None:
        d["added_mass_terms"] = terms
    return RigidBody.from_dict(d)


def test_added_mass_switches_select_the_acting_terms() -> None:
    nu = np.array([[0.8, -0.3, 0.2, 0.1, -0.4, 0.5]])
    nu_dot = np.array([[0.1, 0.2, -0.3, 0.4, 0.0, -0.1]])
    full = _body()
    M_A = full.added_mass
    C_A = coriolis_force(M_A, nu)
    munk = np.zeros(6)
    munk[3:] = np.cross(nu[0, :3], M_A[:3, :3] @ nu[0, :3])
    # N_munk = (Y_v̇ − X_u̇) u v for a diagonal M_A
    assert munk[5] == pytest.approx((12.0 - 5.0) * 0.8 * -0.3)
    assert np.allclose(full.added_mass_force(nu, nu_dot), nu_dot @ M_A.T + C_A)
    no_munk = _body({"munk": False})
    assert np.allclose(no_munk.added_mass_force(nu, nu_dot), nu_dot @ M_A.T + C_A - munk)
    vel_only = _body({"inertial": False})
    assert np.allclose(vel_only.added_mass_force(nu, nu_dot), C_A)
    assert np.allclose(vel_only.M_inertial, vel_only.M_RB)
    none = _body({"inertial": False, "coriolis": False, "munk": False})
    assert np.allclose(none.added_mass_force(nu, nu_dot), 0.0)
    assert np.allclose(none.coriolis_force(nu), coriolis_force(none.M_RB, nu))


#: the entries a slender-AUV simulator zeroes beside the Munk moments: X←q, X←r, Z←q, Y←r
SLENDER = [["X", "q"], ["X", "r"], ["Z", "q"], ["Y", "r"]]


def _coupled_added_mass() -> np.ndarray:
    """A torpedo-like M_A with A12 ≠ 0 (Y_ṙ, Z_q̇ couplings), symmetric PSD."""
    M_A = np.diag([1.0, 34.0, 34.0, 0.15, 4.9, 4.9])
    M_A[1, 5] = M_A[5, 1] = -1.76
    M_A[2, 4] = M_A[4, 2] = 1.76
    return M_A


def test_c_a_entries_are_the_nonzero_entries_of_fossens_c_a() -> None:
    """CA_ENTRIES is exactly where C_A(ν) of a full random M_A is nonzero; the Munk entries
    (K,v) (K,w) (M,u) (M,w) (N,u) (N,v) carry v × (A11 v) when A12 = 0."""
    rng = np.random.default_rng(3)
    L = rng.normal(size=(6, 6))
    C = coriolis_matrix(L @ L.T, rng.normal(size=6))
    assert {(int(i), int(j)) for i, j in zip(*np.nonzero(C), strict=True)} == CA_ENTRIES
    assert len(CA_ENTRIES) == 18
    assert MUNK_ENTRIES == {(3, 1), (3, 2), (4, 0), (4, 2), (5, 0), (5, 1)}
    M_A = np.diag([5.0, 12.0, 14.0, 0.2, 0.9, 0.8])
    nu = rng.normal(size=(20, 6))
    only_munk = AddedMassTerms(coriolis_zero=tuple(sorted(CA_ENTRIES - MUNK_ENTRIES)))
    np.testing.assert_allclose(added_coriolis_force(M_A, only_munk, nu), munk_moment(M_A, nu),
                               rtol=0, atol=1e-12)


@pytest.mark.parametrize("A12", [False, True])
def test_zeroed_entries_remove_exactly_those_entries_of_c_a(A12: bool) -> None:
    """The acting C_A(ν)ν is (mask ⊙ C_A(ν)) ν entry by entry, with or without A12."""
    rng = np.random.default_rng(7)
    M_A = _coupled_added_mass() if A12 else np.diag([1.0, 34.0, 34.0, 0.15, 4.9, 4.9])
    nu = rng.normal(0.0, 0.5, (50, 6))
    terms = AddedMassTerms.from_dict({"munk": False, "coriolis_zero": SLENDER})
    C = coriolis_matrix(M_A, nu)
    want = np.einsum("nij,nj->ni", C, nu)
    for i, j in [(0, 4), (0, 5), (2, 4), (1, 5), *MUNK_ENTRIES]:
        want[:, i] -= C[:, i, j] * nu[:, j]
    np.testing.assert_allclose(added_coriolis_force(M_A, terms, nu), want, rtol=0, atol=1e-12)
    # the X force left is X←p only, which is identically zero: X = 0 for every ν
    assert np.abs(added_coriolis_force(M_A, terms, nu)[:, 0]).max() == 0.0
    assert np.abs(want[:, 0] - coriolis_force(M_A, nu)[:, 0]).max() > 1.0


def test_switches_are_shorthands_of_the_entry_mask() -> None:
    """Names and indices give the same set; munk: false = the six Munk entries; all 18 =
    coriolis: false; the canonical fields keep equal masks equal and as_dict round-trips."""
    by_name = AddedMassTerms.from_dict({"coriolis_zero": SLENDER})
    by_index = AddedMassTerms.from_dict({"coriolis_zero": [[0, 4], [0, 5], [2, 4], [1, 5]]})
    assert by_name == by_index and by_name.coriolis_zero == ((0, 4), (0, 5), (1, 5), (2, 4))
    munk = AddedMassTerms.from_dict({"coriolis_zero": [[i, j] for i, j in MUNK_ENTRIES]})
    assert munk == AddedMassTerms(munk=False) and munk.coriolis_zero == ()
    none = AddedMassTerms.from_dict({"coriolis_zero": [[i, j] for i, j in CA_ENTRIES]})
    assert none == AddedMassTerms(coriolis=False, munk=False)
    both = AddedMassTerms.from_dict({"munk": False, "coriolis_zero": SLENDER})
    assert AddedMassTerms.from_dict(both.as_dict()) == both
    assert AddedMassTerms.from_dict(both.as_parameters()) == both
    assert both.as_dict()["coriolis_zero"] == [["X", "q"], ["X", "r"], ["Y", "r"], ["Z", "q"]]
    assert int(both.mask.sum()) == 36 - 10 and both.zeroed == MUNK_ENTRIES | {
        (0, 4), (0, 5), (2, 4), (1, 5)}
    # switches only: the same three keys as before, no mask
    assert AddedMassTerms(munk=False).as_parameters() == {"inertial": True, "coriolis": True,
                                                          "munk": False}


@pytest.mark.parametrize("terms", [AddedMassTerms(), AddedMassTerms(munk=False),
                                   AddedMassTerms(inertial=False),
                                   AddedMassTerms(coriolis=False, munk=False)])
def test_switch_only_terms_give_the_old_numbers_bit_for_bit(terms: AddedMassTerms) -> None:
    """Files with switches only: C_A(ν)ν − v × (A11 v) as before (A12 = 0), not one bit off."""
    nu = np.random.default_rng(5).normal(size=(40, 6))
    M_A = np.diag([5.0, 12.0, 14.0, 0.2, 0.9, 0.8])
    old = (np.zeros_like(nu) if not terms.coriolis else coriolis_force(M_A, nu)
           - (0.0 if terms.munk else munk_moment(M_A, nu)))
    assert np.array_equal(added_coriolis_force(M_A, terms, nu), old)


@pytest.mark.parametrize(("terms", "match"), [
    ({"coriolis": False}, "munk: true needs coriolis"),
    ({"inertial": "yes"}, "added_mass_terms.inertial: must be true or false"),
    ({"lift": True}, "unknown key"),
    ({"coriolis_zero": [["X", "u"]]}, r"entry \(X, u\) = \[0, 0\] is zero in C_A.*row X: q, r"),
    ({"coriolis_zero": [["X", "Q"]]}, r"coriolis_zero\[0\]: column 'Q' is neither one of u v"),
    ({"coriolis_zero": [[6, 0]]}, r"row 6 is neither one of X Y Z K M N nor an index"),
    ({"coriolis_zero": [[True, 4]]}, r"row True is neither"),
    ({"coriolis_zero": [["X", "q"], [0, 4]]}, r"coriolis_zero\[1\]: \(X, q\) is listed twice"),
    ({"coriolis_zero": ["Xq"]}, r"coriolis_zero\[0\]: must be a \[row, column\] pair"),
    ({"coriolis_zero": "X q"}, "must be a list of"),
    ({"coriolis": False, "munk": False, "coriolis_zero": [["X", "q"]]},
     "coriolis: false already zeroes every entry"),
    ({"coriolis_mask": [1] * 35}, "must be 36 integers 0 or 1.*got 35 items"),
    ({"coriolis_mask": [2] * 36}, "must be 36 integers 0 or 1"),
])
def test_contradictory_switches_are_refused(terms: dict[str, object], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        _body(terms)  # type: ignore[arg-type]


def test_switches_on_a_zero_added_mass_are_refused() -> None:
    with pytest.raises(ConfigError, match="inertial, coriolis, munk set true but added_mass"):
        RigidBody.from_dict({"mass": 1.0, "inertia": [1, 1, 1],
                             "added_mass_terms": {"inertial": True}})
