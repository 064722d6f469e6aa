"""An arm's CSV joint log: columns by joint name in any order, time in any unit, velocity
optional (all joints or none), bad cells named by line and column."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dampest_ros.io.arm_csv import read_joint_csv
from dampest_ros.io.csv import write_table
from dampest_ros.io.csv_table import CsvError

JOINTS = ("j1", "j2")


def log(path: Path, drop: str = "", **change: np.ndarray) -> Path:
    """A two-joint log in ms, columns in reverse joint order, seeded values."""
    rng = np.random.default_rng(5)
    cols: dict[str, np.ndarray] = {"time": np.arange(20) * 2.0}
    for j in reversed(JOINTS):
        for prefix in ("q", "qd", "tau"):
            cols[f"{j}.{prefix}"] = rng.normal(size=20)
    cols.update(change)
    cols.pop(drop, None)
    return write_table(path, cols)


def test_columns_by_name_in_any_order_and_time_in_ms(tmp_path: Path) -> None:
    path = log(tmp_path / "a.csv")
    d = read_joint_csv(path, JOINTS)
    header = path.read_text().splitlines()[0].split(",")
    cols = dict(zip(header, np.loadtxt(path, delimiter=",", skiprows=1).T, strict=True))
    np.testing.assert_array_equal(d.t, np.arange(20) * 0.002)
    for k, j in enumerate(JOINTS):
        np.testing.assert_array_equal(d.position[:, k], cols[f"{j}.q"])
        np.testing.assert_array_equal(d.velocity[:, k], cols[f"{j}.qd"])
        np.testing.assert_array_equal(d.effort[:, k], cols[f"{j}.tau"])
    assert d.topic == str(path)


def test_velocity_is_for_all_joints_or_none(tmp_path: Path) -> None:
    no_qd = tmp_path / "b.csv"
    write_table(no_qd, {"time": np.arange(5) * 0.01, "j1.q": np.ones(5), "j2.q": np.ones(5),
                        "j1.tau": np.ones(5), "j2.tau": np.ones(5)})
    assert np.all(np.isnan(read_joint_csv(no_qd, JOINTS).velocity))
    with pytest.raises(CsvError, match=r"no column 'j1\.qd' \(joint j1's velocity in rad/s\)"):
        read_joint_csv(log(tmp_path / "c.csv", drop="j1.qd"), JOINTS)


def test_an_empty_cell_is_named_by_line_and_column(tmp_path: Path) -> None:
    tau = np.ones(20)
    tau[6] = np.nan
    with pytest.raises(CsvError, match=r"c\.csv: line 8, column 'j2\.tau': not a number"):
        read_joint_csv(log(tmp_path / "c.csv", **{"j2.tau": tau}), JOINTS)
