"""dampest simulate and identify with the vehicle file's sensors: section (issue 15): a bag of
a vehicle with an off-centre DVL and a rotated IMU identifies to the truth with the same file
(and not with the preset that lacks the section); a file whose frame_id does not match the
bag's gets one warning line per topic on stderr."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from dampest_ros.cli.main import main
from dampest_ros.io.yaml_io import load_model, vehicle_path

SENSORS = {"dvl": {"position": [0.3, 0.0, 0.15]},
           "imu": {"position": [0.1, -0.05, 0.05], "rpy": [0.0, 0.2, 1.5707963267948966]},
           "pressure": {"position": [0.3, 0.0, 0.15]}}


def vehicle_file(path: Path, sensors: dict) -> Path:
    doc = yaml.safe_load(vehicle_path("bluerov2_heavy").read_text())
    doc["sensors"] = sensors
    path.write_text(yaml.safe_dump(doc))
    return path


def test_mounted_vehicle_identifies_and_foreign_frame_ids_are_warned(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    mounted = vehicle_file(tmp_path / "mounted.yaml", SENSORS)
    bag = tmp_path / "bag"
    assert main(["simulate", "--vehicle", str(mounted), "--protocol", "B", "--duration", "90",
                 "--seed", "2", "--out", str(bag)]) == 0
    out = tmp_path / "model.yaml"
    capsys.readouterr()
    assert main(["identify", str(bag), "--vehicle", str(mounted), "--out", str(out)]) == 0
    assert "frame_id" not in capsys.readouterr().err
    est, truth = load_model(out), load_model(bag / "truth_model.yaml")
    big = np.abs(truth.theta) > 10.0  # X_u, Z_w and the quadratic forces
    np.testing.assert_allclose(est.theta[big], truth.theta[big], rtol=0.05)
    # the preset without the sensors: section reads the same bag wrongly
    assert main(["identify", str(bag), "--vehicle", "bluerov2_heavy", "--out",
                 str(tmp_path / "centred_model.yaml")]) == 0
    wrong = load_model(tmp_path / "centred_model.yaml").theta
    assert np.max(np.abs(wrong[big] / truth.theta[big] - 1.0)) > 0.2
    # the same mounting, but the file expects other frame ids than the bag carries
    foreign = vehicle_file(tmp_path / "foreign.yaml", {
        **SENSORS, "dvl": {**SENSORS["dvl"], "frame_id": "dvl"},
        "imu": {**SENSORS["imu"], "frame_id": "imu"}})
    assert main(["identify", str(bag), "--vehicle", str(foreign), "--out",
                 str(tmp_path / "foreign_model.yaml")]) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if "frame_id" in line]
    assert len(err) == 2, err
    assert err[0].startswith("bag: warning: dvl/twist: ") and "'dvl_link', expected 'dvl'" \
        in err[0]
    assert err[1].startswith("bag: warning: imu/data: ") and "'imu_link', expected 'imu'" \
        in err[1]
    np.testing.assert_array_equal(load_model(tmp_path / "foreign_model.yaml").theta, est.theta)
