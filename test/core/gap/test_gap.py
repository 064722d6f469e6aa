"""Sim-to-real gap workflow on simulator data with hidden effects.

Every case flies protocol B for 600 s (300 s in the fast hidden-effect checks) with the
BlueROV2 Heavy preset, default (realistic)
sensor noise (``SensorConfig()``: gyro 0.002 rad/s white + 1e-5 rad/s/√s bias walk, DVL
5 mm/s at 8 Hz with dropouts, accelerometer 0.02 m/s², …), and is analysed against the
nominal preset (the model without the effect), fitted on the first 70 % of the time and
scored on the last 30 %.

Hidden magnitudes, chosen to be what a real small ROV shows, not exaggerated:

=================  =============================  ============================================
effect             magnitude                      why realistic
=================  =============================  ============================================
current            (0.12, −0.08, 0) m/s NED       0.14 m/s: a calm harbour or coastal site
buoyancy offset    +1.0 N                         100 g net buoyancy: a vehicle trimmed light
thrust gain        −10 %                          T200 on a 14.8 V pack vs the 16 V curve
CG offset          (2, −2, 2) mm                  payload/ballast placement (GM is 10 mm)
added mass         +25 % (all of M_A)             strip-theory/CFD uncertainty
dead-zone          5 rev/s (300 rpm)              ESC dead band of about ±25 µs
delay              0.10 s                         telemetry + ESC + motor latency
gyro bias          0.005 rad/s per axis (0.29°/s) uncompensated MEMS gyro
DVL bias           (0.01, −0.01, 0) m/s           misaligned/biased DVL
Y_v|r|, …          ≈ 20 % of that DOF's drag      cross-coupling of a box-shaped frame
memory             λ = 1.5 1/s, c/λ ≈ 30 % of     radiation/wake memory
                   the DOF's linear-equivalent
                   damping
model mismatch     X_uu 141 → 100, Z_w 33 → 20,   coefficients from literature for a
                   Z_ẇ 18.7 → 14 in the model     different build
plant switches     no M_A ν̇ / no C_A(ν)ν in the   MuJoCo's fluid model; gz-sim's
                   plant, both in the model       disable_added_mass / disable_coriolis
=================  =============================  ============================================

The fast tests (unmarked) run one seed of the most common effects; ``-m slow`` sweeps every
candidate of the library over seeds 1–3.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Any

import numpy as np
import pytest

from dampest_ros.core.gap.data import GapData
from dampest_ros.core.gap.effects import Buoyancy, Current
from dampest_ros.core.gap.library import library
from dampest_ros.core.gap.localise import concentration, localise
from dampest_ros.core.gap.model_effects import Memory
from dampest_ros.core.gap.relative import refit_relative, relative_samples
from dampest_ros.core.gap.search import (
    NO_FURTHER,
    GapResult,
    find_gap,
    insignificance,
    rejection,
)
from dampest_ros.core.gap.trust import degradations, outside, relative_velocity
from dampest_ros.core.gap.update import divergence_reason, updated_model
from dampest_ros.core.identification.selection import DEFAULT_CROSS
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import (
    DOF_NAMES,
    AddedMassTerms,
    RigidBody,
    coriolis_force,
)
from dampest_ros.core.physics.terms import (
    CrossSpec,
    coriolis_term,
    cross_term,
    linear_term,
    quadratic_term,
)
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.measurements import JointSeries
from dampest_ros.core.signals.preprocess import PreprocessConfig, preprocess
from dampest_ros.core.signals.samples import Samples
from dampest_ros.core.simulation.effects import Effects
from dampest_ros.core.simulation.excitation import make_excitation
from dampest_ros.core.simulation.sensors import SensorBias, SensorConfig, measure
from dampest_ros.core.simulation.simulate import run
from dampest_ros.io.yaml_io import load_vehicle

#: seconds of protocol B: every case, and the fast hidden-effect checks (seed 1; on seeds 2 and
#: 3 too, every named magnitude within 1 % and the residual at most 0.24 of its size, against
#: the 20 % and 0.5 asked; the clean check stays at 600 s, where the best candidate's held-out
#: gain is 0.004 against 0.019 on 300 s, 0.02 asked)
DURATION, FAST_DURATION = 600.0, 300.0
VEHICLE = "bluerov2_heavy"


@lru_cache(maxsize=1)
def vehicle() -> Vehicle:
    return load_vehicle(VEHICLE)


def _simulate(effects: dict[str, Any], seed: int, duration: float,
              plant: dict[str, bool] | None = None) -> tuple[Samples, JointSeries]:
    """Protocol B with hidden ``effects`` (and the plant's added-mass switches ``plant``,
    e.g. ``{'inertial': False}``): what the vehicle logs, preprocessed."""
    v = vehicle()
    if plant:
        terms = AddedMassTerms(**{**v.body.added_mass_terms.as_dict(), **plant})
        v = replace(v, body=replace(v.body, added_mass_terms=terms))
    e = Effects.from_dict(effects)
    traj = run(v, make_excitation("B", v, duration, seed=seed), e)
    rec = measure(traj, v.body.rho, v.body.gravity, SensorConfig(),
                  SensorBias(e.gyro_bias, e.accel_bias, e.dvl_bias), seed=seed)
    samples = preprocess(rec, v, PreprocessConfig())
    joints = rec["thrusters/state"]
    assert isinstance(joints, JointSeries)
    return samples, joints


@lru_cache(maxsize=4)  # seeds 1-3, and seed 1 of the fast checks
def clean(seed: int, duration: float = DURATION) -> tuple[Samples, JointSeries]:
    return _simulate({}, seed, duration)


@lru_cache(maxsize=2)
def hidden(effects_json: str, seed: int, plant_json: str = "{}", duration: float = DURATION
           ) -> tuple[Samples, JointSeries]:
    return _simulate(json.loads(effects_json), seed, duration, json.loads(plant_json))


@dataclass
class Case:
    """A hidden effect: simulator effects and/or a wrong believed model, what must be named
    and how close its magnitude must be."""

    effects: dict[str, Any] = field(default_factory=dict)
    theta: dict[str, float] = field(default_factory=dict)  # believed damping values
    added_mass: dict[int, float] = field(default_factory=dict)  # believed diagonal M_A
    plant: dict[str, bool] = field(default_factory=dict)  # the plant's added-mass switches
    key: str = ""
    error: Callable[[dict[str, float]], float] = lambda m: 0.0


def rel(est: np.ndarray | float, true: np.ndarray | float) -> float:
    """‖est − true‖ / ‖true‖."""
    e, t = np.atleast_1d(np.asarray(est, float)), np.atleast_1d(np.asarray(true, float))
    return float(np.linalg.norm(e - t) / np.linalg.norm(t))


def _vec(m: dict[str, float], *names: str) -> np.ndarray:
    return np.array([m[n] for n in names])


CROSS_VALUES = {"Y_vr": 10.0, "Y_rv": 10.0, "N_vr": 1.4, "N_rv": 1.4, "Z_wq": 40.0,
                "M_qw": 1.0, "Z_wu": 40.0, "M_wu": 1.0, "Y_r": 3.0, "N_v": 2.0}
MEMORY_C = {"u": 6.0, "v": 20.0, "w": 15.0, "r": 1.0}
NOMINAL = dict(zip(vehicle().damping.parameter_names, vehicle().theta, strict=True))


def _cross_case(spec: dict[str, str]) -> Case:
    label = CrossSpec.from_dict(spec).label
    value = CROSS_VALUES[label]
    return Case(effects={"extra_cross": [{**spec, "value": value}]}, key=f"cross.{label}",
                error=lambda m: rel(m[label], value))


def _memory_case(dof: str) -> Case:
    c = MEMORY_C[dof]
    # the magnitude of memory is its steady gain c/λ (the force per unit of a slow
    # velocity); c and λ themselves trade off and scatter by ±40 % over seeds with
    # protocol B, whose thrust has little content near λ: λ is only asked within 50 %
    return Case(effects={"memory": [{"dof": dof, "rate": 1.5, "c": c}]}, key=f"memory.{dof}",
                error=lambda m: max(rel(m["c"] / m["lambda"], c / 1.5),
                                    0.4 * rel(m["lambda"], 1.5)))


def _coef_case(name: str, believed: float) -> Case:
    delta = NOMINAL[name] - believed
    kind = "quadratic" if len(name.split("_")[1]) == 2 else "linear"
    return Case(theta={name: believed}, key=f"{kind}.{name}",
                error=lambda m: rel(m[name], delta))


CASES: dict[str, Case] = {
    "current": Case({"current": [0.12, -0.08, 0.0]}, key="current",
                    error=lambda m: rel(_vec(m, "v_north", "v_east"), [0.12, -0.08])),
    "buoyancy": Case({"buoyancy_offset": 1.0}, key="buoyancy",
                     error=lambda m: rel(m["delta_B"], 1.0)),
    "thrust_gain": Case({"thrust_gain_error": -0.1}, key="thrust_gain",
                        error=lambda m: rel(m["epsilon"], -0.1)),
    "cg_offset": Case({"cg_offset": [0.002, -0.002, 0.002]}, key="cg_offset",
                      error=lambda m: rel(_vec(m, "dx", "dy", "dz"), [0.002, -0.002, 0.002])),
    "added_mass": Case({"added_mass_error": 0.25}, key="added_mass_scale",
                       error=lambda m: rel(m["epsilon"], 0.25)),
    "deadzone": Case({"thruster_deadzone": 5.0}, key="deadzone",
                     error=lambda m: rel(m["n_deadzone"], 5.0)),
    "delay": Case({"delay": 0.1}, key="delay", error=lambda m: rel(m["delay"], 0.1)),
    "gyro_bias": Case({"gyro_bias": [0.005, -0.005, 0.005]}, key="gyro_bias",
                      error=lambda m: rel(_vec(m, "bias_p", "bias_q", "bias_r"),
                                          [0.005, -0.005, 0.005])),
    "dvl_bias": Case({"dvl_bias": [0.01, -0.01, 0.0]}, key="dvl_bias",
                     error=lambda m: rel(_vec(m, "bias_u", "bias_v", "bias_w"),
                                         [0.01, -0.01, 0.0])),
    # the plant applies no M_A ν̇ (MuJoCo) / no C_A(ν)ν (gz-sim's disable_coriolis); the
    # believed model has both
    "plant_no_inertial": Case(plant={"inertial": False}, key="added_mass_inertial",
                              error=lambda m: rel(m["epsilon"], -1.0)),
    "plant_no_coriolis": Case(plant={"coriolis": False, "munk": False},
                              key="added_mass_coriolis", error=lambda m: rel(m["epsilon"], -1.0)),
    "added_mass.w": Case(added_mass={2: 14.0}, key="added_mass.w",
                         error=lambda m: rel(m["Z_wdot"], 18.68 - 14.0)),
    "added_mass.u": Case(added_mass={0: 4.5}, key="added_mass.u",
                         error=lambda m: rel(m["X_udot"], 6.36 - 4.5)),
    "added_mass.v": Case(added_mass={1: 5.0}, key="added_mass.v",
                         error=lambda m: rel(m["Y_vdot"], 7.12 - 5.0)),
    "added_mass.p": Case(added_mass={3: 0.12}, key="added_mass.p",
                         error=lambda m: rel(m["K_pdot"], 0.189 - 0.12)),
    "added_mass.q": Case(added_mass={4: 0.09}, key="added_mass.q",
                         error=lambda m: rel(m["M_qdot"], 0.135 - 0.09)),
    "added_mass.r": Case(added_mass={5: 0.15}, key="added_mass.r",
                         error=lambda m: rel(m["N_rdot"], 0.222 - 0.15)),
}
# a missing or wrong damping coefficient: ~30 % of the nominal, or a value where it is 0
for _name, _believed in {"X_u": 9.0, "Y_v": 5.0, "Z_w": 20.0, "K_p": 0.3, "M_q": 0.4,
                         "N_r": 0.3, "X_uu": 100.0, "Y_vv": 150.0, "Z_ww": 130.0,
                         "K_pp": 0.8, "M_qq": 0.3, "N_rr": 1.0}.items():
    CASES[_name] = _coef_case(_name, _believed)
for _spec in DEFAULT_CROSS:
    _c = _cross_case(dict(_spec))
    CASES[_c.key] = _c
for _dof in MEMORY_C:
    CASES[f"memory.{_dof}"] = _memory_case(_dof)

FAST = ("current", "buoyancy", "thrust_gain", "X_uu")


def believed(case: Case) -> tuple[np.ndarray, RigidBody]:
    """θ and body of the model the user believes."""
    v = vehicle()
    theta = v.damping.theta_from_dict({**NOMINAL, **case.theta})
    b = v.body
    am = b.added_mass.copy()
    for i, val in case.added_mass.items():
        am[i, i] = val
    return theta, RigidBody(b.mass, b.inertia, b.r_g, b.r_b, b.volume, am, b.rho, b.gravity)


@lru_cache(maxsize=len(FAST))
def analyse_named(name: str, seed: int, duration: float = DURATION
                  ) -> tuple[GapData, GapResult]:
    """The analysis of a named case, kept for the FAST cases' later checks (the current's
    speed and direction reuse its analysis)."""
    return analyse(CASES[name], seed, duration)


def analyse(case: Case, seed: int, duration: float = DURATION) -> tuple[GapData, GapResult]:
    v = vehicle()
    samples, joints = (hidden(json.dumps(case.effects), seed, json.dumps(case.plant), duration)
                       if case.effects or case.plant else clean(seed, duration))
    theta, body = believed(case)
    data = GapData(samples, v.damping, theta, body, v.thrusters, joints)
    return data, find_gap(data)


def floor(seed: int) -> np.ndarray:
    """Held-out residual RMS per DOF of the nominal model on clean data (the noise floor)."""
    v = vehicle()
    samples, joints = clean(seed)
    data = GapData(samples, v.damping, v.theta, v.body, v.thrusters, joints)
    return np.sqrt(np.mean(data.r0[data.test] ** 2, axis=0))


def check_hidden(name: str, seed: int, duration: float = DURATION) -> None:
    case = CASES[name]
    _, result = analyse_named(name, seed, duration)
    assert result.named, f"{name}: nothing named"
    assert result.named[0] == case.key, (name, result.named)
    step = result.steps[0]
    # where the hidden effect dominates the residual (≥ 2.5× the clean noise floor), the
    # held-out residual RMS falls by at least half
    affected = step.rms_before >= 2.5 * floor(seed)
    assert affected.any(), (name, step.rms_before, floor(seed))
    assert np.all(step.rms_after[affected] <= 0.5 * step.rms_before[affected]), \
        (name, step.rms_before, step.rms_after)
    # the magnitude after the joint refit of all named effects
    e, p = next((e, p) for e, p in result.effects if e.key == case.key)
    err = case.error(e.magnitude(p))
    assert err <= 0.2, (name, e.magnitude(p), err)
    assert result.conclusion == NO_FURTHER


# --- fast, representative ------------------------------------------------------------------


def test_clean_data_names_nothing() -> None:
    data, result = analyse(Case(), 1)
    assert result.named == [], [s.description for s in result.steps]
    assert result.conclusion == NO_FURTHER
    best = result.screens[0][0]
    assert best.heldout < 0.02
    # the residual of the exact model is the noise floor: a few tenths of a newton
    assert np.all(np.sqrt(np.mean(data.r0**2, axis=0))[:3] < 0.4)


@pytest.mark.parametrize("name", FAST)
def test_hidden_effect_is_named_first(name: str) -> None:
    check_hidden(name, 1, FAST_DURATION)


def test_current_speed_and_direction() -> None:
    _, result = analyse_named("current", 1, FAST_DURATION)
    e, p = result.effects[0]
    m = e.magnitude(p)
    assert m["speed"] == pytest.approx(np.hypot(0.12, 0.08), rel=0.05)
    assert m["direction_deg"] == pytest.approx(np.degrees(np.arctan2(-0.08, 0.12)) % 360, abs=3)
    assert "towards" in result.steps[0].description


@pytest.mark.slow
def test_two_effects_named_within_three_steps() -> None:
    case = Case({"current": [0.1, 0.05, 0.0], "buoyancy_offset": 1.0})
    _, result = analyse(case, 1)
    assert {"current", "buoyancy"} <= set(result.named[:3]), result.named
    m = dict(zip([e.key for e, _ in result.effects],
                 [e.magnitude(p) for e, p in result.effects], strict=True))
    assert rel(_vec(m["current"], "v_north", "v_east"), [0.1, 0.05]) <= 0.2
    assert rel(m["buoyancy"]["delta_B"], 1.0) <= 0.2


def test_linear_effects_are_linear_and_columns_match_predict() -> None:
    """For every candidate, ρ(p) on real data agrees with its columns: exactly for linear
    effects, to first order for the others."""
    v = vehicle()
    samples, joints = clean(1)
    data = GapData(samples.take(slice(0, 3000)), v.damping, v.theta, v.body, v.thrusters,
                       joints)
    ch = data.chunk_at(slice(0, 3000))
    rng = np.random.default_rng(0)
    for e in library():
        p0 = e.starts(data)[len(e.starts(data)) // 2]
        dp = 0.1 * np.asarray(e.steps) * rng.choice([-1.0, 1.0], e.k)
        if e.key.startswith("memory"):
            p0 = np.array([1.0, 1.5])
        X = e.columns(data, ch, p0)
        assert X.shape == (len(ch), 6, e.k), e.key
        lin = e.predict(data, ch, p0) + X @ dp
        exact = e.predict(data, ch, p0 + dp)
        if e.key == "deadzone":
            continue  # piecewise: each rotor crossing n_dz is a jump; only the sum is smooth
        scale = max(float(np.abs(exact - e.predict(data, ch, p0)).max()), 1e-12)
        tol = 1e-9 if e.linear else 0.05
        assert float(np.abs(lin - exact).max()) <= tol * scale + 1e-12, e.key


def test_buoyancy_prediction_is_the_restoring_force_of_a_lighter_body() -> None:
    v = vehicle()
    samples, _ = clean(1)
    data = GapData(samples.take(slice(0, 1000)), v.damping, v.theta, v.body)
    ch = data.chunk_at(slice(0, 1000))
    b = v.body
    lighter = RigidBody(b.mass, b.inertia, b.r_g, b.r_b, b.volume + 2.0 / (b.rho * b.gravity),
                        b.added_mass, b.rho, b.gravity)
    rho = Buoyancy().predict(data, ch, np.array([2.0]))
    np.testing.assert_allclose(rho, lighter.restoring(ch.R) - b.restoring(ch.R), atol=1e-9)


def test_localise_finds_residual_at_high_speed_and_low_frequency() -> None:
    samples, _ = clean(1)
    r = np.zeros((len(samples), 6))
    u = samples.nu[:, 0]
    r[:, 0] = 5.0 * np.abs(u) * u * (np.abs(u) > np.median(np.abs(u)))
    rows = localise(samples, r, passband=2.0)
    by = {(row.group, row.label.split(" (")[0]): row for row in rows}
    assert by[("speed", "|u| high")].rms[0] > 3 * max(by[("speed", "|u| low")].rms[0], 1e-9)
    top = [label for d, label, _ in concentration(rows) if d == 0]
    assert top[0].startswith("|u| high") or top[0].startswith("0–0.05 Hz")
    assert [row for row in rows if row.group == "band"][-1].label.endswith("–2 Hz")
    # over the whole spectrum the band powers add up to the total power (Parseval, within
    # the Welch estimate)
    band_rows = [row for row in localise(samples, r) if row.group == "band"]
    assert band_rows[-1].label.endswith("–25 Hz")
    total = np.sqrt(sum(float(row.rms[0]) ** 2 for row in band_rows))
    assert total == pytest.approx(rows[0].rms[0], rel=0.1)


def test_updated_model_adds_terms_and_mass() -> None:
    v = vehicle()
    samples, _ = clean(1)
    data = GapData(samples.take(slice(0, 1000)), v.damping, v.theta, v.body)
    lib = {e.key: e for e in library()}
    effects = [(lib["quadratic.X_uu"], np.array([10.0])), (lib["cross.Y_vr"], np.array([4.0])),
               (lib["memory.u"], np.array([2.0, 1.5])), (lib["added_mass.w"], np.array([3.0])),
               (lib["buoyancy"], np.array([1.0]))]
    upd = updated_model(data, effects)
    values = dict(zip(upd.model.parameter_names, upd.theta, strict=True))
    assert values["X_uu"] == pytest.approx(151.0)
    assert values["Y_vr"] == pytest.approx(4.0)
    assert values["freq.u.c1"] == pytest.approx(2.0)
    assert float(upd.model.memory_rates[0]) == pytest.approx(1.5)
    assert upd.M[2, 2] == pytest.approx(v.body.M[2, 2] + 3.0)
    assert upd.extra == {"buoyancy_offset": 1.0}


def test_csv_like_data_skips_the_dead_zone() -> None:
    v = vehicle()
    samples, _ = clean(1)
    data = GapData(samples, v.damping, v.theta, v.body)  # no rotor speeds
    result = find_gap(data, library(["thrusters"]))
    assert "deadzone" in result.skipped and "rotor speeds" in result.skipped["deadzone"]
    assert result.named == []


# --- the thorough sweep -----------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("name", sorted(CASES))
def test_every_candidate_hidden(name: str, seed: int) -> None:
    check_hidden(name, seed)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [2, 3])
def test_clean_data_names_nothing_all_seeds(seed: int) -> None:
    _, result = analyse(Case(), seed)
    assert result.named == [], [s.description for s in result.steps]


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("pair", [("current", "buoyancy"), ("thrust_gain", "cg_offset"),
                                  ("delay", "dvl_bias")])
def test_two_effects_all_seeds(pair: tuple[str, str], seed: int) -> None:
    a, b = CASES[pair[0]], CASES[pair[1]]
    _, result = analyse(Case({**a.effects, **b.effects}), seed)
    assert {a.key, b.key} <= set(result.named[:3]), result.named


# --- what gap writes is a valid model, and what it says is what it writes ----------


def _short(rows: int = 6000, body: RigidBody | None = None,
           theta: np.ndarray | None = None) -> GapData:
    """GapData on the first ``rows`` samples of clean seed 1 (the believed model: nominal)."""
    v = vehicle()
    samples, _ = clean(1)
    return GapData(samples.take(slice(0, rows)), v.damping,
                       v.theta if theta is None else theta, body or v.body)


def test_naming_a_term_the_model_has_updates_it() -> None:
    """Before: a cross term the model already had (here N_rv, and Y_r as an off-diagonal
    linear entry) was added a second time: 'terms: duplicate parameter names'."""
    v = vehicle()
    samples, _ = clean(1)
    lin = linear_term(DOF_NAMES, [("Y", "r")])
    model = DampingModel([lin, quadratic_term(), cross_term([CrossSpec.from_dict(
        {"row": "N", "col": "r", "alpha": "|v|"})])])
    theta = model.theta_from_dict({**NOMINAL, "Y_r": 2.0, "N_rv": 3.0})
    data = GapData(samples.take(slice(0, 1000)), model, theta, v.body)
    lib = {e.key: e for e in library()}
    upd = updated_model(data, [(lib["cross.N_rv"], np.array([-1.0])),
                                   (lib["cross.Y_r"], np.array([0.5])),
                                   (lib["linear.X_u"], np.array([1.0]))])
    assert upd.model.parameter_names == model.parameter_names
    values = dict(zip(upd.model.parameter_names, upd.theta, strict=True))
    assert values["N_rv"] == pytest.approx(2.0)
    assert values["Y_r"] == pytest.approx(2.5)
    assert values["X_u"] == pytest.approx(NOMINAL["X_u"] + 1.0)


def test_an_update_that_breaks_M_or_D_is_rejected() -> None:
    """Before: an added mass with a negative eigenvalue and a negative quadratic drag were
    written as found. Now the step is rejected with the reason."""
    data = _short()
    lib = {e.key: e for e in library()}
    r = data.r0
    better = r.copy()  # a step that halves Z's held-out residual
    better[data.test, 2] *= 0.5
    # Z_ẇ of 18.68 lowered by 25: M_A has the eigenvalue −6.3
    why = rejection(data, [(lib["added_mass.w"], np.array([-25.0]))], r, better, 1)
    assert "mass matrix" in why and "-6.32" in why, why
    # Z_ww 190 → −10 with Z_w 33: energy is generated above w = 3.3 m/s... and on the grid
    # of the flown envelope wherever |w| > 33/10 · ... — the data reach |w| ≈ 0.5 m/s, so
    # take Z_w to 0 as well
    why = rejection(data, [(lib["quadratic.Z_ww"], np.array([-200.0])),
                               (lib["linear.Z_w"], np.array([-33.0]))], r, better, 1)
    assert why.startswith("D(ν) would generate energy"), why
    # a positive correction of both is accepted (where it lowers the held-out residual)
    assert rejection(data, [(lib["quadratic.Z_ww"], np.array([20.0]))], r, better, 1) == ""
    # nothing gained held out: the summed evidence is not significant
    why = rejection(data, [(lib["quadratic.Z_ww"], np.array([20.0]))], r, r, 1)
    assert why.startswith("the held-out evidence summed over the DOFs is not significant"), why


def test_an_effect_that_worsens_a_dof_held_out_is_rejected() -> None:
    data = _short()
    lib = {e.key: e for e in library()}
    r = data.r0
    rms = np.sqrt(np.mean(r[data.test] ** 2, axis=0))
    worse = r.copy()
    worse[data.test, 3] *= 1.5  # roll's held-out RMS +50 %
    assert 0.5 * rms[3] > 0.0025 * data.force_scale[3]  # a change that matters
    why = rejection(data, [(lib["thrust_gain"], np.array([0.0]))], r, worse, 1)
    assert why.startswith("the held-out residual of K grows"), why
    # the same rise where the effect explains most of the misfit in X, Y and Z: it is
    # weighed against their gain, log(1.5²) against 3 log(2²), more than 10 %
    traded = worse.copy()
    traded[data.test, :3] *= 0.5
    why = rejection(data, [(lib["thrust_gain"], np.array([0.0]))], r, traded, 1)
    assert why.startswith("the held-out residual of K grows") and "10 %" in why, why
    # a 5 % rise against that gain costs 2.3 % of it: the effect is named
    small = r.copy()
    small[data.test, :3] *= 0.5
    small[data.test, 3] *= 1.05
    assert rejection(data, [(lib["thrust_gain"], np.array([0.0]))], r, small, 1) == ""
    # within what an effect fitted to noise adds (4 k / n_eff), it is not a rise at all
    slight = small.copy()
    slight[data.test, 3] = r[data.test, 3] * (1.0 + 1.0 / data.n_eff_train)
    assert rejection(data, [(lib["thrust_gain"], np.array([0.0]))], r, slight, 1) == ""
    # nor is a rise far below the DOF's force scale (a DOF at its noise floor)
    tiny = small.copy()
    tiny[data.test, 3] = r[data.test, 3] * (1.0 + 0.5 * 0.0025 * data.force_scale[3] / rms[3])
    assert rejection(data, [(lib["thrust_gain"], np.array([0.0]))], r, tiny, 1) == ""


def test_current_uses_the_vehicles_added_mass_switches() -> None:
    """MuJoCo applies C_A(ν_r)ν_r but no M_A ν̇: the current's prediction has no M_A ν̇_c
    then (before it always had)."""
    b = vehicle().body
    off = replace(b, added_mass_terms=AddedMassTerms(inertial=False, coriolis=True, munk=True))
    p = np.array([0.2, -0.1])
    on_data, off_data = _short(3000), _short(3000, off)
    ch = on_data.chunk_at(slice(0, 3000))
    rho_on = Current().predict(on_data, ch, p)
    rho_off = Current().predict(off_data, ch, p)
    vcb = np.einsum("nji,j->ni", ch.R, np.array([0.2, -0.1, 0.0]))
    nu_c_dot = np.concatenate([-np.cross(ch.nu[:, 3:], vcb), np.zeros_like(vcb)], axis=1)
    np.testing.assert_allclose(rho_off - rho_on, nu_c_dot @ b.added_mass.T, atol=1e-12)


def test_a_diverging_free_run_is_explained() -> None:
    v = vehicle()
    theta = v.damping.theta_from_dict({**NOMINAL, "Z_ww": -61.0})
    samples, _ = clean(1)
    why = divergence_reason(v.damping, theta, samples.nu)
    # Z_w w − 61 w²: the heave force peaks at Z_w² / (4 · 61) at w = Z_w / 122
    peak = NOMINAL["Z_w"] ** 2 / (4 * 61.0)
    assert why == f"diverges: Z_ww < 0 leaves no steady heave speed above {peak:.3g} N (+w)"
    assert divergence_reason(v.damping, v.theta, samples.nu) == ""


@pytest.mark.slow
@pytest.mark.parametrize("switch", ["inertial", "coriolis"])
def test_a_plant_without_an_added_mass_term_is_named_in_that_form(switch: str) -> None:
    """The plant applies no M_A ν̇ (MuJoCo, gz-sim's disable_added_mass) or no C_A(ν)ν
    (disable_coriolis); the model has both. Before: a delay of 0.0 ms and a per-DOF added
    mass (M_A's smallest eigenvalue 0), or four cross terms and added masses were named."""
    data, result = analyse_named(f"plant_no_{switch}", 1)
    assert result.named == [f"added_mass_{switch}"], result.named
    assert float(result.effects[0][1][0]) == pytest.approx(-1.0, abs=0.01)
    upd = updated_model(data, result.effects)
    assert getattr(upd.added_mass_terms, switch) is False
    np.testing.assert_array_equal(upd.M, data.body.M)
    upd.body(data)  # a valid rigid body


def test_the_attitude_measures_a_gyro_bias_and_not_a_modelling_error() -> None:
    """A gyro bias must show in the logged attitude (its rate differs from the logged body
    rates by the bias); a modelling error does not, so gap does not call it a gyro bias."""
    from dampest_ros.core.gap.effects import GyroBias, attitude_gyro_bias

    v = vehicle()
    truth = np.array([0.005, -0.005, 0.005])
    case = CASES["gyro_bias"]
    samples, joints = hidden(json.dumps(case.effects), 1)
    theta, body = believed(case)
    biased = GapData(samples, v.damping, theta, body, v.thrusters, joints)
    b, sd = attitude_gyro_bias(biased)
    np.testing.assert_allclose(b, truth, atol=5 * sd.max() + 2e-4)
    assert GyroBias().implausible(biased, truth) == ""
    samples, _ = clean(1)
    data = GapData(samples, v.damping, v.theta, v.body)
    b0, sd0 = attitude_gyro_bias(data)
    assert np.all(np.abs(b0) < 5 * sd0 + 2e-4)
    assert "not a gyro bias" in GyroBias().implausible(data, np.radians([0.0, 4.2, 0.0]))


def test_an_effect_below_its_own_sigma_is_not_named() -> None:
    """The Wald test of an effect's magnitudes against their covariance: a pool's 0.013 ±
    0.006 m/s current is not significant (W 4.7 < 13.8, χ² 99.9 % of 2), a 0.25 ± 0.002 m/s
    one is; a memory state is tested on its gain c alone (λ shapes the kernel)."""
    cov = np.diag([0.006, 0.006]) ** 2
    why = insignificance(Current(), np.array([0.013, 0.0]), cov, 1e-3)
    assert why.startswith("below its own significance: ") and "Wald 4.69 ≤ 13.8" in why, why
    assert insignificance(Current(), np.array([0.25, 0.1]), np.diag([2e-3, 2e-3]) ** 2,
                          1e-3) == ""
    memory = Memory(5)
    strong_c = np.array([3.0, 0.4])
    assert insignificance(memory, strong_c, np.diag([0.5, 5.0]) ** 2, 1e-3) == ""
    assert "Wald" in insignificance(memory, strong_c, np.diag([1.5, 0.01]) ** 2, 1e-3)


# --- the whole evidence: extrapolation of the believed model, the refit at ν_r ---------------


def _current_data(flown: np.ndarray | None = None,
                  model_rmse: np.ndarray | None = None) -> GapData:
    """The hidden-current case of seed 1 against the nominal model."""
    v = vehicle()
    samples, _ = hidden(json.dumps(CASES["current"].effects), 1)
    return GapData(samples, v.damping, v.theta, v.body, flown=flown, model_rmse=model_rmse)


def test_a_dof_worse_only_outside_the_flown_envelope_is_extrapolation() -> None:
    """A DOF whose held-out residual triples where the current moves ν_r outside the
    velocities the model was fitted on is extrapolation: the current that explains most of
    X and Y is named, and the DOF is reported with why. The same rise inside the envelope is
    evidence against it (before, any rise rejected the effect)."""
    samples, _ = hidden(json.dumps(CASES["current"].effects), 1)
    box = np.quantile(samples.nu, [0.1, 0.9], axis=0)  # the model "was fitted" on 80 %
    data = _current_data(flown=box)
    cur = (Current(), np.array([0.12, -0.08]))
    out = outside(data, relative_velocity(data, [cur])) & data.test
    inside = data.test & ~out
    assert 0.2 < inside.sum() / data.test.sum() < 0.8
    r = data.r0
    after = r.copy()
    after[data.test, :2] *= 0.3  # X and Y explained
    after[out, 2] *= 3.0  # Z worse only outside the envelope
    [d] = degradations(data, [cur], r, after, 2, 0.0025)
    assert d.dof == 2 and d.extrapolation, d.text
    ms = np.mean(r[data.test, 2] ** 2)
    share = np.sum(r[out, 2] ** 2) / np.sum(r[data.test, 2] ** 2)
    assert d.after / d.before == pytest.approx(np.sqrt(1 + 8 * share), rel=1e-9)
    assert d.before == pytest.approx(np.sqrt(ms), rel=1e-9)
    assert "relative velocity" in d.why and "fitted on" in d.why and "extrapolation" in d.why
    assert rejection(data, [cur], r, after, 2) == ""
    inner = r.copy()
    inner[data.test, :2] *= 0.3
    inner[inside, 2] *= 3.0  # Z worse where the model is trusted
    [d] = degradations(data, [cur], r, inner, 2, 0.0025)
    assert not d.extrapolation, d.text
    why = rejection(data, [cur], r, inner, 2)
    assert why.startswith("the held-out residual of Z grows"), why
    # unless the rise is within the model's own error on its fit data
    trusted = _current_data(flown=box, model_rmse=np.full(6, 10.0 * np.sqrt(ms)))
    [d] = degradations(trusted, [cur], r, inner, 2, 0.0025)
    assert d.extrapolation and "own error" in d.why, d.text


def test_a_rise_without_a_moved_velocity_is_not_extrapolation() -> None:
    """An effect that does not move ν_r (a thrust gain) gets no allowance."""
    data = _current_data(flown=np.zeros((2, 6)))
    r = data.r0
    after = r.copy()
    after[data.test, 2] *= 2.0
    gain = (library(["thrusters"])[0], np.array([0.0]))
    [d] = degradations(data, [gain], r, after, 1, 0.0025)
    assert not d.extrapolation and d.why == "inside the believed model's flown envelope"
    # nor one named after a current: only the new effect's own move of ν_r counts
    [d] = degradations(data, [(Current(), np.array([0.12, -0.08])), gain], r, after, 1,
                       0.0025)
    assert not d.extrapolation, d.text


def test_the_refit_at_the_relative_velocity_recovers_the_current() -> None:
    """The model's terms refitted at ν_r jointly with the current, from a start 0.04 m/s
    off: the current within 2 % and 1°, and every DOF's held-out residual at least as small
    as the exact model's at ν (the hidden current is 0.144 m/s towards 326.3°)."""
    data = _current_data()
    half = GapData(data.samples.take(slice(0, len(data.samples) // 2)), data.model,
                   data.theta, data.body)
    v = vehicle()
    rel = refit_relative(half, v.damping, v.theta, np.array([0.09, -0.05, 0.0]))
    speed = float(np.hypot(rel.current[0], rel.current[1]))
    heading = float(np.degrees(np.arctan2(rel.current[1], rel.current[0])) % 360)
    assert speed == pytest.approx(np.hypot(0.12, 0.08), rel=0.02)
    assert heading == pytest.approx(np.degrees(np.arctan2(-0.08, 0.12)) % 360, abs=1.0)
    assert np.all(rel.rms_after <= rel.rms_before), (rel.rms_before, rel.rms_after)
    assert np.all(rel.r2_after[:3] >= 0.99), rel.r2_after
    assert rel.fit.names == v.damping.parameter_names


def test_the_refit_at_the_relative_velocity_adds_the_terms_its_model_lacks() -> None:
    """A believed model without the surge and sway quadratic drag: refitted at ν_r with its
    own terms only (rounds=0), X and Y keep held-out R² 0.86 and 0.92; with the default
    selection at ν_r it adds exactly X_uu and Y_vv, every DOF reaches R² ≥ 0.999 held out,
    and the current stays within 1 % and 0.5° (0.144 m/s towards 326.3°)."""
    v = vehicle()
    data = _current_data()
    values = dict(zip(v.damping.parameter_names, v.theta, strict=True))
    lacking = DampingModel([linear_term(), quadratic_term([2, 3, 4, 5])])
    theta = np.array([values[n] for n in lacking.parameter_names])
    half = GapData(data.samples.take(slice(0, len(data.samples) // 2)), lacking, theta,
                   data.body)
    start = np.array([0.09, -0.05, 0.0])
    own = refit_relative(half, lacking, theta, start, rounds=0)
    assert own.added == {} and own.rounds == 0
    assert np.all(own.r2_after[:2] < 0.95), own.r2_after
    rel = refit_relative(half, lacking, theta, start)
    assert rel.added == {0: ["X_uu"], 1: ["Y_vv"]} and rel.rounds == 1
    assert rel.fit.names == rel.model.parameter_names
    assert set(rel.model.parameter_names) == set(v.damping.parameter_names)
    assert np.all(rel.r2_after >= 0.999), rel.r2_after
    found = dict(zip(rel.fit.names, rel.fit.theta, strict=True))
    assert found["X_uu"] == pytest.approx(values["X_uu"], rel=0.05)
    assert found["Y_vv"] == pytest.approx(values["Y_vv"], rel=0.05)
    assert np.hypot(rel.current[0], rel.current[1]) == pytest.approx(np.hypot(0.12, 0.08),
                                                                     rel=0.01)
    heading = float(np.degrees(np.arctan2(rel.current[1], rel.current[0])) % 360)
    assert heading == pytest.approx(np.degrees(np.arctan2(-0.08, 0.12)) % 360, abs=0.5)


def test_relative_samples_leave_the_rigid_body_force_unchanged() -> None:
    """Fossen's property 8.1: for a constant NED current M_RB ν̇ + C_RB(ν)ν is the same at
    ν and at ν_r, so the regression at ν_r differs only in M_A, C_A and D."""
    v = vehicle()
    samples, _ = clean(1)
    s = samples.take(slice(0, 500))
    rel = relative_samples(s, np.array([0.3, -0.2, 0.1]))
    b = v.body

    def rigid(x: Samples) -> np.ndarray:
        return np.asarray(x.nu_dot @ b.M_RB.T + coriolis_force(b.M_RB, x.nu))

    assert np.allclose(rigid(rel), rigid(s), atol=1e-9)
    assert not np.allclose(rel.nu[:, :3], s.nu[:, :3])


def test_the_updated_model_keeps_every_kind_of_term() -> None:
    """Before: a coriolis term (what ``identify --select`` finds for MuJoCo's Magnus lift)
    was dropped from the updated model, so --out wrote the model without it and the refit at
    ν_r fitted the selected terms less that one."""
    v = vehicle()
    samples, _ = clean(1)
    model = DampingModel([linear_term(), quadratic_term(), coriolis_term()])
    theta = np.concatenate([v.theta, [1.5, -2.0, 3.0]])
    data = GapData(samples.take(slice(0, 3000)), model, theta, v.body)
    lib = {e.key: e for e in library()}
    upd = updated_model(data, [(lib["linear.X_u"], np.array([1.0]))])
    assert upd.model.kinds == ["linear", "quadratic", "coriolis"]
    values = dict(zip(upd.model.parameter_names, upd.theta, strict=True))
    assert [values[f"coriolis.m_{d}"] for d in "uvw"] == [1.5, -2.0, 3.0]
    assert values["X_u"] == pytest.approx(NOMINAL["X_u"] + 1.0)
