"""Vehicle presets and the model file (a ROS 2 parameters file)."""

from __future__ import annotations

import importlib.util
import json
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.vehicle import damping_from_spec
from dampest_ros.io import yaml_io

PRESETS = Path(__file__).resolve().parents[2] / "config" / "vehicles"

FULL_SPEC: dict[str, Any] = {
    "linear": {"X_u": 13.7, "Y_v": 2.0, "Z_w": 33.0, "K_p": 0.1, "M_q": 0.8, "N_r": 0.3,
               "Y_r": -0.4},
    "quadratic": {"X_uu": 141.0, "Y_vv": 217.0, "N_rr": 1.5},
    "cross": [{"row": "Y", "col": "v", "alpha": "|r|", "value": 2.0},
              {"row": "N", "col": "r", "alpha": "|v|", "value": 0.7},
              {"row": "Z", "col": "u", "alpha": "w", "name": "Z_uw", "value": -1.5},
              {"row": "X", "col": "u", "alpha": "|U|", "value": 3.0}],
    "freq": [{"dof": "u", "rate": 2.0, "c": 5.0}, {"dof": "r", "rate": 0.5, "c": 0.2},
             {"dof": "u", "rate": 7.0, "c": 1.0}],
    "added": {"added.N_uv": 0.3},
    "point": [{"position": [0.3, 0.0, 0.2], "axis": "w", "value": 12.0},
              {"position": [0.0, -0.3, 0.21], "axis": "v", "speed": "normal", "value": 7.5},
              {"position": [0.44, 0.21, -0.04], "axis": [0.6, 0.8, 0.0], "value": 3.0},
              {"position": [0.05, 0.4, -0.02], "force": "area", "axis": [0, -0.1, 1],
               "value": 20.0},
              {"position": [0.42, -0.32, -0.08], "force": "lift", "axis": "w", "value": -37.0},
              {"position": [0.55, -0.15, 0.12], "force": "magnus", "value": -5.4}],
    "residual": {"modes": [[1, 0, 1, 0, 0, 0], [0, 1, 0, 0, 0, 1], [0, 0, 1, 0, 1, 0]],
                 "values": [4.0, 5.0, 6.0]},
}


@pytest.mark.parametrize(("name", "mass", "x_u", "m11"), [
    ("bluerov2_heavy", 13.5, 13.7, 13.5 + 6.36),
    ("platform_a", 35.0, 10.0, 35.0 + 3.5),
    ("platform_b", 150.0, 60.0, 150.0 + 45.0),
])
def test_presets_load_by_name_and_path(name: str, mass: float, x_u: float, m11: float) -> None:
    assert name in yaml_io.list_vehicles()
    for ref in (name, PRESETS / f"{name}.yaml", str(PRESETS / f"{name}.yaml")):
        v = yaml_io.load_vehicle(ref)
        assert v.body.mass == mass
        assert v.body.M[0, 0] == pytest.approx(m11, abs=1e-12)
        assert v.theta[v.damping.parameter_names.index("X_u")] == x_u
        assert v.damping.parameter_names[:6] == ["X_u", "Y_v", "Z_w", "K_p", "M_q", "N_r"]
        assert v.thrusters.count == 8


def test_bad_preset_names_the_field_and_file(tmp_path: Path) -> None:
    doc = yaml.safe_load((PRESETS / "bluerov2_heavy.yaml").read_text())
    doc["vehicle"]["mass"] = -1.0
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=rf"^{bad}:\d+: vehicle\.mass: got -1\.0; expected "
                                          "mass m in kg, a number > 0$") as err:
        yaml_io.load_vehicle(bad)
    assert err.value.field == "vehicle.mass"
    bad.write_text("vehicle: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        yaml_io.load_vehicle(bad)
    with pytest.raises(FileNotFoundError, match=r"no vehicle preset 'nautilus'.*bluerov2_heavy"):
        yaml_io.load_vehicle("nautilus")


def test_installed_share_dir_is_searched(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    share = tmp_path / "share" / "dampest_ros" / "config" / "vehicles"
    share.mkdir(parents=True)
    (share / "only_installed.yaml").write_text((PRESETS / "platform_a.yaml").read_text())
    monkeypatch.setattr(sys, "prefix", str(tmp_path))
    assert yaml_io.load_vehicle("only_installed").body.mass == 35.0


def _regressor_inputs(n_states: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(5)
    return rng.normal(size=(200, 6)), rng.normal(size=(200, n_states))


def test_damping_spec_is_the_inverse_of_damping_from_spec() -> None:
    model, theta = damping_from_spec(FULL_SPEC)
    again, theta2 = damping_from_spec(yaml_io.damping_spec(model, theta))
    assert again.parameter_names == model.parameter_names
    np.testing.assert_array_equal(theta2, theta)
    nu, z = _regressor_inputs(model.memory_rates.size)
    np.testing.assert_allclose(again.regressor(nu, z), model.regressor(nu, z), rtol=0, atol=1e-12)


def test_model_file_round_trip(tmp_path: Path) -> None:
    model, theta = damping_from_spec(FULL_SPEC)
    p = model.n_params
    rng = np.random.default_rng(9)
    theta_std = np.abs(rng.normal(size=p)) * 10.0 ** rng.integers(-12, 5, p)
    M = rng.normal(size=(6, 6))
    extra = {"vehicle": "bluerov2_heavy", "fit": {"rmse": [0.1, 0.2, 3], "samples": 36000},
             "frozen": False, "frame": "N"}
    path = yaml_io.save_model(tmp_path / "model.yaml", Model(model.parameter_names, theta,
                                                             theta_std, M, extra=extra,
                                                             damping=model, version=7))
    out = yaml_io.load_model(path)
    assert out.parameter_names == model.parameter_names
    np.testing.assert_array_equal(out.theta, theta)
    np.testing.assert_array_equal(out.theta_std, theta_std)
    np.testing.assert_array_equal(out.M, M)
    assert out.version == 7 and "sign_convention: dissipative_positive" in path.read_text()
    assert out.extra == {"vehicle": "bluerov2_heavy", "fit": {"rmse": [0.1, 0.2, 3.0],
                                                                "samples": 36000},
                         "frozen": False, "frame": "N"}
    assert out.damping is not None and out.damping.kinds == model.kinds
    nu, z = _regressor_inputs(model.memory_rates.size)
    np.testing.assert_allclose(out.damping.regressor(nu, z), model.regressor(nu, z),
                               rtol=0, atol=1e-12)
    np.testing.assert_array_equal(out.damping.memory_rates, model.memory_rates)
    assert [p.name for p in tmp_path.iterdir()] == ["model.yaml"]  # no temporary file left


@pytest.mark.skipif(importlib.util.find_spec("rclpy") is None, reason="needs rclpy")
def test_model_file_is_a_ros_parameters_file(tmp_path: Path, children: Any) -> None:
    """rcl's own YAML parser (as for --params-file) reads every entry with the right type."""
    model, theta = damping_from_spec(FULL_SPEC)
    from dampest_ros.core.physics.rigid_body import AddedMassTerms
    # σ of the two coefficients held at their prior: not estimated (inf, nan)
    std = np.r_[np.inf, np.nan, np.full(theta.size - 2, 0.5)]
    held = dict(zip(model.parameter_names[:2], ["no data", "n"], strict=True))
    path = yaml_io.save_model(tmp_path / "model.yaml", Model(
        model.parameter_names, theta, std, np.eye(6) * 2.0, damping=model,
        extra={"note": "n", "flags": [True, False]}, M_A=np.eye(6),
        added_mass_terms=AddedMassTerms(inertial=False), held=held))
    probe = (
        "import json, sys, rclpy\n"
        "from rclpy.node import Node\n"
        "rclpy.init(args=['--ros-args', '--params-file', sys.argv[1]])\n"
        "n = Node('estimator', automatically_declare_parameters_from_overrides=True)\n"
        "value = lambda v: v if isinstance(v, (str, bool, int, float)) else list(v)\n"
        "print(json.dumps({k: [p.type_.name, value(p.value)]\n"
        "                  for k, p in n.get_parameters_by_prefix('model').items()}))\n"
        "n.destroy_node(); rclpy.shutdown()\n")
    env = dict(os.environ, ROS_DOMAIN_ID="93", ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               PYTHONPATH=str(Path(__file__).resolve().parents[2]))
    proc = children.run([sys.executable, "-c", probe, str(path)], capture_output=True,
                        text=True, timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr
    params = json.loads(proc.stdout.strip().splitlines()[-1])
    types = {k: v[0] for k, v in params.items()}
    assert types["parameter_names"] == "STRING_ARRAY"
    assert types["theta"] == types["theta_std"] == types["M"] == "DOUBLE_ARRAY"
    assert types["version"] == "INTEGER" and types["sign_convention"] == "STRING"
    assert types["terms.linear"] == types["terms.cross.alphas"] == "STRING_ARRAY"
    assert types["terms.cross.rows"] == types["terms.freq.dofs"] == "INTEGER_ARRAY"
    assert types["terms.residual.modes"] == types["terms.freq.rates"] == "DOUBLE_ARRAY"
    assert types["terms.added"] == "BOOL" and types["flags"] == "BOOL_ARRAY"
    assert params["note"] == ["STRING", "n"]  # not the boolean "n"
    assert params["theta"][1] == theta.tolist()
    assert params["theta_std"][1][0] == np.inf and np.isnan(params["theta_std"][1][1])
    assert params["theta_std"][1][2:] == [0.5] * (theta.size - 2)
    # per coefficient: did the data determine it; the reasons of those held at the prior
    assert params["identified"] == ["BOOL_ARRAY", [False, False] + [True] * (theta.size - 2)]
    assert params["held.names"] == ["STRING_ARRAY", model.parameter_names[:2]]
    assert params["held.reasons"] == ["STRING_ARRAY", ["no data", "n"]]
    assert params["terms.cross.alphas"][1] == ["|r|", "|v|", "w", "|U|"]
    # the added-mass switches are three BOOL parameters, M_A 36 doubles
    assert params["added_mass_terms.inertial"] == ["BOOL", False]
    assert params["added_mass_terms.coriolis"] == params["added_mass_terms.munk"] == ["BOOL",
                                                                                    True]
    assert types["M_A"] == "DOUBLE_ARRAY" and params["M_A"][1] == np.eye(6).ravel().tolist()


def test_invalid_extra_and_failed_save_keep_the_old_file(tmp_path: Path) -> None:
    path = yaml_io.save_model(tmp_path / "m.yaml", Model(["X_u"], np.array([1.0]), np.array([0.1]),
                                                         np.eye(6)))
    before = path.read_text()
    with pytest.raises(ValueError, match=r"model\.fit\.bad: a ROS parameter array"):
        yaml_io.save_model(path, Model(["X_u"], np.array([2.0]), np.array([0.1]), np.eye(6),
                                       extra={"fit": {"bad": [1.0, "a"]}}))
    with pytest.raises(ValueError, match="reserved"):
        yaml_io.save_model(path, Model(["X_u"], np.array([2.0]), np.array([0.1]), np.eye(6),
                                       extra={"theta": 1.0}))
    with pytest.raises(ValueError, match="non-empty"):
        yaml_io.save_model(path, Model(["X_u"], np.array([2.0]), np.array([0.1]), np.eye(6),
                                       extra={"empty": []}))
    assert path.read_text() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.yaml"]


def test_load_model_errors_name_the_entry(tmp_path: Path) -> None:
    model, theta = damping_from_spec(FULL_SPEC)
    path = yaml_io.save_model(tmp_path / "m.yaml", Model(model.parameter_names, theta, theta,
                                                         np.eye(6), damping=model))
    doc = yaml.safe_load(path.read_text())
    params = doc["/**"]["ros__parameters"]["model"]
    params["terms"]["quadratic"] = ["X_uu"]
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=r"m\.yaml:\d+: model\.terms: the terms give"):
        yaml_io.load_model(path)
    del params["theta"]
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=r"m\.yaml:\d+: model\.theta: missing; add it"):
        yaml_io.load_model(path)
    path.write_text("/**: {ros__parameters: {other: 1}}\n")
    with pytest.raises(ConfigError, match="no <node>: ros__parameters: model"):
        yaml_io.load_model(path)


def test_added_mass_switches_round_trip_through_the_file_and_the_parameters(
        tmp_path: Path) -> None:
    """model.M_A and model.added_mass_terms go into the file and the model.* parameters and
    come back exactly; older files without them read as all switches on, no M_A."""
    from dampest_ros.core.physics.rigid_body import AddedMassTerms

    model, theta = damping_from_spec({"linear": {"X_u": 13.7, "N_r": 0.5}})
    v = yaml_io.load_vehicle("bluerov2_heavy")
    terms = AddedMassTerms(inertial=False, coriolis=True, munk=False)
    path = yaml_io.save_model(tmp_path / "m.yaml", Model(model.parameter_names, theta, theta,
                                                         v.body.M, damping=model,
                                                         M_A=v.body.added_mass,
                                                         added_mass_terms=terms))
    doc = yaml.safe_load(path.read_text())["/**"]["ros__parameters"]["model"]
    assert doc["added_mass_terms"] == {"inertial": False, "coriolis": True, "munk": False}
    assert doc["M_A"][0] == 6.36 and len(doc["M_A"]) == 36
    out = yaml_io.load_model(path)
    assert out.added_mass_terms == terms and out.acting_terms == terms
    np.testing.assert_array_equal(out.M_A, v.body.added_mass)
    assert "M_A" not in out.extra and "added_mass_terms" not in out.extra
    # the node parameters (bool leaves of a namespace) give the same model
    params = yaml_io.model_parameters(out)
    assert params["model.added_mass_terms.inertial"] is False
    assert params["model.added_mass_terms.munk"] is False
    back = yaml_io.model_from_parameters(params)
    assert back.added_mass_terms == terms
    np.testing.assert_array_equal(back.M_A, v.body.added_mass)
    # an older file: no switches, no M_A → all on
    old = yaml_io.save_model(tmp_path / "old.yaml", Model(model.parameter_names, theta, theta,
                                                          v.body.M, damping=model))
    o = yaml_io.load_model(old)
    assert o.added_mass_terms is None and o.M_A is None and o.acting_terms.all
    assert "added_mass_terms" not in old.read_text()
    # switches that turn effects off cannot be written or read without M_A
    with pytest.raises(ValueError, match="need M_A to split M"):
        yaml_io.save_model(tmp_path / "x.yaml", Model(model.parameter_names, theta, theta, v.body.M,
                                                      added_mass_terms=terms))
    del doc["M_A"]
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump({"/**": {"ros__parameters": {
        "model": doc}}}))
    with pytest.raises(ConfigError, match=r"bad\.yaml:\d+: model\.M_A: missing"):
        yaml_io.load_model(tmp_path / "bad.yaml")
    doc["added_mass_terms"] = {"inertial": "no"}
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump({"/**": {"ros__parameters": {
        "model": doc}}}))
    with pytest.raises(ConfigError, match=r"bad\.yaml:\d+: model\.added_mass_terms\.inertial: "
                                         r"got \"no\"; expected true or false"):
        yaml_io.load_model(tmp_path / "bad.yaml")


def test_model_file_says_which_coefficients_the_data_determined(tmp_path: Path) -> None:
    """A coefficient flagged 'not identified' was written as theta (its prior, std
    NaN) like any estimate. The file now carries model.identified and the reasons
    (model.held); the node parameters carry the same; files without the field read as all
    identified, and the unidentified lists earlier identify versions wrote are read as held."""
    model, theta = damping_from_spec({"linear": {"X_u": 13.7, "Y_v": 2.0},
                                      "quadratic": {"X_uu": 141.0, "Y_vv": 217.0}})
    std = np.array([0.2, 0.1, 1.5, np.nan])  # Y_vv held at its prior: no σ
    held = {"Y_vv": "no excitation: its regressor column is zero"}
    path = yaml_io.save_model(tmp_path / "m.yaml", Model(model.parameter_names, theta, std,
                                                         np.eye(6), damping=model, held=held))
    doc = yaml.safe_load(path.read_text())["/**"]["ros__parameters"]["model"]
    assert doc["identified"] == [True, True, True, False]
    assert doc["held"] == {"names": ["Y_vv"], "reasons": [held["Y_vv"]]}
    m = yaml_io.load_model(path)
    assert m.held == held and m.identified.tolist() == [True, True, True, False]
    assert "identified" not in m.extra and "held" not in m.extra
    params = yaml_io.model_parameters(m)
    assert params["model.identified"] == [True, True, True, False]
    assert params["model.held.names"] == ["Y_vv"]
    assert yaml_io.model_from_parameters(params).held == held
    # a file that does not say: all identified
    del doc["identified"], doc["held"]
    doc["theta_std"] = [0.2, 0.1, 1.5, 3.0]
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"model": doc}}}))
    assert yaml_io.load_model(path).identified.all()
    # earlier identify versions: unidentified / unidentified_reason lists, σ NaN
    doc["theta_std"][3] = float("nan")
    doc["unidentified"], doc["unidentified_reason"] = ["Y_vv"], ["poorly determined"]
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"model": doc}}}))
    assert yaml_io.load_model(path).held == {"Y_vv": "poorly determined"}
    # a held name the model does not have, or a mask of the wrong length, is refused
    with pytest.raises(ConfigError, match=r"^model\.held: .*Z_ww"):
        yaml_io.save_model(tmp_path / "x.yaml", Model(model.parameter_names, theta, std, np.eye(6),
                                                      held={"Z_ww": "?", **held}))
    doc["identified"] = [True, False]
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"model": doc}}}))
    with pytest.raises(ConfigError, match=r"m\.yaml:\d+: model\.identified: has 2 entries for 4 "
                                             r"parameter_names"):
        yaml_io.load_model(path)


@pytest.mark.parametrize(("entry", "index", "value", "match"), [
    ("theta", 2, float("nan"), r"^model\.theta: not finite: X_uu = nan"),
    ("theta", 0, float("inf"), r"^model\.theta: not finite: X_u = inf"),
    ("theta_std", 1, float("nan"), r"^model\.theta_std: not finite for an identified "
                                   r"coefficient: Y_v = nan"),
    ("M", 7, float("-inf"), r"^model\.M: not finite: M\[Y,v\] = -inf"),
])
def test_every_reader_refuses_non_finite_numbers(tmp_path: Path, entry: str, index: int,
                                                  value: float, match: str) -> None:
    """A NaN in a model file's theta was served by model_server_node and the client
    returned a NaN feed-forward. The file, its text, its node parameters and the evaluable
    Model all refuse it, naming the entry; a held coefficient's σ may be NaN."""
    model, theta = damping_from_spec({"linear": {"X_u": 13.7, "Y_v": 2.0},
                                      "quadratic": {"X_uu": 141.0, "Y_vv": 217.0}})
    std, M = np.array([0.2, 0.1, 1.5, np.nan]), 20.0 * np.eye(6)
    held = {"Y_vv": "poorly determined"}
    path = yaml_io.save_model(tmp_path / "m.yaml", Model(model.parameter_names, theta, std, M,
                                                         damping=model, held=held))
    good = yaml_io.load_model(path)
    assert np.isnan(good.theta_std[3]) and good.theta[3] == 217.0
    doc = yaml.safe_load(path.read_text())
    doc["/**"]["ros__parameters"]["model"][entry][index] = value
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=r"m\.yaml:\d+: " + match[1:]):
        yaml_io.load_model(path)
    with pytest.raises(ConfigError, match=r"^<text>:\d+: " + match[1:]):
        yaml_io.loads_model(path.read_text())
    params = yaml_io.model_parameters(Model(good.parameter_names, good.theta, good.theta_std,
                                            good.M, damping=good.damping, held=held))
    params[f"model.{entry}"] = list(params[f"model.{entry}"])
    params[f"model.{entry}"][index] = value
    with pytest.raises(ConfigError, match=r"^<parameters>: " + match[1:]):
        yaml_io.model_from_parameters(params)
    bad = {"theta": good.theta.copy(), "theta_std": good.theta_std.copy(),
           "M": good.M.reshape(36).copy()}
    bad[entry][index] = value
    with pytest.raises(ConfigError, match=match):  # nor the Model every writer takes
        Model(good.parameter_names, bad["theta"], bad["theta_std"], bad["M"],
              damping=good.damping, held=held)


def test_c_a_entry_mask_round_trips_as_a_ros_integer_array(tmp_path: Path) -> None:
    """Zeroed entries beyond the switches are written as model.added_mass_terms.coriolis_mask
    (36 ints, 1 = acts) and come back equal from the file and from the parameters."""
    from dampest_ros.core.physics.rigid_body import AddedMassTerms

    model, theta = damping_from_spec({"linear": {"X_u": 13.7, "N_r": 0.5}})
    v = yaml_io.load_vehicle("bluerov2_heavy")
    terms = AddedMassTerms(munk=False, coriolis_zero=((0, 4), (0, 5), (2, 4), (1, 5)))
    path = yaml_io.save_model(tmp_path / "m.yaml", Model(model.parameter_names, theta, theta,
                                                         v.body.M, damping=model,
                                                         M_A=v.body.added_mass,
                                                         added_mass_terms=terms))
    doc = yaml.safe_load(path.read_text())["/**"]["ros__parameters"]["model"]
    mask = doc["added_mass_terms"]["coriolis_mask"]
    assert len(mask) == 36 and sum(mask) == 26
    assert mask[4] == mask[5] == mask[6 + 5] == mask[12 + 4] == mask[18 + 1] == 0
    assert yaml_io.load_model(path).added_mass_terms == terms
    params = yaml_io.model_parameters(yaml_io.load_model(path))
    assert params["model.added_mass_terms.coriolis_mask"] == mask
    assert yaml_io.model_from_parameters(params).added_mass_terms == terms


def _vehicle_with(tmp_path: Path, terms_line: str) -> Path:
    """The bluerov2_heavy preset with an added_mass_terms line under added_mass."""
    text = yaml_io.vehicle_path("bluerov2_heavy").read_text()
    anchor = next(line for line in text.splitlines() if line.strip().startswith("added_mass:"))
    path = tmp_path / "vehicle.yaml"
    path.write_text(text.replace(anchor, f"{anchor}\n  added_mass_terms: {terms_line}"))
    return path


def test_vehicle_file_states_zeroed_c_a_entries_by_name_or_index(tmp_path: Path) -> None:
    by_name = yaml_io.load_vehicle(_vehicle_with(
        tmp_path, "{munk: false, coriolis_zero: [[X, q], [X, r], [Z, q], [Y, r]]}"))
    by_index = yaml_io.load_vehicle(_vehicle_with(
        tmp_path, "{munk: false, coriolis_zero: [[0, 4], [0, 5], [2, 4], [1, 5]]}"))
    assert by_name.body.added_mass_terms == by_index.body.added_mass_terms
    assert len(by_name.body.added_mass_terms.zeroed) == 10


@pytest.mark.parametrize(("line", "match"), [
    ("{coriolis_zero: [[X, Q]]}", r"vehicle\.yaml:\d+: .*coriolis_zero"),
    ("{coriolis_zero: [[X, u]]}", r"vehicle\.yaml:\d+: .*\(X, u\) = \[0, 0\] is zero in C_A"),
    ("{coriolis_zero: [X, q]}", r"vehicle\.yaml:\d+: .*coriolis_zero"),
])
def test_vehicle_file_typo_in_zeroed_entries_is_one_line_naming_the_place(
        tmp_path: Path, line: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        yaml_io.load_vehicle(_vehicle_with(tmp_path, line))
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(("axis", "error"), [
    ("[0.6, 0.8, 0.0]", None), ("[3, 4, 0]", None),
    ("[0, 0, 0]", r"vehicle\.yaml:\d+: damping\.point\[0\]\.axis: \[0, 0, 0\]: a direction "
                  r"is three finite numbers, not all zero"),
    ("[.nan, 1, 0]", r"damping\.point\[0\]\.axis: .*three finite numbers"),
    ("[1, 0]", r"vehicle\.yaml:\d+: .*damping\.point\[0\]\.axis"),
])
def test_vehicle_file_element_along_a_direction(tmp_path: Path, axis: str,
                                                error: str | None) -> None:
    """An element of a vehicle file's damping may lie along a direction [e_x, e_y, e_z]
    (normalised); a zero, non-finite or short one is one line naming the place."""
    text = yaml_io.vehicle_path("tooled_rov").read_text()
    path = tmp_path / "vehicle.yaml"
    path.write_text(text.replace("\n  coriolis:", "\n  point: [{position: [0.44, 0.21, -0.04], "
                                 f"force: lift, axis: {axis}, value: -3.0}}]\n  coriolis:"))
    if error is None:
        v = yaml_io.load_vehicle(path)
        assert "lift.e(0.6,0.8,0)@(0.44,0.21,-0.04)" in v.damping.parameter_names
        return
    with pytest.raises(ConfigError, match=error) as info:
        yaml_io.load_vehicle(path)
    assert "\n" not in str(info.value)
