"""Simulator (dampest_ros.core.simulation.simulate): steady states, energy, current, hidden effects,
runs."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from dampest_ros.core.physics.frames import euler_from_matrix, quat_to_matrix
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.simulation.effects import Effects
from dampest_ros.core.simulation.excitation import PROTOCOLS, make_excitation
from dampest_ros.core.simulation.simulate import Simulator, run
from dampest_ros.core.simulation.trajectory import Trajectory

PRESET_DIR = Path(__file__).resolve().parents[3] / "config" / "vehicles"


def preset(name: str) -> dict[str, Any]:
    with (PRESET_DIR / f"{name}.yaml").open() as f:
        return dict(yaml.safe_load(f))


def neutral(d: dict[str, Any], centred: bool = True) -> dict[str, Any]:
    """A copy with W = B exactly and, if ``centred``, r_g = r_b = 0: g(η) ≡ 0."""
    d = copy.deepcopy(d)
    body = d["vehicle"]
    body["volume"] = body["mass"] / body["rho"]
    if centred:
        body["r_g"] = [0.0, 0.0, 0.0]
        body["r_b"] = [0.0, 0.0, 0.0]
    return d


def surge_vehicle() -> Vehicle:
    """Neutral, centred BlueROV2 Heavy with two thrusters on the x axis pushing along +x, so
    that equal rotor speeds give a pure surge force."""
    d = neutral(preset("bluerov2_heavy"))
    d["thrusters"]["units"] = [
        {"name": "fore", "position": [0.2, 0.0, 0.0], "direction": [1.0, 0.0, 0.0]},
        {"name": "aft", "position": [-0.2, 0.0, 0.0], "direction": [1.0, 0.0, 0.0]},
    ]
    return Vehicle.from_dict(d)


def coefficient(v: Vehicle, name: str) -> float:
    return float(v.theta[v.damping.parameter_names.index(name)])


def fly(sim: Simulator, command: np.ndarray, duration: float) -> Trajectory:
    for _ in range(round(duration / sim.dt)):
        sim.step(command)
    return sim.trajectory()


def positive_root(a: float, b: float, c: float) -> float:
    """Positive root of a x² + b x − c = 0 (a, b, c > 0)."""
    return (-b + np.sqrt(b * b + 4 * a * c)) / (2 * a)


# --- the equation of motion -----------------------------------------------------------------


def test_acceleration_is_fossens_equation() -> None:
    # The simulator inlines the maths for speed; check its ν̇ against the module functions:
    # M ν̇ = τ − C_RB(ν)ν − C_A(ν_r)ν_r − D(ν_r)ν_r − Σ c z − g(η) + M_A ν̇_c
    v = Vehicle.from_dict(preset("bluerov2_heavy"))
    effects = Effects.from_dict({
        "current": [0.2, -0.1, 0.05], "current_variation": 0.1, "current_period": 100.0,
        "cg_offset": [0.01, -0.005, 0.02], "buoyancy_offset": 2.0, "added_mass_error": 0.2,
        "thrust_gain_error": -0.05,
        "extra_cross": [{"row": "N", "col": "v", "alpha": "|r|", "value": 3.0}],
        "memory": [{"dof": "u", "rate": 2.0, "c": 10.0}, {"dof": "r", "rate": 0.5, "c": 0.3}],
    })
    rng = np.random.default_rng(2)
    for _ in range(20):
        sim = Simulator(v, effects, dt=0.01, quaternion=rng.normal(size=4))
        sim.x[7:13] = rng.normal(size=6) * 0.5
        sim.x[13:15] = rng.normal(size=2)  # memory states
        sim.x[15:] = rng.uniform(-50, 50, 8)  # rotor speeds
        x0 = sim.x.copy()
        sim.step(x0[15:])
        traj = sim.trajectory()
        truth = sim.truth
        body, model, theta = truth.body, truth.damping, truth.theta
        R = quat_to_matrix(x0[3:7])
        nu, z, n = x0[7:13], x0[13:15], x0[15:]
        w = 2 * np.pi / 100.0
        c = np.array([0.2, -0.1 + 0.1, 0.05])  # current + variation·[sin 0, cos 0, 0]
        c_dot = np.array([0.1 * w, 0.0, 0.0])
        v_c = R.T @ c
        nu_r = nu - np.r_[v_c, 0, 0, 0]
        nu_c_dot = np.r_[R.T @ c_dot - np.cross(nu[3:], v_c), 0, 0, 0]
        tau = v.thrusters.wrench(0.95 * v.thrusters.thrust(n))
        rhs = (tau - body.coriolis_force(nu, nu_r)
               - model.force(nu_r[None], theta, z[None])[0]
               - body.restoring(R) + body.added_mass @ nu_c_dot)
        expected = np.linalg.solve(body.M, rhs)
        np.testing.assert_allclose(traj.tau[0], tau, rtol=0, atol=1e-12 * np.abs(tau).max())
        np.testing.assert_allclose(traj.nu_dot[0], expected, rtol=0,
                                   atol=1e-12 * np.abs(expected).max())
        np.testing.assert_allclose(traj.current[0], c, atol=1e-15)
        np.testing.assert_array_equal(traj.memory[0], z)
    # the hidden body effects are in the truth, not in the nominal vehicle
    assert truth.body.r_g == pytest.approx([0.01, -0.005, 0.02])
    assert truth.body.buoyancy - v.body.buoyancy == pytest.approx(2.0, rel=1e-9)
    np.testing.assert_allclose(truth.body.added_mass, 1.2 * v.body.added_mass)
    assert "N_vr" in truth.damping.parameter_names
    assert "N_vr" not in v.damping.parameter_names


# --- steady surge ----------------------------------------------------------------------------


def test_steady_surge_solves_the_damping_law() -> None:
    v = surge_vehicle()
    X_u, X_uu = coefficient(v, "X_u"), coefficient(v, "X_uu")
    assert (X_u, X_uu) == (13.7, 141.0)
    n = 30.0
    traj = fly(Simulator(v, dt=0.01), np.full(2, n), 10.0)
    tau = traj.tau[-1]
    # the thrust curve: T = k_T ρ D⁴ n², two thrusters, and no other component
    assert tau[0] == pytest.approx(2 * 0.45 * 1000.0 * 0.076**4 * n * n, rel=1e-12)
    np.testing.assert_allclose(tau[1:], 0.0, atol=1e-12)
    u = traj.nu[-1, 0]
    assert u == pytest.approx(positive_root(X_uu, X_u, tau[0]), abs=1e-6)
    assert abs(X_u * u + X_uu * u * abs(u) - tau[0]) < 1e-6 * tau[0]
    np.testing.assert_allclose(traj.nu[:, 1:], 0.0, atol=1e-12)  # pure surge
    np.testing.assert_allclose(traj.nu_dot[-1], 0.0, atol=1e-9)
    # and backwards (u < 0): X_u u + X_uu u|u| = τ
    traj = fly(Simulator(v, dt=0.01), np.full(2, -n), 10.0)
    assert traj.nu[-1, 0] == pytest.approx(-positive_root(X_uu, X_u, -traj.tau[-1, 0]), abs=1e-6)


def test_heavy_vehicle_sinks_at_the_terminal_speed() -> None:
    # 5 N heavier than neutral (buoyancy_offset < 0), centred: Z_w w + Z_ww w|w| = W − B, w > 0
    v = Vehicle.from_dict(neutral(preset("bluerov2_heavy")))
    sim = Simulator(v, Effects(buoyancy_offset=-5.0), dt=0.02)
    assert sim.truth.body.weight - sim.truth.body.buoyancy == pytest.approx(5.0, rel=1e-9)
    traj = fly(sim, np.zeros(8), 10.0)
    w = positive_root(coefficient(v, "Z_ww"), coefficient(v, "Z_w"), 5.0)
    assert traj.nu[-1, 2] == pytest.approx(w, abs=1e-6)
    assert traj.position[-1, 2] > traj.position[0, 2] + 0.9 * w * 5.0  # deeper (NED z down)


# --- energy -----------------------------------------------------------------------------------


def test_kinetic_energy_never_increases_without_thrust() -> None:
    v = Vehicle.from_dict(neutral(preset("bluerov2_heavy")))
    rng = np.random.default_rng(0)
    M = v.body.M
    dt, steps = 0.01, 100
    for _ in range(100):
        q = rng.normal(size=4)
        sim = Simulator(v, dt=dt, quaternion=q, record=False)
        sim.x[7:13] = rng.normal(size=6) * [0.5, 0.5, 0.5, 1.0, 1.0, 1.0]
        energy = np.empty(steps + 1)
        power = np.empty(steps + 1)
        for k in range(steps + 1):
            nu = sim.nu.copy()
            energy[k] = 0.5 * nu @ M @ nu
            power[k] = float(v.damping.dissipation(nu, v.theta)[0])
            if k < steps:
                sim.step(np.zeros(8))
        assert np.all(np.diff(energy) <= 1e-9 * energy[:-1])
        assert energy[-1] < 0.9 * energy[0]
        # the loss is the damping power: E(0) − E(T) = ∫ νᵀD(ν)ν dt (Simpson on the grid;
        # RK4 and Simpson errors are O(h⁴): worst case 1.2e-4 at h = 0.01, 8e-6 at 0.005)
        dissipated = dt / 3 * (power[0] + power[-1] + 4 * power[1:-1:2].sum()
                               + 2 * power[2:-1:2].sum())
        assert energy[0] - energy[-1] == pytest.approx(dissipated, rel=1e-3)


# --- current ------------------------------------------------------------------------------------


def test_vehicle_drifts_with_a_constant_current() -> None:
    v = Vehicle.from_dict(neutral(preset("platform_a"), centred=False))
    current = np.array([0.3, -0.2, 0.1])
    traj = fly(Simulator(v, Effects(current=tuple(current)), dt=0.02), np.zeros(8), 60.0)
    np.testing.assert_allclose(traj.current, np.broadcast_to(current, traj.current.shape))
    assert np.abs(traj.nu[0]).max() == 0.0  # starts at rest over ground
    R = quat_to_matrix(traj.quaternion[-1])
    ground = R @ traj.nu[-1, :3]
    np.testing.assert_allclose(ground, current, rtol=0, atol=1e-3)
    relative = traj.nu[-1, :3] - R.T @ current
    assert np.abs(relative).max() < 1e-3
    assert np.abs(traj.nu[-1, 3:]).max() < 1e-3
    # the position follows the water
    drift = (traj.position[-1] - traj.position[-500]) / (traj.t[-1] - traj.t[-500])
    np.testing.assert_allclose(drift, current, atol=1e-3)


# --- hidden effects --------------------------------------------------------------------------


def test_memory_effect_adds_dc_damping() -> None:
    v = surge_vehicle()
    rate, c = 2.0, 10.0
    effects = Effects.from_dict({"memory": [{"dof": "u", "rate": rate, "c": c}]})
    cmd = np.full(2, 30.0)
    traj = fly(Simulator(v, effects, dt=0.01), cmd, 20.0)
    plain = fly(Simulator(v, dt=0.01), cmd, 20.0)
    tau = traj.tau[-1, 0]
    assert tau == plain.tau[-1, 0]
    u = traj.nu[-1, 0]
    # steady state z = u/λ: τ = (X_u + c/λ) u + X_uu u|u|
    X_u, X_uu = coefficient(v, "X_u"), coefficient(v, "X_uu")
    assert u == pytest.approx(positive_root(X_uu, X_u + c / rate, tau), abs=1e-6)
    assert u < plain.nu[-1, 0] - 0.01
    assert traj.memory.shape == (len(traj), 1)
    assert traj.memory[-1, 0] == pytest.approx(u / rate, abs=1e-6)


def test_delay_shifts_the_response() -> None:
    v = surge_vehicle()
    dt, delay = 0.01, 0.2
    cmd = np.full(2, 30.0)
    base = fly(Simulator(v, dt=dt), cmd, 0.6)
    late = fly(Simulator(v, Effects(delay=delay), dt=dt), cmd, 0.6)

    def onset(tr: Trajectory) -> float:
        return float(tr.t[np.argmax(tr.nu[:, 0] > 1e-6)])

    assert onset(base) < 0.05
    assert onset(late) - onset(base) == pytest.approx(delay, abs=1e-9)
    # the applied force is the undelayed one, shifted by the delay; the logs are not delayed
    shift = round(delay / dt)
    np.testing.assert_allclose(late.tau[shift:], base.tau[:-shift], rtol=0, atol=1e-12)
    np.testing.assert_allclose(late.tau[:shift], 0.0, atol=0)
    np.testing.assert_array_equal(late.rotor_speed, base.rotor_speed)


def test_thrust_gain_error_scales_the_applied_wrench_without_motor_lag() -> None:
    d = preset("bluerov2_heavy")
    d["thrusters"]["model"]["time_constant"] = 0.0
    v = Vehicle.from_dict(d)
    sim = Simulator(v, Effects(thrust_gain_error=0.1), dt=0.01)
    rng = np.random.default_rng(1)
    for _ in range(200):
        sim.step(rng.uniform(-50.0, 50.0, 8))  # a new command every step
    traj = sim.trajectory()
    logged = v.thrusters.wrench(traj.thrust)
    assert np.abs(traj.tau).max() > 10.0
    np.testing.assert_allclose(traj.tau, 1.1 * logged, rtol=0, atol=1e-9 * np.abs(traj.tau).max())


def test_thrust_gain_error_with_motor_lag() -> None:
    v = Vehicle.from_dict(preset("bluerov2_heavy"))
    sim = Simulator(v, Effects(thrust_gain_error=0.1), dt=0.01)
    cmd = np.array([40.0, -35.0, 20.0, -10.0, 30.0, 30.0, -30.0, -25.0])
    traj = fly(sim, cmd, 2.0)
    logged = v.thrusters.wrench(traj.thrust)
    scale = np.abs(traj.tau).max()
    # step means: RK4 of the motor lag against the logged exact exponential (Simpson for the
    # thrust); close while the rotors spin up (h/T = 0.2; worst 4e-5 of the range) ...
    np.testing.assert_allclose(traj.tau, 1.1 * logged, rtol=0, atol=1e-4 * scale)
    # ... and equal once it has settled (40 time constants)
    np.testing.assert_allclose(traj.tau[-1], 1.1 * logged[-1], rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(traj.thrust[-1], v.thrusters.thrust(cmd), rtol=1e-12)


def test_deadzone_hides_small_rotor_speeds() -> None:
    v = surge_vehicle()
    sim = Simulator(v, Effects(thruster_deadzone=5.0), dt=0.01)
    traj = fly(sim, np.full(2, 4.0), 1.0)
    assert np.all(traj.tau == 0.0)
    assert np.all(traj.nu == 0.0)
    assert traj.thrust[-1, 0] > 0.1  # the logs do not know


def test_effects_from_dict_rejects_unknown_key() -> None:
    with pytest.raises(ConfigError) as info:
        Effects.from_dict({"current": [0.1, 0.0, 0.0], "curent_variation": 0.1})
    assert info.value.field == "effects"
    assert "curent_variation" in str(info.value)


def test_effects_from_dict_round_trip() -> None:
    d = {"current": [0.1, 0.0, -0.05], "delay": 0.1,
         "memory": [{"dof": "u", "rate": 2.0, "c": 10.0}]}
    e = Effects.from_dict(d)
    assert e.current == (0.1, 0.0, -0.05)
    assert e.delay == 0.1
    assert e.memory == ({"dof": "u", "rate": 2.0, "c": 10.0},)
    assert Effects.from_dict(e.as_dict()) == e
    assert Effects().as_dict() == {}


def test_simulator_rejects_bad_step() -> None:
    with pytest.raises(ConfigError) as info:
        Simulator(surge_vehicle(), dt=0.0)
    assert info.value.field == "dt"


# --- protocols ---------------------------------------------------------------------------------

# std of each velocity component of protocol B (BlueROV2 Heavy, 60 s, seed 0), measured
# 0.227 0.308 0.211 0.404 0.399 1.341; the thresholds are about half of that.
B_MIN_STD = np.array([0.11, 0.15, 0.10, 0.20, 0.20, 0.67])


@pytest.mark.parametrize("protocol", [  # optimal designs its references first (~12 s)
    pytest.param(p, marks=pytest.mark.slow) if p == "optimal" else p for p in PROTOCOLS])
def test_protocols_fly_the_bluerov2(protocol: str) -> None:
    v = Vehicle.from_dict(preset("bluerov2_heavy"))
    ex = make_excitation(protocol, v, 60.0, seed=0)
    traj = run(v, ex)
    assert len(traj) == 3001  # 0 … 60 s at 50 Hz control, one RK4 step of 0.02 s per tick
    for name in ("nu", "nu_dot", "tau", "position", "quaternion", "thrust"):
        assert np.all(np.isfinite(getattr(traj, name))), name
    roll, pitch, _ = euler_from_matrix(quat_to_matrix(traj.quaternion)).T
    assert np.abs(roll).max() < np.deg2rad(60.0)
    assert np.abs(pitch).max() < np.deg2rad(60.0)
    assert np.all(np.abs(traj.tau).max(axis=0) <= v.thrusters.max_wrench * (1 + 1e-9))
    std = traj.nu.std(axis=0)
    assert np.all(std > 1e-3), std  # every protocol moves every DOF a little
    if protocol == "B":
        assert np.all(std > B_MIN_STD), std


@pytest.mark.parametrize("terms", [{"inertial": False},
                                   {"inertial": True, "coriolis": True, "munk": False},
                                   {"inertial": False, "coriolis": False, "munk": False}])
def test_added_mass_switches_reach_the_physics(terms: dict[str, bool]) -> None:
    """With any switches, τ − M ν̇ − C(ν)ν − g(η) on the ground truth is D(ν)ν exactly
    (no motor lag: the logged step-mean τ is the τ of the logged ν̇)."""
    from dampest_ros.core.identification.regression import target
    from dampest_ros.core.signals.samples import Samples

    d = preset("bluerov2_heavy")
    d["vehicle"]["added_mass_terms"] = terms
    d["thrusters"]["model"]["time_constant"] = 0.0
    v = Vehicle.from_dict(d)
    traj = run(v, make_excitation("B", v, 20.0, seed=4), dt=0.02)
    R = quat_to_matrix(traj.quaternion)
    smp = Samples(t=traj.t, nu=traj.nu, nu_dot=traj.nu_dot, tau=traj.tau,
                  euler=euler_from_matrix(R), depth=traj.position[:, 2],
                  segment=np.zeros(len(traj.t), dtype=np.int64))
    d_force = v.damping.force(traj.nu, v.theta, np.zeros((len(traj.t), 0)))
    assert np.abs(target(smp, v.body) - d_force).max() < 1e-9 * np.abs(d_force).max()
    d["vehicle"].pop("added_mass_terms")
    wrong = target(smp, Vehicle.from_dict(d).body)
    assert np.abs(wrong - d_force).max() > 1e-3 * np.abs(d_force).max()



def test_log_blocks_and_streaming_give_the_same_trajectory(monkeypatch: pytest.MonkeyPatch
                                                           ) -> None:
    """Log rows built per block of steps (any block size) and taken in chunks as the
    simulator node takes them: the one trajectory, bit for bit; its mean τ is the RK4-weighted
    mean of the applied thrust, which at a steady command is the thrust itself."""
    v = Vehicle.from_dict(preset("bluerov2_heavy"))
    fx = Effects(current=(0.1, 0.0, 0.0), current_variation=0.05, memory=(
        {"dof": "u", "rate": 2.0, "c": 5.0},), delay=0.04)
    cmd = np.linspace(-20.0, 20.0, v.thrusters.count)

    def fly(block: int, chunk: int) -> list[Trajectory]:
        monkeypatch.setattr(Simulator, "BLOCK", block)
        sim = Simulator(v, fx)
        parts = []
        for k in range(1, 61):
            sim.step(cmd)
            if k % chunk == 0:
                parts.append(sim.take_log(keep=1))
        return parts

    whole = fly(4096, 60)[0]
    pieces = fly(7, 20)
    for name in ("t", "position", "quaternion", "nu", "nu_dot", "tau", "rotor_speed", "thrust",
                 "current", "memory"):
        joined = np.concatenate([getattr(pieces[0], name)]
                                + [getattr(p, name)[1:] for p in pieces[1:]])
        assert joined.tobytes() == np.asarray(getattr(whole, name)).tobytes(), name
    # the rotors settle (T_m = 0.05 s, 24 of them): the last step's mean thrust is T(n) of
    # the command, and the applied wrench its allocation
    thrust = v.thrusters.gain * cmd * np.abs(cmd)
    np.testing.assert_allclose(whole.thrust[-1], thrust, rtol=1e-9)
    np.testing.assert_allclose(whole.tau[-1], v.thrusters.wrench(thrust), rtol=0,
                               atol=1e-9 * np.abs(thrust).max())
