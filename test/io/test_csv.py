"""CSV in the seed paper's format: exact round trip, column maps, FRD <-> FLU conversion."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dampest_ros.core.samples import Samples
from dampest_ros.io import csv as dcsv


def columns(n: int = 50, extras: bool = True) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(11)
    cols = {c: rng.normal(size=n) * 10.0 ** rng.integers(-300, 300, n)
            for c in dcsv.REQUIRED_COLUMNS}
    cols["time"] = np.arange(n) / 100.0
    cols["u"][:5] = [0.1, -0.0, np.pi, 1 / 3, 5e-324]
    if extras:
        for name in ("thruster1", "thruster2"):
            cols[f"rpm_{name}"] = rng.normal(size=n) * 1000
            cols[f"thrust_{name}"] = rng.normal(size=n) * 10
        for name in ("roll", "pitch", "yaw"):
            cols[name] = rng.uniform(-np.pi, np.pi, n)
    return cols


def test_round_trip_is_exact(tmp_path: Path) -> None:
    cols = columns()
    shuffled = dict(reversed(list(cols.items())))  # required columns are written first anyway
    path = dcsv.write_csv(tmp_path / "run.csv", shuffled)
    header = path.read_text().splitlines()[0]
    assert header.startswith("time,u,v,w,p,q,r,ax,ay,az,wx,wy,wz,depth,"
                             "tau_X,tau_Y,tau_Z,tau_K,tau_M,tau_N,")
    out = dcsv.read_csv(path)
    assert list(out)[:20] == list(dcsv.REQUIRED_COLUMNS)
    assert set(out) == set(cols)
    for name, values in cols.items():
        np.testing.assert_array_equal(out[name], values, err_msg=name, strict=True)
    assert np.signbit(out["u"][1])  # -0.0 survives


def test_missing_required_columns_are_named(tmp_path: Path) -> None:
    cols = columns(extras=False)
    del cols["depth"], cols["tau_N"]
    with pytest.raises(ValueError, match=r"missing required columns \['depth', 'tau_N'\]"):
        dcsv.write_csv(tmp_path / "a.csv", cols)
    path = tmp_path / "b.csv"
    path.write_text(",".join(cols) + "\n" + ",".join(["1"] * len(cols)) + "\n")
    with pytest.raises(ValueError, match=r"b\.csv: missing required columns \['depth', 'tau_N'\]"):
        dcsv.read_csv(path)


@pytest.mark.parametrize("nested", [True, False])
def test_column_map_renames_user_columns(tmp_path: Path, nested: bool) -> None:
    cols = columns(5, extras=False)
    theirs = {"time": "t [s]", "u": "vel_x", "tau_X": "Fx", "depth": "z"}
    path = tmp_path / "user.csv"
    names = [theirs.get(c, c) for c in cols]
    path.write_text(",".join(f'"{n}"' for n in names) + "\n" + "\n".join(
        ",".join(repr(float(cols[c][i])) for c in cols) for i in range(5)) + "\n")
    with pytest.raises(ValueError, match=r"missing required columns \['time', 'u', 'depth'"):
        dcsv.read_csv(path)
    entries = [f"'{v}': {k}\n" for k, v in theirs.items()]
    map_file = tmp_path / "map.yaml"
    map_file.write_text("columns:\n" + "".join("  " + e for e in entries) if nested
                        else "".join(entries))
    column_map = dcsv.load_column_map(map_file)
    assert column_map == {v: k for k, v in theirs.items()}
    out = dcsv.read_csv(path, column_map)
    for name, values in cols.items():
        np.testing.assert_array_equal(out[name], values, err_msg=name)


def test_bad_column_map_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "map.yaml"
    path.write_text("a: u\nb: u\n")
    with pytest.raises(ValueError, match=r"several columns map to \['u'\]"):
        dcsv.load_column_map(path)
    path.write_text("- a\n- b\n")
    with pytest.raises(ValueError, match="mapping of column name"):
        dcsv.load_column_map(path)


def test_header_only_and_bad_rows(tmp_path: Path) -> None:
    path = tmp_path / "empty.csv"
    path.write_text(",".join(dcsv.REQUIRED_COLUMNS) + "\n")
    out = dcsv.read_csv(path)
    assert all(v.shape == (0,) for v in out.values()) and len(out) == 20
    path.write_text(",".join(dcsv.REQUIRED_COLUMNS) + "\n" + ",".join(["1"] * 19) + ",x\n")
    with pytest.raises(ValueError, match=r"empty\.csv"):
        dcsv.read_csv(path)


def test_samples_round_trip_through_a_file_exactly(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    n = 50
    t = np.r_[np.arange(25) * 0.02, 10.0 + np.arange(25) * 0.02]
    samples = Samples(t, rng.normal(size=(n, 6)), rng.normal(size=(n, 6)),
                      rng.normal(size=(n, 6)) * 30, rng.normal(size=(n, 3)),
                      rng.uniform(0, 10, n), np.r_[np.zeros(25), np.ones(25)].astype(np.int64))
    path = dcsv.write_csv(tmp_path / "s.csv", dcsv.samples_to_columns(samples))
    back = dcsv.samples_from_columns(dcsv.read_csv(path))
    for name in ("t", "nu", "nu_dot", "tau", "euler", "depth", "segment"):
        np.testing.assert_array_equal(getattr(back, name), getattr(samples, name), err_msg=name)


def test_samples_without_attitude_or_segments_are_level_and_split_at_gaps() -> None:
    cols = columns(8, extras=False)
    cols["time"] = np.r_[np.arange(4) * 0.1, 5.0 + np.arange(4) * 0.1]
    with pytest.warns(UserWarning, match="level attitude"):
        s = dcsv.samples_from_columns(cols)
    np.testing.assert_array_equal(s.segment, [0, 0, 0, 0, 1, 1, 1, 1])
    np.testing.assert_array_equal(s.euler, np.zeros((8, 3)))
    cols["time"] = cols["time"][::-1].copy()
    with pytest.raises(ValueError, match="increase"):
        dcsv.samples_from_columns(cols)
