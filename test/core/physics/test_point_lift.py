"""The lift and Magnus force of an element (dampest_ros.core.physics.point_lift) against a
direct computation of the force at a point and its moment, their zero power, and how they
are named, stored and offered."""

from __future__ import annotations

import numpy as np

from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.geometry import Geometry
from dampest_ros.core.physics.point_drag import PointSpec, point_library, point_spec, point_term
from dampest_ros.core.physics.point_lift import candidate_lifts


def direct(nu: np.ndarray, spec: PointSpec, c: float) -> np.ndarray:
    """The element's force written out, as the wrench [F; r × F], shape (N, 6): lift
    F = c (e·v_p) (‖v_p‖² e − (e·v_p) v_p) / ‖v_p‖, Magnus F = c ω × v_p less c ω × v at the
    origin, v_p = v + ω × r."""
    r = np.array(spec.position)
    vp = nu[:, :3] + np.cross(nu[:, 3:], r)
    if spec.force == "magnus":
        F = c * np.cross(nu[:, 3:], vp)
        return np.c_[F - c * np.cross(nu[:, 3:], nu[:, :3]), np.cross(r, F)]
    e = np.eye(3)[spec.axis]
    speed, along = np.linalg.norm(vp, axis=1)[:, None], (vp @ e)[:, None]
    F = c * along * (speed ** 2 * e - along * vp) / speed
    return np.c_[F, np.cross(r, F)]


SPECS = [PointSpec((0.42, -0.32, -0.08), 2, force="lift"),
         PointSpec((-0.1, 0.1, 0.24), 0, force="lift"),
         PointSpec((0.55, -0.15, 0.12), -1, force="magnus")]


def test_lift_and_magnus_are_the_forces_at_the_point_and_do_no_work() -> None:
    """The model's force and its regressor equal the written-out wrenches to 1e-12 (a float's
    lift, a bottle's, a Magnus force's lever arm); the force is perpendicular to v_p, so the power
    νᵀD(ν)ν is 0 (to 1e-12 of ‖τ‖‖ν‖) whatever the sign of c, and projecting onto the
    dissipative set leaves negative coefficients as they are."""
    rng = np.random.default_rng(7)
    model = DampingModel([point_term(SPECS)])
    nu = rng.normal(size=(400, 6)) * np.array([0.6, 0.5, 0.4, 0.8, 0.7, 0.6])
    theta = np.array([-37.0, 56.0, -5.4])
    want = sum(direct(nu, s, c) for s, c in zip(SPECS, theta, strict=True))
    np.testing.assert_allclose(model.force(nu, theta), want, atol=1e-12)
    np.testing.assert_allclose(model.regressor(nu) @ theta, want, atol=1e-12)
    scale = np.linalg.norm(want, axis=1) * np.linalg.norm(nu, axis=1)
    assert np.all(np.abs(model.dissipation(nu, theta)) <= 1e-12 * scale)
    np.testing.assert_array_equal(model.project(theta), theta)
    # a lift of the size of an element's drag: 0.5 c ‖v_p‖² at 45° to its axis
    vp = np.array([[1.0, 0.0, 1.0, 0.0, 0.0, 0.0]])
    lift = DampingModel([point_term([PointSpec((0.0, 0.0, 0.0), 2, force="lift")])])
    np.testing.assert_allclose(np.linalg.norm(lift.force(vp, np.array([2.0]))[0, :3]),
                               0.5 * 2.0 * 2.0, rtol=1e-12)


def test_names_and_model_file_entries_read_back() -> None:
    """Each name reads back to its element (``lift.w@(…)``, ``magnus@(…)``), its mapping
    too, and its mirror across the xz plane keeps the force and the axis."""
    for spec in SPECS:
        assert point_spec(spec.basis()) == spec
        assert PointSpec.from_dict(spec.to_dict()) == spec
        assert spec.mirror.mirror == spec and spec.mirror.force == spec.force
    assert [s.label for s in SPECS] == ["lift.w@(0.42,-0.32,-0.08)", "lift.u@(-0.1,0.1,0.24)",
                                        "magnus@(0.55,-0.15,0.12)"]


def mujoco_kutta(vp: np.ndarray, size: np.ndarray, rho: float = 1000.0) -> np.ndarray:
    """MuJoCo's Kutta lift of an ellipsoid with semi-axes ``size`` along the body axes at
    velocity ``vp`` (N, 3), written out from its documentation (computation/fluid.rst):
    f = C_K ρ A_proj (v̂·n̂) (n̂ × v) × v, n = (r_y r_z / r_x v_x, r_z r_x / r_y v_y,
    r_x r_y / r_z v_z), C_K = 1, A_proj = π √(Σ (r_j r_k)⁴ v_i² / Σ (r_j r_k)² v_i²)."""
    rx, ry, rz = size
    pair = np.array([ry * rz, rz * rx, rx * ry])
    area = np.pi * np.sqrt((pair ** 4 * vp ** 2).sum(1) / (pair ** 2 * vp ** 2).sum(1))
    n = vp * np.array([ry * rz / rx, rz * rx / ry, rx * ry / rz])
    n /= np.linalg.norm(n, axis=1)[:, None]
    cos = (n * vp).sum(1) / np.linalg.norm(vp, axis=1)
    return (rho * area * cos)[:, None] * np.cross(np.cross(n, vp), vp)


def test_a_thin_plates_lift_along_its_normal_is_mujocos_kutta_lift() -> None:
    """A wing (semi-axes 0.13, 0.3, 0.012 m) at (0.05, 0.4, −0.02) m in MuJoCo's fluid model:
    its Kutta lift (the force on the body, −D(ν)ν) is the lift along its normal w with
    c = ρ π r_x r_y = 122.5 N s²/m² (fitted: 122.9, the rest 0.8 % of its size) on flows at
    least 20° off the wing's plane (closer, MuJoCo's normal turns towards the flow)."""
    rng = np.random.default_rng(3)
    spec = PointSpec((0.05, 0.4, -0.02), 2, force="lift")
    nu = rng.normal(size=(4000, 6)) * np.array([0.6, 0.4, 0.3, 0.4, 0.3, 0.3])
    vp = nu[:, :3] + np.cross(nu[:, 3:], np.array(spec.position))
    nu = nu[np.abs(vp[:, 2]) > np.sin(np.radians(20.0)) * np.linalg.norm(vp, axis=1)]
    vp = nu[:, :3] + np.cross(nu[:, 3:], np.array(spec.position))
    f = mujoco_kutta(vp, np.array([0.13, 0.3, 0.012]))
    truth = -np.c_[f, np.cross(np.array(spec.position), f)]
    column = DampingModel([point_term([spec])]).regressor(nu)[:, :, 0]
    c = float((column * truth).sum() / (column * column).sum())
    assert abs(c / (1000.0 * np.pi * 0.13 * 0.3) - 1.0) < 0.005, c
    assert np.linalg.norm(truth - c * column) < 0.01 * np.linalg.norm(truth)


def test_candidate_lifts_are_slender_geoms_along_their_long_axis_flat_ones_their_normal(
        ) -> None:
    """frame_rov's shapes: a vertical float lifts along w, a bottle along u, a camera arm
    pitched 0.3 rad along its own long axis (cos 0.3, 0, −sin 0.3); a flat foam block along its
    normal w and a wing rolled 0.1 rad along its own normal (0, −sin 0.1, cos 0.1), both flat;
    a sphere and a geom at the origin are not offered."""
    geometry = Geometry.from_dict({"geoms": [
        {"name": "float", "size": [0.08, 0.08, 0.2], "position": [0.42, -0.32, -0.08]},
        {"name": "bottle", "size": [0.3, 0.09, 0.09], "position": [0.0, 0.0, -0.05]},
        {"name": "arm", "size": [0.1, 0.035, 0.035], "position": [0.55, -0.15, 0.12],
         "rpy": [0.0, 0.3, 0.0]},
        {"name": "foam", "size": [0.45, 0.35, 0.06], "position": [0.0, 0.0, -0.22]},
        {"name": "wing", "size": [0.13, 0.3, 0.012], "position": [0.05, 0.4, -0.02],
         "rpy": [0.1, 0.0, 0.0]},
        {"name": "ball", "size": [0.1, 0.1, 0.1], "position": [0.3, 0.0, 0.0]},
        {"name": "hull", "size": [0.8, 0.1, 0.1]}]})
    assert candidate_lifts(geometry) == [
        ((0.42, -0.32, -0.08), 2, False), ((0.0, 0.0, -0.05), 0, False),
        ((0.55, -0.15, 0.12), (0.9553, 0.0, -0.2955), False), ((0.0, 0.0, -0.22), 2, True),
        ((0.05, 0.4, -0.02), (0.0, -0.0998, 0.995), True)]
    assert [s.label for s in point_library([], candidate_lifts(geometry))[-4:]] == [
        "lift.w@(0,0,-0.22)", "area.w@(0,0,-0.22)", "lift.e(0,-0.0998,0.995)@(0.05,0.4,-0.02)",
        "area.e(0,-0.0998,0.995)@(0.05,0.4,-0.02)"]
    assert candidate_lifts(None) == []
