"""Model files (a vehicle's damping and an arm's base parameters) checked against their
schemas: a misspelt key, a wrong type or lists of unequal lengths are refused with
``file:line: key: what; fix``, never ignored or read as something else; what the package
writes passes the same check."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from dampest_ros.core.arm.online import ArmEstimate
from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.identity import ARM_KIND, Identity
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.vehicle import damping_from_spec
from dampest_ros.io.arm import ArmDataError, load_arm_model, save_arm_model
from dampest_ros.io.schema import check
from dampest_ros.io.strict_yaml import load_yaml
from dampest_ros.io.yaml_io import load_model, load_vehicle, save_model

EVERY_TERM = {
    "linear": {"X_u": 13.7, "Y_v": 2.0, "Z_w": 33.0, "N_r": 0.3, "Y_r": -0.4},
    "quadratic": {"X_uu": 141.0, "Y_vv": 217.0},
    "cross": [{"row": "Y", "col": "v", "alpha": "|r|", "value": 2.0},
              {"row": "Z", "col": "u", "alpha": "w", "name": "Z_uw", "value": -1.5}],
    "freq": [{"dof": "u", "rate": 2.0, "c": 5.0}, {"dof": "r", "rate": 0.5, "c": 0.2}],
    "added": {"added.N_uv": 0.3},
    "coriolis": {"coriolis.m_u": 0.5},
    "residual": {"modes": [[1, 0, 1, 0, 0, 0]], "values": [4.0]},
}


def vehicle_file(tmp_path: Path) -> Path:
    """A model with every term kind, the vehicle's identity, a held coefficient and extras."""
    vehicle = load_vehicle("bluerov2_heavy")
    damping, theta = damping_from_spec(EVERY_TERM)
    std = np.full(damping.n_params, 0.1)
    std[1] = np.nan
    return save_model(tmp_path / "model.yaml", Model(
        damping.parameter_names, theta, std, vehicle.body.M, damping=damping,
        held={"Y_v": "no excitation"}, identity=vehicle.identity,
        M_A=vehicle.body.added_mass, added_mass_terms=vehicle.body.added_mass_terms,
        extra={"source": "test", "rmse": [0.1, 0.2], "fit": {"samples": 10, "ok": True},
               "flown_speeds": {"min": [-1.0] * 6, "max": [1.0] * 6}}))


def arm_file(tmp_path: Path) -> Path:
    """An arm model of two base parameters with an identity and extras."""
    est = ArmEstimate(("j1", "j2"), ["b1", "b2"], np.array([0.5, 1.5]), np.array([0.1, 0.2]),
                      np.array([True, False]), ["b1 = I1", "b2 = I2 + m2 l2"],
                      identity=Identity(ARM_KIND, "two_link", (("links", "ab12"),)))
    return save_arm_model(tmp_path / "arm.yaml", est, "two_link",
                          {"source": "test", "consistent_full": {"names": ["a"],
                                                                 "values": [1.0]}})


def edit(path: Path, old: str, new: str) -> int:
    """Replace the first ``old`` in the file by ``new``; the 1-based line of the change."""
    text = path.read_text()
    at = text.index(old)
    path.write_text(text[:at] + new + text[at + len(old):])
    return text[:at].count("\n") + 1


def test_what_the_package_writes_passes_the_model_schemas(tmp_path: Path) -> None:
    vehicle = vehicle_file(tmp_path)
    check(load_yaml(vehicle), "model")
    assert load_model(vehicle).held == {"Y_v": "no excitation"}
    check(load_yaml(arm_file(tmp_path)), "arm_model")
    assert load_arm_model(tmp_path / "arm.yaml").identified.tolist() == [True, False]


@pytest.mark.parametrize(("old", "new", "key", "says"), [
    ("theta_std:", "theta_sdt:", "model.theta_sdt", "unknown key; did you mean theta_std?"),
    ("parameter_names:", "parameter_name:", "model.parameter_name",
     "did you mean parameter_names?"),
    ("identified:", "identifed:", "model.identifed", "did you mean identified?"),
    ("M_A:", "M_a:", "model.M_a", "did you mean M_A?"),
    ("version: 1", "version: one", "model.version", 'got "one"; expected an integer'),
    ("theta: [", "theta: [13.7x, ", "model.theta[0]", 'got "13.7x"; expected a number'),
    ("theta: [", "theta: [1.0, ", "model.theta", "17 entries for 16 parameter_names; give one"),
    ("names: [Y_vr, Z_uw]", "names: [Y_vr]", "model.terms.cross.names",
     "has 1 entries for 2 terms.cross.rows"),
    ("reasons: [no excitation]", "reasons: [a, b]", "model.held.reasons",
     "has 2 entries for 1 held.names"),
    ("rates: [", "rates: [-1.0, ", "model.terms.freq.rates[0]", "expected a rate λ > 0"),
    ("kind: vehicle_damping", "kind: 3", "model.identity.kind", "got 3; expected"),
])
def test_a_vehicle_model_file_refuses_typos_types_and_lengths(
        tmp_path: Path, old: str, new: str, key: str, says: str) -> None:
    """A misspelt ``identifed`` was kept as an extra entry and the held coefficient read as
    identified; ``version: one`` and ``13.7x`` crashed with a bare ValueError."""
    path = vehicle_file(tmp_path)
    line = edit(path, old, new)
    with pytest.raises(ConfigError) as err:
        load_model(path)
    assert str(err.value).startswith(f"{path}:{line}: {key}: "), err.value
    assert says in str(err.value)


@pytest.mark.parametrize(("old", "new", "key", "says"), [
    ("theta_std:", "theta_sdt:", "model.theta_sdt", "unknown key; did you mean theta_std?"),
    ("mapping:", "maping:", "model.maping", "did you mean mapping?"),
    ("version: 1", "version: 1.5", "model.version", "got 1.5; expected an integer"),
    ("theta: [", "theta: [0.1, ", "model.theta", "3 entries for 2 parameter_names"),
    ("identified: [true, false]", "identified: [true, nope]", "model.identified[1]",
     'got "nope"; expected true or false'),
    ("theta_std: [0.1", "theta_std: [.nan", "model.theta_std", "must be finite"),
    ("kind: arm_base_parameters", "kind: arm", "model.kind", "not an arm's model file"),
])
def test_an_arm_model_file_refuses_typos_types_and_lengths(
        tmp_path: Path, old: str, new: str, key: str, says: str) -> None:
    path = arm_file(tmp_path)
    line = edit(path, old, new)
    with pytest.raises(ArmDataError) as err:
        load_arm_model(path)
    assert str(err.value).startswith(f"{path}:{line}: {key}: "), err.value
    assert says in str(err.value)


def test_a_model_of_the_other_kind_is_named(tmp_path: Path) -> None:
    """An arm's file given as a vehicle's model, and the other way round."""
    with pytest.raises(ConfigError, match=re.escape(f"{arm_file(tmp_path)}:") + r"\d+: "
                       r"model\.kind: arm_base_parameters: an arm's model file"):
        load_model(tmp_path / "arm.yaml")
    with pytest.raises(ArmDataError, match=re.escape(f"{vehicle_file(tmp_path)}:") + r"\d+: "
                       r"model\.kind: None, not 'arm_base_parameters'"):
        load_arm_model(tmp_path / "model.yaml")
