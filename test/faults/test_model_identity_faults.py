"""A model used with a vehicle (or arm) it does not belong to: refused naming both, with the
fix; a file written before models carried an identity: taken with a warning."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from dampest_ros.cli.inputs import load_model_for
from dampest_ros.cli.main import main
from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.identity import digest
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.io.yaml_io import foreign_model, load_model, load_vehicle, save_model

REPO = Path(__file__).resolve().parents[2]


def vehicle_model(vehicle: Vehicle) -> Model:
    """The vehicle's nominal damping as a model of it."""
    return Model(vehicle.damping.parameter_names, vehicle.theta,
                 np.full(vehicle.damping.n_params, 0.1), vehicle.body.M,
                 damping=vehicle.damping, identity=vehicle.identity)


def renamed_heavier(tmp_path: Path) -> Path:
    """The BlueROV2 Heavy preset 2 kg heavier under the same name."""
    spec = yaml.safe_load((REPO / "config/vehicles/bluerov2_heavy.yaml").read_text())
    spec["vehicle"]["mass"] = float(spec["vehicle"]["mass"]) + 2.0
    path = tmp_path / "bluerov2_heavy_payload.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def test_the_hash_follows_the_rounding_rule() -> None:
    assert digest({"a": 1.0, "b": [0.1 + 0.2, -0.0]}) == digest({"b": [0.3, 0.0], "a": 1})
    assert digest({"a": 1.0}) != digest({"a": 1.000001})
    heavy = load_vehicle("bluerov2_heavy")
    assert heavy.identity.hash == load_vehicle("bluerov2_heavy").identity.hash
    assert heavy.identity.hash != load_vehicle("bluerov2_heavy_mujoco").identity.hash


def test_export_refuses_another_vehicles_model(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    path = save_model(tmp_path / "torpedo.yaml", vehicle_model(load_vehicle("torpedo_auv")))
    capsys.readouterr()
    assert main(["export", str(path), "--format", "gz", "--vehicle", "bluerov2_heavy"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "belongs to vehicle_damping 'torpedo_auv'" in err
    assert "not to the vehicle in use 'bluerov2_heavy'" in err
    assert "they differ in rigid_body, added_mass)" in err  # thrusters do not decide


def test_validate_and_gap_refuse_a_model_of_a_vehicle_of_the_same_name(tmp_path: Path
                                                                       ) -> None:
    """Same name, 2 kg more: the rigid body's hash tells them apart (load_model_for is what
    validate and gap read --model with)."""
    path = save_model(tmp_path / "m.yaml", vehicle_model(load_vehicle("bluerov2_heavy")))
    payload = load_vehicle(renamed_heavier(tmp_path))
    assert payload.name == "bluerov2_heavy"
    with pytest.raises(ConfigError, match=r"\(they differ in rigid_body\)") as info:
        load_model_for(str(path), payload)
    assert f"'bluerov2_heavy' ({payload.identity.hash[:8]})" in str(info.value)


def test_old_model_file_loads_with_a_warning(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    heavy = load_vehicle("bluerov2_heavy")
    path = save_model(tmp_path / "old.yaml", vehicle_model(heavy))
    doc = yaml.safe_load(path.read_text())
    del doc["/**"]["ros__parameters"]["model"]["identity"]
    path.write_text(yaml.safe_dump(doc))
    assert load_model(path).identity is None
    capsys.readouterr()
    load_model_for(str(path), heavy)
    assert capsys.readouterr().err == (
        f"warning: {path}: no vehicle identity: written before model files carried "
        "model.identity (dampest_ros 0.1.0 and earlier); cannot check it belongs to vehicle "
        "'bluerov2_heavy'\n")


def test_identify_prior_of_another_vehicle_is_refused(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    prior = save_model(tmp_path / "p.yaml", vehicle_model(load_vehicle("platform_a")))
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    capsys.readouterr()
    assert main(["identify", str(tmp_path / "a"), str(tmp_path / "b"), "--vehicle",
                 "bluerov2_heavy", "--prior", str(prior)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "belongs to vehicle_damping 'platform_a'" in err


def test_save_refuses_to_replace_another_vehicles_or_an_arms_model(tmp_path: Path) -> None:
    """What the nodes' ~/save checks before writing."""
    heavy, torpedo = load_vehicle("bluerov2_heavy"), load_vehicle("torpedo_auv")
    path = save_model(tmp_path / "m.yaml", vehicle_model(torpedo))
    why = foreign_model(path, heavy.identity)
    assert why is not None and "'torpedo_auv'" in why and "set save_path" in why
    assert foreign_model(path, torpedo.identity) is None
    assert foreign_model(tmp_path / "none.yaml", heavy.identity) is None
    from dampest_ros.core.physics.identity import arm_identity
    arm = arm_identity("ur5", {"names": ["j1"]}, ["j1.m"])
    why = foreign_model(path, arm)
    assert why is not None and "it is a vehicle_damping model, not a arm one" in why


def test_a_hull_model_holds_with_other_thrusters_and_switches(tmp_path: Path) -> None:
    """Thrusters only turn telemetry into τ, and the added-mass switches travel with the
    model: neither refuses a model of the same hull (a vehicle file without thrusters for a
    log of τ; a MuJoCo-like plant without M_A ν̇)."""
    from dataclasses import replace

    from dampest_ros.core.physics.rigid_body import AddedMassTerms

    heavy = load_vehicle("bluerov2_heavy")
    path = save_model(tmp_path / "m.yaml", vehicle_model(heavy))
    bare = replace(heavy, thrusters=None)
    switched = replace(heavy, body=replace(heavy.body, added_mass_terms=AddedMassTerms(
        inertial=False, coriolis=True, munk=False)))
    for other in (bare, switched):
        load_model_for(str(path), other)  # no refusal
