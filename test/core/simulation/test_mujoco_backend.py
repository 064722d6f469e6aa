"""MuJoCo backend (dampest_ros.core.simulation.mujoco_backend): what MuJoCo's fluid model applies,
measured, and the faithful vehicle description of the two presets."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from dampest_ros.core.identification.regression import target
from dampest_ros.core.physics.frames import euler_from_matrix, quat_to_matrix
from dampest_ros.core.physics.geometry import Geometry
from dampest_ros.core.physics.rigid_body import AddedMassTerms, ConfigError, coriolis_force
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.samples import Samples
from dampest_ros.core.simulation.effects import Effects
from dampest_ros.core.simulation.excitation import make_excitation
from dampest_ros.core.simulation.mujoco_backend import (
    MujocoSimulator,
    compile_model,
    plant_added_mass,
    plant_vehicle,
)
from dampest_ros.core.simulation.simulate import run
from dampest_ros.io.yaml_io import load_vehicle

mujoco = pytest.importorskip("mujoco")

PRESETS = ("bluerov2_heavy_mujoco", "torpedo_auv", "box_rov", "sled_auv", "frame_rov",
           "winged_auv", "tooled_rov")
PRESETS_DIR = Path(__file__).resolve().parents[3] / "config" / "vehicles"


def _quiet(v: Vehicle, coef: tuple[float, ...] = (0, 0, 0, 0, 0), viscosity: float = 0.0
           ) -> Vehicle:
    """The vehicle with every geom's drag and lift coefficients replaced."""
    assert v.geometry is not None
    geoms = tuple(replace(g, fluidcoef=tuple(float(c) for c in coef))
                  for g in v.geometry.geoms)
    return replace(v, geometry=Geometry(geoms, viscosity))


def _fluid(sim: MujocoSimulator, nu: np.ndarray) -> np.ndarray:
    """MuJoCo's fluid wrench at body velocity ν (FRD), level attitude, body frame."""
    d = sim.data
    d.qvel[:3], d.qvel[3:] = nu[:3], nu[3:]
    mujoco.mj_forward(sim.model, d)
    return np.array(d.qfrc_fluid)


@pytest.mark.parametrize("name", PRESETS)
def test_presets_carry_the_added_mass_mujoco_applies(name: str) -> None:
    v = load_vehicle(name)
    assert v.geometry is not None
    M_A = plant_added_mass(compile_model(v.body, v.geometry, 0.005), v.body.rho)
    assert np.allclose(v.body.added_mass, M_A, rtol=1e-5, atol=1e-5 * np.abs(M_A).max())
    assert v.body.added_mass_terms == AddedMassTerms(inertial=False)
    assert np.allclose(plant_vehicle(v).body.added_mass, M_A)


def test_no_inertial_added_mass_a_step_force_sees_m_rb() -> None:
    v = load_vehicle("torpedo_auv")
    sim = MujocoSimulator(_quiet(v), dt=0.01)
    sim.data.qfrc_applied[:] = [10.0, 0, 0, 0, 0, 0]
    mujoco.mj_forward(sim.model, sim.data)
    # M_RB ν̇ = [F, 0, W, 0, 0, 0] (gravity at r_g below the origin: no moment when level);
    # with the inertial added mass it would be (M_RB + M_A) ν̇
    wrench = np.array([10.0, 0, v.body.weight, 0, 0, 0])
    assert np.allclose(sim.data.qacc, np.linalg.solve(v.body.M_RB, wrench), rtol=1e-9)
    assert not np.allclose(sim.data.qacc, np.linalg.solve(v.body.M, wrench), rtol=1e-3)


@pytest.mark.parametrize("name", PRESETS)
def test_velocity_terms_are_fossens_coriolis_of_the_composite_added_mass(name: str) -> None:
    """Fins and housings off the origin, rotated: Σ per-geom forces = −C_A(ν)ν of M_A."""
    v = load_vehicle(name)
    sim = MujocoSimulator(_quiet(v), dt=0.01)
    rng = np.random.default_rng(3)
    for _ in range(5):
        nu = rng.normal(0, [0.5, 0.5, 0.5, 0.8, 0.8, 0.8])
        expected = -coriolis_force(v.body.added_mass, nu)
        assert np.allclose(_fluid(sim, nu), expected, rtol=1e-4, atol=1e-6)


def test_drag_uses_the_euclidean_speed() -> None:
    """A sphere (projected area the same in every direction) with blunt drag only:
    X(u, v) = −ρ A C ‖v‖ u, so adding a sway speed equal to u multiplies X by √2."""
    v = load_vehicle("bluerov2_heavy_mujoco")
    sphere = Geometry.from_dict({"geoms": [{"name": "ball", "size": [0.2, 0.2, 0.2]}]})
    sim = MujocoSimulator(_quiet(replace(v, geometry=sphere), (0.5, 0, 0, 0, 0)))
    x_alone = _fluid(sim, np.array([0.5, 0, 0, 0, 0, 0]))[0]
    x_with_sway = _fluid(sim, np.array([0.5, 0.5, 0, 0, 0, 0]))[0]
    assert x_alone == pytest.approx(-v.body.rho * np.pi * 0.2**2 * 0.5 * 0.5 * 0.5, rel=1e-9)
    assert x_with_sway / x_alone == pytest.approx(np.sqrt(2.0), rel=1e-9)


def test_no_buoyancy_from_the_fluid_model_and_the_plant_buoys() -> None:
    v = load_vehicle("torpedo_auv")
    sim = MujocoSimulator(_quiet(v), dt=0.02)
    mujoco.mj_forward(sim.model, sim.data)
    assert np.allclose(sim.data.qfrc_fluid, 0.0)
    # W − B = 33.0 · 9.81 − 1000 · 9.81 · 0.03351 < 0: lighter than water, rises (−z NED)
    # with ẇ = (W − B) / m (B is applied at r_b; the fluid model adds none)
    for _ in range(25):
        sim.step(np.zeros(v.thrusters.count))
    net = v.body.weight - v.body.buoyancy
    assert sim.nu[2] == pytest.approx(net / v.body.mass * 0.5, rel=1e-9)


def _samples(traj: Any) -> Samples:
    R = quat_to_matrix(traj.quaternion)
    n = len(traj.t)
    return Samples(t=traj.t, nu=traj.nu, nu_dot=traj.nu_dot, tau=traj.tau,
                   euler=euler_from_matrix(R), depth=traj.position[:, 2],
                   segment=np.zeros(n, dtype=np.int64))


@pytest.mark.parametrize("name", PRESETS)
def test_faithful_description_target_equals_the_true_fluid_wrench(name: str) -> None:
    """y = τ − M_RB ν̇ − C_RB ν − C_A ν − g(η) is what remains of the water's wrench
    once its added-mass velocity terms are taken out: −hydro − C_A(ν)ν, to 1e-9."""
    v = load_vehicle(name)
    traj = run(v, make_excitation("B", v, 20.0, seed=2), dt=0.02, backend="mujoco")
    assert traj.hydro is not None and np.abs(traj.hydro).max() > 1.0
    y = target(_samples(traj), v.body)
    expected = -traj.hydro - coriolis_force(v.body.added_mass, traj.nu)
    assert np.abs(y - expected).max() < 1e-9 * max(1.0, float(np.abs(expected).max()))


def test_current_is_mujocos_wind() -> None:
    v = load_vehicle("bluerov2_heavy_mujoco")
    drift = MujocoSimulator(v, Effects(current=(0.3, -0.1, 0.05)))
    still = MujocoSimulator(v)
    for _ in range(10):
        drift.step(drift.wrench_to_command(np.array([20.0, 0, 0, 0, 0, 1.0])))
    # the same state, still water, moving at the velocity relative to the water instead
    still.data.qpos[:] = drift.data.qpos
    still.data.qvel[:] = drift.data.qvel
    still.data.qvel[:3] -= [0.3, -0.1, 0.05]
    mujoco.mj_forward(still.model, still.data)
    mujoco.mj_forward(drift.model, drift.data)
    assert np.allclose(drift.data.qfrc_fluid, still.data.qfrc_fluid, rtol=1e-9, atol=1e-12)
    traj = drift.trajectory()
    assert np.allclose(traj.current, [0.3, -0.1, 0.05])


def test_effects_of_the_fluid_model_are_refused() -> None:
    v = load_vehicle("torpedo_auv")
    with pytest.raises(ConfigError, match="memory: not available on the mujoco backend"):
        MujocoSimulator(v, Effects(memory=({"dof": "u", "rate": 1.0, "c": 1.0},)))


def test_bad_geometry_is_named_with_its_file(tmp_path: Path) -> None:
    v = load_vehicle("bluerov2_heavy")
    with pytest.raises(ConfigError, match="no geometry: block"):
        MujocoSimulator(v)
    doc = yaml.safe_load((PRESETS_DIR / "torpedo_auv.yaml").read_text())
    for geo, field in (({"geoms": [{"size": [0.1, -0.2, 0.1]}]}, r"geoms\[0\].size"),
                       ({"geoms": [{"size": [0.1, 0.2]}]}, r"geoms\[0\].size"),
                       ({"geoms": []}, "geometry.geoms"),
                       ({"geoms": [{"size": [1, 1, 1]}], "viscosity": -1}, "viscosity"),
                       ({"geoms": [{"size": [1, 1, 1], "mass": 3}]}, r"geoms\[0\]")):
        path = tmp_path / "bad.yaml"
        path.write_text(yaml.safe_dump({**doc, "geometry": geo}))
        with pytest.raises(ConfigError, match=f"^{re.escape(str(path))}:[0-9]+: .*{field}"):
            load_vehicle(str(path))
    # what MuJoCo itself rejects (an inertia that breaks the triangle inequality, which no
    # real body has): named, with the vehicle file
    doc["vehicle"]["inertia"] = [0.1, 4.29, 0.1]
    path = tmp_path / "lopsided.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=f"MuJoCo rejects the vehicle \\(vehicle file {path}"):
        MujocoSimulator(load_vehicle(str(path)))


@pytest.mark.parametrize(("change", "match"), [
    ({"added_mass": [[1, 2, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, 0, 1, 0, 0, 0],
                     [0, 0, 0, 1, 0, 0], [0, 0, 0, 0, 1, 0], [0, 0, 0, 0, 0, 1]]},
     "added_mass: must be symmetric"),
    ({"added_mass": [1, 1, -5, 0.1, 0.1, 0.1]}, "added_mass: must be positive semi-definite"),
    ({"added_mass_terms": {"inertial": False, "coriolis": False, "munk": True}},
     "munk: true needs coriolis"),
])
def test_bad_added_mass_is_named_with_its_file(tmp_path: Path, change: dict[str, Any],
                                               match: str) -> None:
    doc = yaml.safe_load((PRESETS_DIR / "torpedo_auv.yaml").read_text())
    doc["vehicle"].update(change)
    path = tmp_path / "v.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=f"^{re.escape(str(path))}:[0-9]+: .*{match}"):
        load_vehicle(str(path))
