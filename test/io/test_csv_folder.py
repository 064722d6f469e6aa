"""The folder of per-topic CSV files: the file-name rule, message types from columns, the
clock of each file and the time-unit rule, on small files written here."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dampest_ros.core.signals.measurements import JointSeries, PressureSeries, WrenchSeries
from dampest_ros.core.signals.resample import resample_uniform
from dampest_ros.io.bag import MissingTopicError, bag_summary, read_bag
from dampest_ros.io.csv_folder import decoded_topic, is_csv_folder, read_csv_folder
from dampest_ros.io.csv_table import CsvError, seconds, time_unit


@pytest.mark.parametrize(("name", "topic"), [
    ("imu_data.csv", "imu/data"), ("_imu_data.csv", "imu/data"), ("imu-data.csv", "imu/data"),
    ("_slash_imu_slash_data.csv", "imu/data"), ("mybag-_vehicle_imu_data.csv.gz", "imu/data"),
    ("thrusters_state.csv", "thrusters/state"), ("truth_hydro_wrench.csv", "truth/hydro_wrench"),
    ("wrench.csv", "wrench"), ("_slash_sonar_slash_range.csv", "sonar/range"),
])
def test_file_names_give_topics(tmp_path: Path, name: str, topic: str) -> None:
    folder = tmp_path / "log"
    folder.mkdir()
    path = folder / name
    text = "%time,field.header.stamp,field.fluid_pressure\n1,1000000000,1\n2,1100000000,2\n"
    if name.endswith(".gz"):
        import gzip
        path.write_bytes(gzip.compress(text.encode()))
    else:
        path.write_text(text)
    assert is_csv_folder(folder)
    assert list(read_csv_folder(folder)) == [topic]
    assert decoded_topic("_slash_sonar_slash_range.csv") == "sonar/range"


def test_types_clock_and_first_line_fields(tmp_path: Path) -> None:
    """JointState names from the first line, text columns ignored; header stamps
    preferred, the record time used when they are all zero; ROS 2 sec/nanosec pairs."""
    (tmp_path / "thrusters_state.csv").write_text(
        "%time,field.header.seq,field.header.stamp,field.header.frame_id,field.name0,"
        "field.name1,field.velocity0,field.velocity1,field.effort0,field.effort1\n"
        "5000,0,0,,T1,T2,1,2,3,4\n6000,1,0,,T1,T2,1.5,2.5,3.5,4.5\n7000,2,0,,T1,T2,1,2,3,4\n")
    (tmp_path / "pressure.csv").write_text(
        "bag_time_ns,header.stamp.sec,header.stamp.nanosec,header.frame_id,fluid_pressure,"
        "variance\n9,1700000000,500000000,p_link,101325,4\n9,1700000000,600000000,,101326,4\n")
    (tmp_path / "wrench.csv").write_text(
        "%time,field.header.stamp,field.wrench.force.x,field.wrench.force.y,"
        "field.wrench.force.z,field.wrench.torque.x,field.wrench.torque.y,field.wrench.torque.z"
        "\n0,20,1,2,3,4,5,6\n0,40,1,2,3,4,5,6\n0,60,1,2,3,4,5,\n")
    rec = read_bag(tmp_path)
    joints = rec["thrusters/state"]
    assert isinstance(joints, JointSeries) and joints.names == ("T1", "T2")
    np.testing.assert_allclose(joints.stamp, [5.0, 6.0, 7.0])  # %time, in s (1 s steps)
    np.testing.assert_array_equal(joints.effort[1], [3.5, 4.5])
    pres = rec["pressure"]
    assert isinstance(pres, PressureSeries) and pres.frame_id == "p_link" and pres.variance == 4
    np.testing.assert_allclose(pres.stamp - 1.7e9, [0.5, 0.6], atol=1e-6)
    wrench = rec["wrench"]
    assert isinstance(wrench, WrenchSeries)
    np.testing.assert_allclose(wrench.stamp, [0.02, 0.04, 0.06])  # ms: 20 ms steps
    assert np.isnan(wrench.torque[2, 2])  # an empty cell is nan, dropped downstream
    summary = bag_summary(tmp_path)
    assert summary.storage == "csv" and summary.topics["/wrench"].count == 3
    window = read_csv_folder(tmp_path, ["wrench.csv"], start=0.03, stop=0.07)
    np.testing.assert_allclose(window["wrench.csv"].stamp, [0.04, 0.06])
    with pytest.raises(MissingTopicError, match="imu/data"):
        read_bag(tmp_path, ["imu/data"])


@pytest.mark.parametrize(("step", "first", "unit"), [
    (0.005, 0.0, "s"), (0.2, 12.0, "s"), (5.0, 0.0, "ms"), (20_000.0, 0.0, "µs"),
    (5e6, 0.0, "ns"), (2e8, 3e9, "ns"), (0.5, 1.7e9, "s"), (5.0, 1.7e12, "ms"),
    (5000.0, 1.7e15, "µs"), (5e6, 1.7e18, "ns"), (2.0, 1.7e9, "s"),
])
def test_time_unit_rule(step: float, first: float, unit: str) -> None:
    t = first + step * np.arange(50) * (1 + 0.3 * np.sin(np.arange(50)) / 50)
    assert time_unit(t) == unit
    assert seconds(t, "f", "time")[1] == unit


def test_time_must_increase_and_have_two_rows() -> None:
    with pytest.raises(CsvError, match=r"f: line 4, column 'time': time 2 does not increase"):
        seconds(np.array([1.0, 2.0, 2.0, 3.0]), "f", "time")
    with pytest.raises(CsvError, match="1 data line"):
        seconds(np.array([1.0]), "f", "time")


def test_resample_uniform_keeps_even_rows_and_regrids_jitter_with_the_mean_step() -> None:
    t = np.arange(100) * 0.02
    x = np.stack([np.sin(t), t], axis=1)
    even = resample_uniform(t, x)
    assert not even.resampled and even.gaps == 0 and even.period == pytest.approx(0.02)
    np.testing.assert_array_equal(even.t, t)
    rng = np.random.default_rng(0)
    moved = t + 0.006 * rng.uniform(-1, 1, len(t))
    moved = np.r_[moved[:50], moved[50:] + 1.0]  # a 1 s gap after row 49
    u = resample_uniform(moved, np.stack([np.sin(moved), moved], axis=1))
    assert u.resampled and u.gaps == 1 and np.unique(u.segment).tolist() == [0, 1]
    within = np.r_[np.diff(moved[:50]), np.diff(moved[50:])]
    assert u.period == pytest.approx(within.mean(), rel=1e-12)
    steps = np.diff(u.t)[np.diff(u.segment) == 0]
    np.testing.assert_allclose(steps, u.period, rtol=1e-9)
    np.testing.assert_allclose(u.x[:, 1], u.t, atol=1e-12)  # linear: exact
