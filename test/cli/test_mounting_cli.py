"""dampest simulate and identify with the vehicle file's sensors: section: a bag of
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


@pytest.fixture(scope="module")
def flown(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """90 s of protocol B of the mounted vehicle: the bag, its vehicle file, and a file of the
    same mounting that expects the frame ids 'dvl' and 'imu' (the bag has the defaults)."""
    root = tmp_path_factory.mktemp("mounted")
    mounted = vehicle_file(root / "mounted.yaml", SENSORS)
    foreign = vehicle_file(root / "foreign.yaml", {
        **SENSORS, "dvl": {**SENSORS["dvl"], "frame_id": "dvl"},
        "imu": {**SENSORS["imu"], "frame_id": "imu"}})
    assert main(["simulate", "--vehicle", str(mounted), "--protocol", "B", "--duration", "90",
                 "--seed", "2", "--out", str(root / "bag")]) == 0
    return root / "bag", mounted, foreign


def test_mounted_vehicle_identifies_and_foreign_frame_ids_are_warned(
        flown: tuple[Path, Path, Path], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    bag, mounted, foreign = flown
    out = tmp_path / "model.yaml"
    capsys.readouterr()
    assert main(["identify", str(bag), "--vehicle", str(mounted), "--out", str(out)]) == 0
    assert "frame_id" not in capsys.readouterr().err
    est, truth = load_model(out), load_model(bag / "truth_model.yaml")
    big = np.abs(truth.theta) > 10.0  # X_u, Z_w and the quadratic forces
    np.testing.assert_allclose(est.theta[big], truth.theta[big], rtol=0.05)
    # the preset without the sensors: section reads the same bag wrongly: its terms are off
    # (compared alone, --no-select; the default would add library terms for the misfit)
    assert main(["identify", str(bag), "--vehicle", "bluerov2_heavy", "--no-select", "--out",
                 str(tmp_path / "centred_model.yaml")]) == 0
    assert "misfit:" in capsys.readouterr().out
    wrong = load_model(tmp_path / "centred_model.yaml").theta
    assert np.max(np.abs(wrong[big] / truth.theta[big] - 1.0)) > 0.2
    # the same mounting, but the file expects other frame ids than the bag carries
    assert main(["identify", str(bag), "--vehicle", str(foreign), "--out",
                 str(tmp_path / "foreign_model.yaml")]) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if "frame_id" in line]
    # every DVL message (707 of 721 pings: dropouts), the IMU messages of the used stretches
    assert [line.split(" message(s)")[0] for line in err] == [
        "bag: warning: dvl/twist: 707", "bag: warning: imu/data: 16014"], err
    assert "'dvl_link', expected 'dvl'" in err[0] and "'imu_link', expected 'imu'" in err[1]
    np.testing.assert_array_equal(load_model(tmp_path / "foreign_model.yaml").theta, est.theta)


@pytest.mark.slow
def test_rls_path_warns_about_foreign_frame_ids(flown: tuple[Path, Path, Path],
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """The same lines from the online preprocessing (--method rls), counting every message."""
    bag, _, foreign = flown
    capsys.readouterr()
    assert main(["identify", str(bag), "--vehicle", str(foreign), "--method", "rls"]) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if "frame_id" in line]
    assert [line.split(" message(s)")[0] for line in err] == [
        "bag: warning: imu/data: 18001", "bag: warning: dvl/twist: 707"], err  # all of them
