"""dampest simulate: the bag, the truth model and the CSV it writes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dampest_ros.cli.main import main
from dampest_ros.io.bag import bag_summary, read_bag
from dampest_ros.io.csv import read_csv, samples_from_columns
from dampest_ros.io.yaml_io import load_model, load_vehicle


def test_simulate_writes_bag_truth_and_csv(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                           ) -> None:
    out = tmp_path / "bag"
    assert main(["simulate", "--vehicle", "bluerov2_heavy", "--protocol", "B", "--duration",
                 "20", "--seed", "3", "--out", str(out), "--csv", str(tmp_path / "s.csv")]) == 0
    summary = bag_summary(out)
    assert summary.storage == "mcap"
    types = {name.lstrip("/"): t.msgtype for name, t in summary.topics.items()}
    assert types == {"imu/data": "sensor_msgs/msg/Imu",
                     "dvl/twist": "geometry_msgs/msg/TwistWithCovarianceStamped",
                     "pressure": "sensor_msgs/msg/FluidPressure",
                     "thrusters/state": "sensor_msgs/msg/JointState",
                     "truth/odom": "nav_msgs/msg/Odometry"}
    counts = {name.lstrip("/"): t.count for name, t in summary.topics.items()}
    assert counts["imu/data"] == 20 * 200 + 1 and counts["thrusters/state"] == 20 * 50 + 1
    truth = load_model(out / "truth_model.yaml")
    vehicle = load_vehicle("bluerov2_heavy")
    assert truth.parameter_names == vehicle.damping.parameter_names
    np.testing.assert_array_equal(truth.theta, vehicle.theta)
    np.testing.assert_allclose(truth.M, vehicle.body.M)
    samples = samples_from_columns(read_csv(tmp_path / "s.csv"))
    assert len(samples) > 500 and np.all(np.isfinite(samples.nu))
    assert "imu/data" in capsys.readouterr().out


def test_simulated_bag_is_in_ros_frames(tmp_path: Path) -> None:
    """REP-103/105: at rest and level the IMU reads +g on z (FLU); the truth odometry is ENU
    (z = −depth from the pressure sensor) and its body twist agrees with the DVL's in sign."""
    out = tmp_path / "bag"
    assert main(["simulate", "--protocol", "B", "--duration", "10", "--out", str(out),
                 "--seed", "2"]) == 0
    rec = read_bag(out, ["truth/odom", "imu/data", "dvl/twist", "pressure"])
    imu, odom, dvl, pres = (rec[k] for k in ("imu/data", "truth/odom", "dvl/twist", "pressure"))
    assert imu.linear_acceleration[0, 2] == pytest.approx(9.81, abs=0.1)
    depth = (pres.fluid_pressure[0] - 101325.0) / (1000.0 * 9.81)
    assert odom.position[0, 2] == pytest.approx(-depth, abs=0.01)
    assert depth > 3.0
    i = np.searchsorted(odom.stamp, dvl.stamp[10:])
    assert np.corrcoef(odom.linear[i, 1], dvl.linear[10:, 1])[0, 1] > 0.99


def test_simulate_refuses_to_overwrite(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                       ) -> None:
    (tmp_path / "bag").mkdir()
    assert main(["simulate", "--duration", "5", "--out", str(tmp_path / "bag")]) == 2
    assert "exists" in capsys.readouterr().err


def test_simulate_rejects_unknown_effect(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                         ) -> None:
    assert main(["simulate", "--duration", "5", "--out", str(tmp_path / "b"),
                 "--effects", "curent: [0.1, 0, 0]"]) == 2
    assert "curent" in capsys.readouterr().err
