"""The element drag term (dampest_ros.core.physics.point_drag) against a direct computation of
the force at a point and its moment."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.directions import BODY_AXES, direction, geom_axes
from dampest_ros.core.physics.geometry import Geometry
from dampest_ros.core.physics.point_drag import (
    PointSpec,
    candidate_points,
    mirror_pairs,
    point_library,
    point_spec,
    point_term,
)
from dampest_ros.core.physics.rigid_body import ConfigError


def direct(nu: np.ndarray, spec: PointSpec, c: float) -> np.ndarray:
    """D(ν)ν of one element, written out: F = c s v_p,a e_a at r with v_p = v + ω × r and
    s = ‖v_p‖ or |v_p,a|; the wrench [F; r × F], shape (N, 6)."""
    r = np.array(spec.position)
    vp = nu[:, :3] + np.cross(nu[:, 3:], r)
    speed = np.linalg.norm(vp, axis=1) if spec.speed == "|U|" else np.abs(vp[:, spec.axis])
    F = np.zeros_like(vp)
    F[:, spec.axis] = c * speed * vp[:, spec.axis]
    return np.c_[F, np.cross(r, F)]


def test_columns_are_the_force_at_the_point_and_its_moment() -> None:
    """Each column is the drag of a unit coefficient at its point (force along its axis and
    moment r × F), both speeds; the model's force, the regressor and the written-out wrench
    agree to 1e-12, and the power is c s v_p,a² ≥ 0."""
    rng = np.random.default_rng(5)
    specs = point_library([(p, BODY_AXES) for p in
                           ((0.3, 0.0, 0.2), (0.0, -0.3, 0.21), (-0.45, 0.1, -0.22))])
    model = DampingModel([point_term(specs)])
    nu = rng.normal(size=(300, 6)) * np.array([0.5, 0.4, 0.3, 0.6, 0.5, 0.4])
    theta = rng.uniform(5.0, 50.0, len(specs))
    Phi = model.regressor(nu)
    for k, spec in enumerate(specs):
        np.testing.assert_allclose(Phi[:, :, k], direct(nu, spec, 1.0), rtol=0, atol=1e-12)
    total = sum(direct(nu, s, c) for s, c in zip(specs, theta, strict=True))
    np.testing.assert_allclose(model.force(nu, theta), total, rtol=0, atol=1e-11)
    np.testing.assert_allclose(Phi @ theta, total, rtol=0, atol=1e-11)
    power = model.dissipation(nu, theta)
    assert power.min() > 0.0
    # a negative coefficient is not dissipative: the term's projection clips it at 0
    assert model.terms[0].project(-theta).max() == 0.0


def test_one_coefficient_acts_in_the_force_and_both_lever_moments() -> None:
    """Heave drag at (0.3, 0, 0.2) m: Z and the pitch moment M = −x Z, nothing in K or N."""
    spec = PointSpec((0.3, 0.0, 0.2), 2)
    nu = np.array([[0.0, 0.0, 0.5, 0.0, 0.0, 0.0]])
    f = DampingModel([point_term([spec])]).force(nu, np.array([40.0]))[0]
    np.testing.assert_allclose(f, [0.0, 0.0, 10.0, 0.0, -3.0, 0.0], atol=1e-12)
    # a pitch rate q = 1 rad/s moves the point at v_p = ω × r = (0.2, 0, −0.3) m/s: on its
    # speed Z = 40 · √0.13 · (−0.3), on its normal speed Z = 40 · 0.3 · (−0.3); M = −x Z
    nu = np.array([[0.0, 0.0, 0.0, 0.0, 1.0, 0.0]])
    for s, speed in (("|U|", np.sqrt(0.13)), ("normal", 0.3)):
        one = DampingModel([point_term([PointSpec(spec.position, 2, s)])])
        z = -12.0 * speed
        np.testing.assert_allclose(one.force(nu, np.array([40.0]))[0],
                                   [0.0, 0.0, z, 0.0, -0.3 * z, 0.0], atol=1e-12)


def test_names_read_back_and_bad_entries_name_the_field() -> None:
    for spec in point_library([((0.3, -0.125, 0.2), BODY_AXES)]):
        assert point_spec(spec.basis()) == spec
        assert PointSpec.from_dict(spec.to_dict()) == spec
    assert PointSpec((0.3, 0.0, 0.2), 2).label == "drag.w|U|@(0.3,0,0.2)"
    assert PointSpec((0.3, 0.0, 0.2), 2, "normal").label == "drag.ww@(0.3,0,0.2)"
    with pytest.raises(ConfigError, match=r"damping\.point\[0\]\.axis.*along u, v, w or a dir"):
        PointSpec.from_dict({"position": [0, 0, 1], "axis": "q"}, "damping.point[0]")
    with pytest.raises(ConfigError, match=r"point\.speed"):
        PointSpec.from_dict({"position": [0, 0, 1], "axis": "w", "speed": "fast"})
    with pytest.raises(ConfigError, match=r"point\.position"):
        PointSpec.from_dict({"position": [0, 1], "axis": "w"})


def test_directions_off_the_body_axes_read_back() -> None:
    """An element along a direction off the body axes: its name carries the direction (4
    decimals, the largest component positive), reads back exactly, its file entry too; a
    direction that is a body axis is that axis (the same name and numbers as today); a zero or
    non-finite direction is refused naming the field."""
    e = direction((-0.6, -0.8, 0.0))
    assert e == (0.6, 0.8, 0.0) and direction((0.0, 2.0, 1e-12)) == 1
    assert direction(np.array([0.8008, 0.491, 0.3429])) == (0.8008, 0.491, 0.3429)
    where = (0.44, 0.21, -0.04)
    assert PointSpec(where, e, force="lift").label == "lift.e(0.6,0.8,0)@(0.44,0.21,-0.04)"
    assert PointSpec(where, e, "normal").label == "drag.e(0.6,0.8,0)e@(0.44,0.21,-0.04)"
    for spec in point_library([(where, geom_axes((0.3, -0.35, 0.55)))],
                              [(where, geom_axes((0.3, -0.35, 0.55))[0], True)]):
        assert not isinstance(spec.axis, int)
        assert point_spec(spec.basis()) == spec
        assert PointSpec.from_dict(spec.to_dict()) == spec
        assert spec.mirror.mirror == spec
    assert PointSpec.from_dict({"position": [0, 0, 1], "axis": [0, 0, -3]}) == \
        PointSpec((0.0, 0.0, 1.0), 2)
    assert PointSpec.from_dict({"position": [0, 0, 1], "axis": [3, 4, 0], "force": "area"}) \
        == PointSpec((0.0, 0.0, 1.0), (0.6, 0.8, 0.0), force="area")
    for bad in ([0, 0, 0], [1, 2], [1, float("nan"), 0], ["u", 0, 0]):
        with pytest.raises(ConfigError, match=r"damping\.point\[0\]\.axis.*three finite"):
            PointSpec.from_dict({"position": [0, 0, 1], "axis": bad}, "damping.point[0]")


def test_a_force_along_a_direction_is_its_rotation_of_the_body_axis_force() -> None:
    """The drag, area drag and lift of an element along a unit direction e are those of a
    body-axis element of a vehicle turned so that its axis is e: with a rotation R taking
    e_x to e = (0.6, 0.8, 0) and r to R r, the force at ν equals R applied to the body-axis
    force at the turned velocity Rᵀ ν (force and moment)."""
    rng = np.random.default_rng(8)
    R = np.array([[0.6, -0.8, 0.0], [0.8, 0.6, 0.0], [0.0, 0.0, 1.0]])
    r = np.array([0.2, -0.1, 0.3])
    where = tuple(map(float, R @ r))
    nu = rng.normal(0.0, 0.4, (50, 6))
    turned = np.hstack([nu[:, :3] @ R, nu[:, 3:] @ R])  # Rᵀ ν per sample
    for speed, force in (("|U|", "drag"), ("normal", "drag"), ("|U|", "area"),
                         ("|U|", "lift")):
        there = DampingModel([point_term([PointSpec(where, (0.6, 0.8, 0.0), speed, force)])])
        axis = DampingModel([point_term([PointSpec((0.2, -0.1, 0.3), 0, speed, force)])])
        f = axis.force(turned, np.array([7.0]))
        np.testing.assert_allclose(there.force(nu, np.array([7.0])),
                                   np.hstack([f[:, :3] @ R.T, f[:, 3:] @ R.T]), atol=1e-9)


def test_candidate_points_are_the_geoms_off_the_origin_else_a_generic_set() -> None:
    geometry = Geometry.from_dict({"geoms": [
        {"size": [0.5, 0.4, 0.2]}, {"size": [0.1, 0.1, 0.1], "position": [0.3, 0.0, 0.2]},
        {"size": [0.1, 0.1, 0.1], "position": [0.3, 0.0, 0.2]},
        {"size": [0.1, 0.1, 0.1], "position": [0.0, -0.3, 0.2]}]})
    assert candidate_points(geometry, 1.0) == [((0.3, 0.0, 0.2), BODY_AXES),
                                               ((0.0, -0.3, 0.2), BODY_AXES)]
    assert candidate_points(None, 2.0) == [
        (p, BODY_AXES) for p in ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 0.5, 0.0),
                                 (0.0, -0.5, 0.0), (0.0, 0.0, 0.5), (0.0, 0.0, -0.5))]
    assert len(point_library(candidate_points(None, 2.0))) == 36


def test_mirror_pairs_are_the_twins_across_the_xz_plane() -> None:
    """Drags at (0.1, ±0.2, 0) along the same axis on the same speed pair up; a drag on the
    centre line, or at a point without its twin, does not."""
    specs = point_library([(p, BODY_AXES) for p in
                           ((0.1, 0.2, 0.0), (0.0, 0.0, 0.3), (0.1, -0.2, 0.0), (0.5, 0.4, 0.0))])
    pairs = mirror_pairs(specs)
    assert [(specs[i].label, specs[j].label) for i, j in pairs][:2] == [
        ("drag.u|U|@(0.1,0.2,0)", "drag.u|U|@(0.1,-0.2,0)"),
        ("drag.v|U|@(0.1,0.2,0)", "drag.v|U|@(0.1,-0.2,0)")]
    assert len(pairs) == 6


def test_a_flat_elements_area_drag_is_along_its_velocity_on_its_normal_speed() -> None:
    """area.w at (0.05, 0.4, −0.02) m, c = 60 N s²/m²: the force c |v_p,w| v_p along the
    element's own velocity and its moment r × F (to 1e-12), power c |v_p,w| ‖v_p‖² ≥ 0, a
    negative coefficient clipped at 0; surging edge-on it has no drag, at 45° in the xz plane
    (u = w = 0.5 m/s) it is 60 · 0.5 · (0.5, 0, 0.5) = (15, 0, 15) N."""
    rng = np.random.default_rng(11)
    spec = PointSpec((0.05, 0.4, -0.02), 2, force="area")
    model = DampingModel([point_term([spec])])
    nu = rng.normal(size=(300, 6)) * np.array([0.5, 0.4, 0.3, 0.6, 0.5, 0.4])
    r = np.array(spec.position)
    vp = nu[:, :3] + np.cross(nu[:, 3:], r)
    F = 60.0 * np.abs(vp[:, 2:]) * vp
    np.testing.assert_allclose(model.force(nu, np.array([60.0])), np.c_[F, np.cross(r, F)],
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(model.dissipation(nu, np.array([60.0])),
                               60.0 * np.abs(vp[:, 2]) * (vp ** 2).sum(1), rtol=1e-12)
    assert model.terms[0].project(np.array([-60.0]))[0] == 0.0
    f = model.force(np.array([[1.0, 0, 0, 0, 0, 0], [0.5, 0, 0.5, 0, 0, 0]]), np.array([60.0]))
    np.testing.assert_allclose(f[:, :3], [[0.0, 0.0, 0.0], [15.0, 0.0, 15.0]], atol=1e-12)
    assert spec.label == "area.w@(0.05,0.4,-0.02)"
    assert point_spec(spec.basis()) == spec and PointSpec.from_dict(spec.to_dict()) == spec
    assert spec.mirror.mirror == spec and spec.mirror.force == "area"
