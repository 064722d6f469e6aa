"""Logs as users bring them: a folder of per-topic CSV files as `rostopic echo -p` writes
them, read as one log the way a bag is, and a single CSV whose time is in ms and uneven."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from dampest_ros.cli.main import main
from dampest_ros.core.signals.measurements import (
    ImuSeries,
    JointSeries,
    OdometrySeries,
    PressureSeries,
    Series,
    TwistSeries,
)
from dampest_ros.io import csv as dcsv
from dampest_ros.io.bag import read_bag, write_bag
from dampest_ros.io.yaml_io import load_model

#: The file names a folder of this test uses: each naming form of the tools.
FILE_NAMES = {"imu/data": "imu-data.csv", "dvl/twist": "_dvl_twist.csv",
              "pressure": "_slash_pressure.csv", "thrusters/state": "thrusters_state.csv",
              "truth/odom": "bagname-_truth_odom.csv"}
#: Record time (%time) is the wall clock of the recording: a date, and a latency later.
RECORD_EPOCH_NS = 1_700_000_000 * 10**9


def _xyz(prefix: str, axes: str = "xyz") -> list[str]:
    return [f"field.{prefix}.{a}" for a in axes]


def _rows(series: Series) -> dict[str, np.ndarray]:
    """The message fields of one series as rostopic flattens them (name → column)."""
    n = len(series)
    if isinstance(series, ImuSeries):
        cols = {**dict(zip(_xyz("orientation", "xyzw"), series.orientation.T, strict=True)),
                **{f"field.orientation_covariance{i}": np.full(n, v)
                   for i, v in enumerate(series.orientation_covariance)},
                **dict(zip(_xyz("angular_velocity"), series.angular_velocity.T, strict=True)),
                **dict(zip(_xyz("linear_acceleration"), series.linear_acceleration.T,
                           strict=True))}
    elif isinstance(series, TwistSeries):
        cols = {**dict(zip(_xyz("twist.twist.linear"), series.linear.T, strict=True)),
                **dict(zip(_xyz("twist.twist.angular"), series.angular.T, strict=True)),
                **{f"field.twist.covariance{i}": np.full(n, v)
                   for i, v in enumerate(series.covariance)}}
    elif isinstance(series, PressureSeries):
        cols = {"field.fluid_pressure": series.fluid_pressure,
                "field.variance": np.full(n, series.variance)}
    elif isinstance(series, JointSeries):
        cols = {**{f"field.name{i}": np.full(n, name) for i, name in enumerate(series.names)},
                **{f"field.velocity{i}": v for i, v in enumerate(series.velocity.T)},
                **{f"field.effort{i}": e for i, e in enumerate(series.effort.T)}}
    else:
        assert isinstance(series, OdometrySeries)
        cols = {"field.child_frame_id": np.full(n, series.child_frame_id),
                **dict(zip(_xyz("pose.pose.position"), series.position.T, strict=True)),
                **dict(zip(_xyz("pose.pose.orientation", "xyzw"), series.orientation.T,
                           strict=True)),
                **dict(zip(_xyz("twist.twist.linear"), series.linear.T, strict=True)),
                **dict(zip(_xyz("twist.twist.angular"), series.angular.T, strict=True))}
    return cols


def write_rostopic_csv(path: Path, series: Series, rng: np.random.Generator) -> None:
    """One topic as `rostopic echo -p` writes it: %time (record time, ns), header seq,
    stamp (ns) and an empty frame_id, then the fields; numbers in full precision."""
    stamp_ns = np.round(series.stamp * 1e9).astype(np.int64)
    record_ns = RECORD_EPOCH_NS + stamp_ns + rng.integers(100_000, 3_000_000, len(series))
    text = {"%time": record_ns.astype(str),
            "field.header.seq": np.arange(len(series)).astype(str),
            "field.header.stamp": stamp_ns.astype(str),
            "field.header.frame_id": np.full(len(series), "")}
    for name, col in _rows(series).items():
        text[name] = col if col.dtype.kind == "U" else np.char.mod("%.17g", col)
    table = np.stack(list(text.values()), axis=1)
    np.savetxt(path, table, fmt="%s", delimiter=",", header=",".join(text), comments="")


def jittered(series: Series, rng: np.random.Generator, share: float = 0.3) -> Series:
    """The series with every stamp moved by up to ±share of its period (uniform)."""
    dt = float(np.median(np.diff(series.stamp)))
    moved = series.stamp + share * dt * rng.uniform(-1.0, 1.0, len(series))
    return replace(series, stamp=np.maximum(moved, 0.0))


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """BlueROV2 Heavy, protocol B, 120 s seed 4, stamps jittered ±30 %: as a rosbag2 bag
    (bag/) and as a folder of rostopic CSV files (csv/)."""
    root = tmp_path_factory.mktemp("csvfolder")
    assert main(["simulate", "--vehicle", "bluerov2_heavy", "--protocol", "B", "--duration",
                 "120", "--seed", "4", "--out", str(root / "sim")]) == 0
    rng = np.random.default_rng(7)
    rec = {t: jittered(s, rng) for t, s in read_bag(root / "sim").items()}
    write_bag(root / "bag", rec)
    (root / "csv").mkdir()
    for topic, series in rec.items():
        write_rostopic_csv(root / "csv" / FILE_NAMES[topic], series, rng)
    return root


def test_folder_identifies_like_the_bag_of_the_same_recording(
        recording: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    for log in ("bag", "csv"):
        assert main(["identify", str(recording / log), "--vehicle", "bluerov2_heavy",
                     "--delay", "auto", "--out", str(recording / f"{log}.yaml")]) == 0
    err = capsys.readouterr().err
    assert "imu-data.csv → imu/data (sensor_msgs/msg/Imu, 24001 messages): time from " \
           "field.header.stamp in ns" in err
    assert "bagname-_truth_odom.csv → truth/odom" in err
    bag, folder = load_model(recording / "bag.yaml"), load_model(recording / "csv.yaml")
    assert folder.parameter_names == bag.parameter_names
    ratio = np.abs(folder.theta - bag.theta) / bag.theta_std
    # measured: max |Δθ|/σ = 1.4e-11 (the same messages and stamps to the nanosecond)
    assert ratio.max() < 1e-6, ratio.max()
    assert np.all(bag.theta_std > 0)


def test_folder_of_the_mujoco_torpedo_identifies_like_its_bag(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Physics we did not write: MuJoCo's torpedo (60 s, protocol B), stamps jittered ±30 %,
    as a rosbag2 bag and as a rostopic CSV folder: the same θ."""
    assert main(["simulate", "--backend", "mujoco", "--vehicle", "torpedo_auv", "--protocol",
                 "B", "--duration", "60", "--seed", "2", "--out", str(tmp_path / "sim")]) == 0
    rng = np.random.default_rng(8)
    rec = {t: jittered(s, rng) for t, s in read_bag(tmp_path / "sim").items()
           if t in FILE_NAMES}
    write_bag(tmp_path / "bag", rec)
    (tmp_path / "csv").mkdir()
    for topic, series in rec.items():
        write_rostopic_csv(tmp_path / "csv" / FILE_NAMES[topic], series, rng)
    capsys.readouterr()
    models = []
    for log in ("bag", "csv"):
        assert main(["identify", str(tmp_path / log), "--vehicle", "torpedo_auv", "--out",
                     str(tmp_path / f"{log}.yaml")]) == 0
        models.append(load_model(tmp_path / f"{log}.yaml"))
    bag, folder = models
    assert np.max(np.abs(folder.theta - bag.theta) / bag.theta_std) < 1e-6


def test_inspect_folder_names_files_columns_rates_and_time_unit(
        recording: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["inspect", str(recording / "csv")]) == 0
    out = capsys.readouterr().out
    assert "ready for identification" in out
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("imu-data.csv"))
    assert "imu/data" in line and "field.header.stamp" in line and " ns " in f"{line} "
    rates = next(ln for ln in out.splitlines() if ln.strip().startswith("/imu/data"))
    assert " 200 " in rates  # 200 Hz IMU, mean rate of the jittered stamps


@pytest.mark.parametrize(("damage", "expected"), [
    ("header_only", "only a header line"),
    ("bad_cell", "line 4, column 'field.angular_velocity.y': 'x' is not a number"),
    ("backwards", "line 3, column 'field.header.stamp'"),
    ("unknown", "no CSV file here is a topic identification reads"),
])
def test_folder_errors_are_one_line_and_exit_2(
        recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], damage: str,
        expected: str) -> None:
    imu = (recording / "csv" / FILE_NAMES["imu/data"]).read_text().splitlines()
    header = imu[0].split(",")
    folder = tmp_path / damage
    folder.mkdir()
    if damage == "header_only":
        imu = imu[:1]
    elif damage == "bad_cell":
        cells = imu[3].split(",")
        cells[header.index("field.angular_velocity.y")] = "x"
        imu[3] = ",".join(cells)
    elif damage == "backwards":
        imu[1], imu[2] = imu[2], imu[1]
    else:
        imu = ["a,b,c", "1,2,3", "2,3,4"]
    (folder / "imu_data.csv").write_text("\n".join(imu) + "\n")
    capsys.readouterr()
    assert main(["identify", str(folder), "--vehicle", "bluerov2_heavy"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0] and "Traceback" not in err[0], err
    assert "imu_data.csv" in err[0] or str(folder) in err[0]


def test_single_csv_in_ms_with_uneven_time_is_resampled(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The seed CSV of a simulation, its rows moved to jittered times (values interpolated
    there) and time written in ms: the unit is named, the duration is right and θ is that
    of the even log within its σ."""
    even = tmp_path / "even.csv"
    assert main(["simulate", "--vehicle", "bluerov2_heavy", "--protocol", "B", "--duration",
                 "120", "--seed", "5", "--out", str(tmp_path / "sim"), "--csv", str(even)]) == 0
    cols = dcsv.read_csv(even, required=("time",))
    t = cols["time"]
    moved = t + 0.3 * (t[1] - t[0]) * np.random.default_rng(3).uniform(-1, 1, len(t))
    moved = np.clip(moved, t[0], t[-1])
    uneven = {k: (np.interp(moved, t, v) if k not in ("time", "segment") else v)
              for k, v in cols.items()}
    uneven["time"] = moved * 1000.0
    del uneven["segment"]
    dcsv.write_csv(tmp_path / "uneven.csv", uneven)
    capsys.readouterr()
    for name in ("even", "uneven"):
        assert main(["identify", str(tmp_path / f"{name}.csv"), "--vehicle", "bluerov2_heavy",
                     "--out", str(tmp_path / f"{name}.yaml")]) == 0
    captured = capsys.readouterr()
    assert "time column 'time' read in milliseconds (detected)" in captured.err
    # seconds, the format's own unit, is not named
    assert not any(ln.startswith("even.csv: time") for ln in captured.err.splitlines())
    assert "resampled by linear interpolation onto a uniform 50 Hz clock" in captured.err
    lines = {name: next(ln for ln in captured.out.splitlines() if f"{name}.csv: " in ln)
             for name in ("even", "uneven")}
    counts = {k: [int(x) for x in re.findall(r": (\d+) samples \((\d+) s", v)[0]]
              for k, v in lines.items()}
    # the same duration: the rate comes from the mean step, not from the first one
    assert counts["uneven"][1] == counts["even"][1] == 116, lines
    assert abs(counts["uneven"][0] - counts["even"][0]) <= 2, lines
    a, b = load_model(tmp_path / "even.yaml"), load_model(tmp_path / "uneven.yaml")
    ratio = np.abs(a.theta - b.theta) / a.theta_std
    # measured: max |Δθ|/σ = 1.17 (sampled at jittered times, interpolated back: twice)
    assert ratio.max() < 3.0, dict(zip(a.parameter_names, ratio.round(2), strict=True))


def test_single_csv_with_quaternion_columns_identifies_as_with_euler_angles(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Attitude as qx, qy, qz, qw (FRD in NED) instead of roll, pitch, yaw: the same θ to
    rounding, and a note saying where the attitude came from; a column that is not a unit
    quaternion is refused by row."""
    from dampest_ros.core.physics.frames import matrix_from_euler, matrix_to_quat

    euler_csv = tmp_path / "euler.csv"
    assert main(["simulate", "--vehicle", "bluerov2_heavy", "--protocol", "B", "--duration",
                 "60", "--seed", "9", "--out", str(tmp_path / "sim"), "--csv",
                 str(euler_csv)]) == 0
    cols = dcsv.read_csv(euler_csv, required=("time",))
    wxyz = matrix_to_quat(matrix_from_euler(np.stack([cols.pop(n) for n in
                                                      ("roll", "pitch", "yaw")], axis=1)))
    cols.update(zip(("qw", "qx", "qy", "qz"), wxyz.T, strict=True))
    dcsv.write_csv(tmp_path / "quat.csv", cols)
    capsys.readouterr()
    models = []
    for name in ("euler", "quat"):
        assert main(["identify", str(tmp_path / f"{name}.csv"), "--vehicle", "bluerov2_heavy",
                     "--out", str(tmp_path / f"{name}.yaml")]) == 0
        models.append(load_model(tmp_path / f"{name}.yaml"))
    assert "attitude from the quaternion columns qx, qy, qz, qw" in capsys.readouterr().err
    np.testing.assert_allclose(models[1].theta, models[0].theta, rtol=1e-9, atol=1e-12)
    cols["qw"] = cols["qw"] * 2.0
    dcsv.write_csv(tmp_path / "bad.csv", cols)
    assert main(["identify", str(tmp_path / "bad.csv"), "--vehicle", "bluerov2_heavy"]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()[-1:]
    assert "qx, qy, qz, qw of row 1 have norm" in line and "not 1" in line, line
