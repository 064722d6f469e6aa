"""CSV in the seed paper's format: exact round trip, column maps, FRD <-> FLU conversion."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dampest_ros.core.signals.samples import Samples
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


# --- .csv.gz and the flavours of logs ---------------------------------


def test_gz_round_trip_is_exact_and_reads_like_csv(tmp_path: Path) -> None:
    cols = columns()
    plain = dcsv.write_csv(tmp_path / "s.csv", cols)
    packed = dcsv.write_csv(tmp_path / "s.csv.gz", cols)
    assert packed.read_bytes()[:2] == b"\x1f\x8b"  # gzip magic
    assert dcsv.is_csv(packed) and dcsv.is_csv(plain) and not dcsv.is_csv(tmp_path / "s.gz")
    a, b = dcsv.read_csv(plain), dcsv.read_csv(packed)
    assert list(a) == list(b)
    for name in a:
        np.testing.assert_array_equal(b[name], cols[name], err_msg=name)
    (tmp_path / "bad.csv.gz").write_bytes(b"not gzip")
    with pytest.raises(ValueError, match=r"bad\.csv\.gz"):
        dcsv.read_csv(tmp_path / "bad.csv.gz")


G = 9.81


def motion(n: int = 2000, rate: float = 100.0) -> dict[str, np.ndarray]:
    """Smooth ν with its exact derivative, attitude and depth (FRD/NED), 20 s at 100 Hz."""
    t = np.arange(n) / rate
    k = np.arange(6)[None, :]
    w = 2 * np.pi * (0.2 + 0.05 * k)  # rad/s per DOF
    amp = np.array([[0.5, 0.3, 0.2, 0.4, 0.3, 0.6]])
    nu = amp * np.sin(w * t[:, None] + k)
    nu_dot = amp * w * np.cos(w * t[:, None] + k)
    out = {"time": t, "depth": 2.0 + 0.1 * np.sin(t)}
    out.update({c: nu[:, i] for i, c in enumerate(dcsv.VELOCITY_COLUMNS)})
    out.update({c: nu_dot[:, i] for i, c in enumerate(dcsv.ACCELERATION_COLUMNS)})
    out.update(roll=0.2 * np.sin(0.3 * t), pitch=0.15 * np.cos(0.2 * t), yaw=0.1 * t)
    return out


def specific_force(m: dict[str, np.ndarray]) -> np.ndarray:
    """f = v̇ + ω × v − g Rᵀe_z (what an IMU at the body origin measures, FRD)."""
    from dampest_ros.core.physics.frames import matrix_from_euler

    nu = np.stack([m[c] for c in dcsv.VELOCITY_COLUMNS], axis=1)
    v_dot = np.stack([m[c] for c in ("ax", "ay", "az")], axis=1)
    down = matrix_from_euler(np.stack([m["roll"], m["pitch"], m["yaw"]], axis=1))[:, 2, :]
    return v_dot + np.cross(nu[:, 3:], nu[:, :3]) - G * down


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_seed_flavour_specific_force_gyro_rates_and_thrusts(sign: float) -> None:
    from dampest_ros.io.yaml_io import load_vehicle

    thr = load_vehicle("bluerov2_heavy").thrusters
    m = motion()
    rng = np.random.default_rng(5)
    f = rng.normal(size=(len(m["time"]), thr.count)) * 10.0  # thrust per thruster, N
    log = {k: v for k, v in m.items() if k not in dcsv.ACCELERATION_COLUMNS}
    a = sign * specific_force(m)  # sign −1: the log's az ≈ +g when level at rest
    log.update(ax=a[:, 0], ay=a[:, 1], az=a[:, 2], wx=m["p"], wy=m["q"], wz=m["r"])
    log.update({f"thrust_{n}": f[:, j] for j, n in enumerate(thr.names)})
    out, notes = dcsv.interpret_columns(log, thr, G)
    for c in ("ax", "ay", "az"):  # u̇, v̇, ẇ recovered exactly
        np.testing.assert_allclose(out[c], m[c], atol=1e-12, err_msg=c)
    for c in ("wx", "wy", "wz"):  # ṗ, q̇, ṙ by central differences: O(h²) ≈ 1e-4 relative
        err = np.max(np.abs(out[c] - m[c])[1:-1]) / np.max(np.abs(m[c]))
        assert err < 3e-4, (c, err)
    tau = f @ thr.allocation.T
    for i, c in enumerate(dcsv.FORCE_COLUMNS):
        np.testing.assert_allclose(out[c], tau[:, i], rtol=1e-12, atol=1e-12, err_msg=c)
    text = "\n".join(notes)
    assert "specific force" in text and "gyro rates" in text and "thrust of 8 thrusters" in text
    assert ("read as −f" in text) == (sign < 0)


def test_rpm_columns_go_through_the_thrust_curve() -> None:
    from dampest_ros.io.yaml_io import load_vehicle

    thr = load_vehicle("bluerov2_heavy").thrusters
    m = motion(200)
    n = np.random.default_rng(2).uniform(-40, 40, size=(200, thr.count))  # rev/s
    log = dict(m)
    log.update({f"rpm_{name}": 60.0 * n[:, j] for j, name in enumerate(thr.names)})
    out, notes = dcsv.interpret_columns(log, thr, G)
    # T = k_T ρ D⁴ n|n| = 0.45 · 1000 · 0.076⁴ n|n| for the BlueROV2 T200 preset
    tau = (0.45 * 1000.0 * 0.076**4 * n * np.abs(n)) @ thr.allocation.T
    np.testing.assert_allclose(np.stack([out[c] for c in dcsv.FORCE_COLUMNS], axis=1), tau,
                               rtol=1e-12, atol=1e-12)
    assert any("rpm" in x and "thrust curve" in x for x in notes)
    del log[f"rpm_{thr.names[2]}"]
    with pytest.raises(ValueError, match=r"thruster3.*--columns.*thrust_thruster3"):
        dcsv.interpret_columns(log, thr, G)


def test_plain_columns_pass_unchanged_and_ambiguity_names_the_map_entry() -> None:
    from dampest_ros.io.yaml_io import load_vehicle

    thr = load_vehicle("bluerov2_heavy").thrusters
    m = motion(500)
    m.update({c: np.full(500, float(i)) for i, c in enumerate(dcsv.FORCE_COLUMNS)})
    out, notes = dcsv.interpret_columns(m, thr, G)
    assert notes == []
    for c in m:
        np.testing.assert_array_equal(out[c], m[c], err_msg=c)
    odd = dict(m, az=np.full(500, 5.0))  # mean |a| ≈ 5 m/s²: neither ν̇ nor specific force
    with pytest.raises(ValueError, match=r"ax, ay, az are ambiguous.*'ax: acc_x'"):
        dcsv.interpret_columns(odd, thr, G)
    out, _ = dcsv.interpret_columns(odd, thr, G, declared={"ax", "ay", "az"})
    np.testing.assert_array_equal(out["az"], 5.0)
    half = dict(m, wx=m["p"] + 0.4 * m["q"], wy=m["q"] + 0.4 * m["r"], wz=m["r"] + 0.4 * m["p"])
    with pytest.raises(ValueError, match=r"wx, wy, wz are ambiguous.*'wx: gyro_x'"):
        dcsv.interpret_columns(half, thr, G)
    out, notes = dcsv.interpret_columns(half, thr, G, declared={"wx", "wy", "wz"})
    assert notes == []  # 'wx: wx' in the map: taken as ṗ, q̇, ṙ, no detection
    np.testing.assert_array_equal(out["wx"], half["wx"])
    gyro = {("gyro_" + c[1] if c in ("wx", "wy", "wz") else c): v for c, v in half.items()}
    out, notes = dcsv.interpret_columns(gyro, thr, G, declared={"gyro_x", "gyro_y", "gyro_z"})
    assert notes == []  # 'wx: gyro_x' in the map: ṗ, q̇, ṙ from the derivative of p, q, r
    err = np.max(np.abs(out["wx"] - m["wx"])[1:-1]) / np.max(np.abs(m["wx"]))
    assert err < 3e-4


def test_rows_with_non_finite_cells_are_dropped_counted_and_split(tmp_path: Path) -> None:
    """One NaN cell made every coefficient 'collinear (variance inflation inf)'.
    read_log drops the rows whose used columns are not finite, counts them per column and
    starts a new segment after each hole (a single row left between two holes goes too);
    columns the log does not read are not looked at."""
    n = 20
    cols = {c: np.ones(n) for c in dcsv.REQUIRED_COLUMNS}
    cols["time"] = np.arange(n) / 50.0
    cols["u"] = np.arange(n, dtype=float)
    cols["notes"] = np.full(n, np.nan)  # not read by read_log
    cols["v"][5] = np.nan
    cols["tau_Z"][[12, 14]] = [np.inf, -np.inf]  # row 13 alone between them
    path = dcsv.write_csv(tmp_path / "holes.csv", cols)
    with pytest.warns(UserWarning, match="level attitude"):
        samples, notes = dcsv.read_log(path, None, 9.81)
    assert notes[0] == ("4 of 20 rows dropped: non-finite values (v 1, tau_Z 2), and 1 "
                        "row(s) left alone between them; the log is split there (3 segments)")
    np.testing.assert_array_equal(samples.nu[:, 0], [0, 1, 2, 3, 4, 6, 7, 8, 9, 10, 11, 15,
                                                     16, 17, 18, 19])
    np.testing.assert_array_equal(samples.segment, [0] * 5 + [1] * 6 + [2] * 5)
    assert samples.rate == 50.0 and np.all(np.isfinite(samples.tau))
    cols["u"][:] = np.nan
    dcsv.write_csv(path, cols)
    with pytest.raises(ValueError, match="20 of 20 rows have a non-finite value"):
        dcsv.read_log(path, None, 9.81)
