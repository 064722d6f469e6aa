"""dampest identify on MuJoCo's fluid model: do the 95 % intervals of the default identify
contain the pure-axis damping coefficients MuJoCo's ellipsoid model defines?

Along one axis ν = s e_k (every geom then sees a velocity along one of its principal axes, so
no Kutta lift, and no Magnus force without rotation) MuJoCo's force in row k is exactly
a_k s + b_k s|s|. For a translation, per geom of semi-axes r (MuJoCo's documented ellipsoid
model): the viscous a = 3π D μ with D = (2/3)(r_x + r_y + r_z) and the drag
b = ρ (C_blunt A_k + C_slender (A_max − A_k)), A_k the area projected along k and A_max that
of the two largest semi-axes. A rotation moves the geoms off the origin through the water
too: its a and b are read off MuJoCo's own wrench at ±s (the form is exact, to 1e-14). The
identified counterpart is the same functional of θ: the model's row-k force along the axis
split into its s and s|s| parts, each a linear combination cᵀθ with σ = √(cᵀΣc).
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

from dampest_ros.cli.main import build_parser, main
from dampest_ros.core.identification.batch import Fit
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import coriolis_force
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.io.yaml_io import load_vehicle

mujoco = pytest.importorskip("mujoco")

#: Speeds (m/s, rad/s) at which the pure-axis forms are read.
SPEEDS = np.array([-0.8, -0.3, -0.05, 0.05, 0.3, 0.8])


def documented_translation(vehicle: Vehicle) -> np.ndarray:
    """(a, b) of u, v, w from MuJoCo's documented ellipsoid formulas, shape (2, 3)."""
    assert vehicle.geometry is not None
    mu, rho = vehicle.geometry.viscosity, vehicle.body.rho
    out = np.zeros((2, 3))
    for g in vehicle.geometry.geoms:
        r = np.asarray(g.size, dtype=float)
        big = np.sort(r)[::-1]
        a_max = np.pi * big[0] * big[1]
        for k in range(3):
            a_k = np.pi * np.prod(np.delete(r, k))
            out[0, k] += 3.0 * np.pi * (2.0 / 3.0) * r.sum() * mu
            out[1, k] += rho * (g.fluidcoef[0] * a_k + g.fluidcoef[1] * (a_max - a_k))
    return out


def pure_axis_truth(vehicle: Vehicle) -> np.ndarray:
    """(a_k, b_k) of every axis, shape (2, 6): MuJoCo's wrench at ±s less its added-mass
    Coriolis force, fitted by a s + b s|s| (exact); the translations equal the documented
    formulas when no geom is rotated (frame_rov's camera arm is)."""
    from dampest_ros.core.simulation.mujoco_backend import compile_model

    assert vehicle.geometry is not None
    m = compile_model(vehicle.body, vehicle.geometry, 0.002)
    d = mujoco.MjData(m)
    X = np.c_[SPEEDS, SPEEDS * np.abs(SPEEDS)]
    out = np.zeros((2, 6))
    for k in range(6):
        f = np.zeros(len(SPEEDS))
        for n, s in enumerate(SPEEDS):
            nu = np.zeros(6)
            nu[k] = s
            d.qvel[:] = nu
            mujoco.mj_forward(m, d)
            # D(ν)ν = −(fluid wrench) − C_A(ν)ν
            f[n] = -(d.qfrc_fluid[k] + coriolis_force(vehicle.body.added_mass, nu)[k])
        out[:, k], *_ = np.linalg.lstsq(X, f, rcond=None)
        np.testing.assert_allclose(X @ out[:, k], f, atol=1e-9 * np.abs(f).max())
    if not any(any(g.rpy) for g in vehicle.geometry.geoms):
        # the formulas of documented_translation are those of geoms along the body axes
        np.testing.assert_allclose(out[:, :3], documented_translation(vehicle), rtol=1e-9)
    return out


def pure_axis_functionals(model: DampingModel) -> np.ndarray:
    """c with (a_k, b_k) = c[:, k] θ for the model's row-k force along axis k, shape
    (2, 6, p); NaN where a column along the axis is not of the form a s + b s|s| (s² or a
    higher power: the terms mix)."""
    X = np.c_[SPEEDS, SPEEDS * np.abs(SPEEDS), SPEEDS ** 2]
    out = np.zeros((2, 6, model.n_params))
    for k in range(6):
        nu = np.zeros((len(SPEEDS), 6))
        nu[:, k] = SPEEDS
        Phi = model.regressor(nu)[:, k, :]
        c, *_ = np.linalg.lstsq(X, Phi, rcond=None)
        mixed = (np.abs(X @ c - Phi).max(axis=0) > 1e-9) | (np.abs(c[2]) > 1e-9)
        # round-off of the split (≤ 1e-15) is no contribution
        out[:, k] = np.where(mixed, np.nan, np.where(np.abs(c[:2]) > 1e-9, c[:2], 0.0))
    return out


class Coverage(NamedTuple):
    """Per axis (u..r): truth, estimate, σ and whether the 95 % interval holds the truth."""

    truth: np.ndarray      # (2, 6): linear a, quadratic b
    value: np.ndarray      # (2, 6)
    std: np.ndarray        # (2, 6)
    inside: np.ndarray     # (2, 6) bool


def coverage(vehicle: Vehicle, model: DampingModel, fit: Fit) -> Coverage:
    """The pure-axis truths against the fit's values and 95 % intervals (the fit's own
    Student-t quantile, :meth:`Fit.quantile`)."""
    c = pure_axis_functionals(model)
    value = np.einsum("akp,p->ak", np.nan_to_num(c), fit.theta)
    cov = np.nan_to_num(fit.cov)
    std = np.sqrt(np.einsum("akp,pq,akq->ak", np.nan_to_num(c), cov, np.nan_to_num(c)))
    std[np.isnan(c).any(axis=2)] = np.nan
    truth = pure_axis_truth(vehicle)
    return Coverage(truth, value, std, np.abs(value - truth) <= fit.quantile(0.95) * std)


@pytest.mark.parametrize("vehicle", ["torpedo_auv", "bluerov2_heavy_mujoco", "box_rov",
                                     "sled_auv", "frame_rov", "winged_auv", "tooled_rov"])
def test_documented_pure_axis_drag_is_mujocos(vehicle: str) -> None:
    """MuJoCo's wrench along each axis is a s + b s|s| to 1e-9, and along u, v, w its a and b
    are the documented ellipsoid formulas (pure_axis_truth asserts both); e.g. the torpedo's
    surge: a = 3π (2/3)(0.8 + 0.1 + 0.1) 1e-3 + four fins = 0.0105 N s/m, b = 92.17 N s²/m²."""
    truth = pure_axis_truth(load_vehicle(vehicle))
    assert np.all(truth[1] > 0) and np.all(truth[0] > 0)
    if vehicle == "torpedo_auv":
        np.testing.assert_allclose(truth[:, 0], [0.01045522, 92.174328], rtol=1e-6)


def test_pure_axis_functionals_sum_the_terms_that_act_along_the_axis() -> None:
    """X_uu and X_uU both act as u|u| along surge (their sum is the pure-axis drag), X_uAvw
    not at all; a u·u column (X_uxu) is neither s nor s|s| (NaN: surge's coefficients mix,
    :func:`coverage` leaves the axis out)."""
    from dampest_ros.core.physics.terms import cross_term, library, linear_term, quadratic_term

    specs = {s.label: s for s in library(rows=["X"])}
    model = DampingModel([linear_term(), quadratic_term(),
                          cross_term([specs["X_uU"], specs["X_uAvw"]])])
    c = pure_axis_functionals(model)
    names = model.parameter_names
    assert [names[k] for k in np.flatnonzero(c[1, 0])] == ["X_uu", "X_uU"]
    assert [names[k] for k in np.flatnonzero(c[0, 0])] == ["X_u"]
    np.testing.assert_allclose(c[1, 0][c[1, 0] != 0], [1.0, 1.0])
    mixed = DampingModel([quadratic_term(), cross_term([specs["X_uxu"]])])
    c = pure_axis_functionals(mixed)[:, 0]
    assert np.isnan(c[:, -1]).all() and not np.isnan(c[:, :-1]).any()


def session_coverage(bags: list[Path], vehicle: str) -> Coverage:
    """The default ``dampest identify`` of one session flown as ``bags`` (their samples
    joined as segments: the default's selection and fit of one log) and its pure-axis
    coverage."""
    from dampest_ros.cli import identify
    from dampest_ros.cli.inputs import load_samples
    from dampest_ros.core.identifier import DampingIdentifier
    from dampest_ros.core.signals.samples import Samples

    v = load_vehicle(vehicle)
    args = build_parser().parse_args(["identify", str(bags[0]), "--vehicle", vehicle])
    samples = Samples.concatenate([load_samples(str(b), v, args, []) for b in bags])
    model = identify.default_selection(samples, identify.structure_of(args, v)[0], v, args)
    fitted = DampingIdentifier(v, method=args.method, cutoff=args.cutoff,
                               structure=model).fit(samples).fit_
    assert fitted is not None
    return coverage(v, model, fitted)


def session_inside(vehicle: str, seeds: range, root: Path) -> float:
    """Share of the pure-axis intervals holding the truth over ``seeds``: per seed a session
    of protocol B (600 s) and protocol axes (300 s), realistic sensors, the default identify
    (an axis whose terms mix has no clean truth: left out)."""
    inside = []
    for seed in seeds:
        bags = []
        for name, duration in (("B", "600"), ("axes", "300")):
            bags.append(root / f"{name}{seed}")
            assert main(["simulate", "--backend", "mujoco", "--vehicle", vehicle, "--protocol",
                         name, "--duration", duration, "--seed", str(seed),
                         "--out", str(bags[-1])]) == 0
        c = session_coverage(bags, vehicle)
        inside.append(np.where(np.isnan(c.std), np.nan, c.inside))
    return float(np.nanmean(inside))


@pytest.mark.slow
@pytest.mark.parametrize("vehicle", ["torpedo_auv", "bluerov2_heavy_mujoco"])
def test_pure_axis_intervals_of_the_default_identify_hold_mujocos_drag(
        vehicle: str, tmp_path: Path) -> None:
    """Seeds 1–5, a session of protocol B and the pure-axis legs of protocol axes: the 95 %
    intervals of the 12 pure-axis coefficients (linear and quadratic, u..r) hold the truth in
    ≥ 90 % of the cases. Measured (README): torpedo 60 of 60, ROV 56 of 60. The legs let the
    pure-axis check see where the model's law along an axis departs from MuJoCo's (the
    torpedo's surge +37 %: its projected area changes fastest near the axis) and scale that
    row's σ by the Birge ratio (up to 8.5 here); on protocol B alone no DOF is flown along
    its axis, the check says so, and 19 of 60 intervals held."""
    assert session_inside(vehicle, range(1, 6), tmp_path) >= 0.9


@pytest.mark.slow
@pytest.mark.parametrize("vehicle", ["box_rov", "sled_auv", "frame_rov", "winged_auv",
                                     "tooled_rov"])
def test_pure_axis_intervals_hold_on_the_untuned_geometries(vehicle: str,
                                                           tmp_path: Path) -> None:
    """The same on the five geometries nothing was tuned on, seeds 1–3. Measured (README):
    34/34, 34/36, 36/36, 36/36, 36/36."""
    assert session_inside(vehicle, range(1, 4), tmp_path) >= 0.9
