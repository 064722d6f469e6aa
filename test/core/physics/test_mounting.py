"""Sensor mounting: the vehicle file's sensors: section, the simulator's off-centre
sensors against hand-computed truth, the preprocessing (offline and online) that undoes the
mounting, identification with a 0.3 m DVL offset and a rotated IMU equal to the centred case
within σ (and not without the correction), frame_id checks, and a DVL on TwistStamped."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from dampest_ros.core.identification.batch import Fit, FitOptions, fit
from dampest_ros.core.online.preprocessor import OnlinePreprocessor
from dampest_ros.core.online.sample import OnlineSample, to_samples
from dampest_ros.core.physics.frames import matrix_from_euler, matrix_to_quat
from dampest_ros.core.physics.mounting import Mounting, SensorMount
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.measurements import ImuSeries, PressureSeries, Recording, TwistSeries
from dampest_ros.core.signals.preprocess import preprocess
from dampest_ros.core.simulation.excitation import make_excitation
from dampest_ros.core.simulation.sensors import SensorConfig, measure
from dampest_ros.core.simulation.simulate import run
from dampest_ros.core.simulation.trajectory import Trajectory
from dampest_ros.io.yaml_io import load_vehicle, vehicle_path

G, RHO, ATM = 9.81, 1000.0, 101325.0
EXACT = SensorConfig(gyro_noise=0.0, gyro_bias_walk=0.0, accel_noise=0.0, accel_bias_walk=0.0,
                     orientation_noise=0.0, dvl_noise=0.0, dvl_dropout_rate=0.0,
                     pressure_noise=0.0, rpm_noise=0.0)
#: DVL 0.3 m forward and 0.15 m below the origin; the IMU off-centre, yawed 90° and pitched;
#: the pressure sensor beside the DVL.
MOUNTED = Mounting.from_dict({
    "dvl": {"position": [0.3, 0.0, 0.15]},
    "imu": {"position": [0.1, -0.05, 0.05], "rpy": [0.0, 0.2, np.pi / 2]},
    "pressure": {"position": [0.3, 0.0, 0.15]},
})
#: Only the DVL's lever arm: what ω × r alone does.
LEVER = Mounting.from_dict({"dvl": {"position": [0.3, 0.0, 0.15]}})


@pytest.fixture(scope="module")
def vehicle() -> Vehicle:
    return load_vehicle("bluerov2_heavy")


@pytest.fixture(scope="module")
def flight(heavy_b60: tuple[Trajectory, Recording]) -> Trajectory:
    """60 s of protocol B on the native BlueROV2 Heavy, seed 3 (the session's
    :func:`heavy_b60`)."""
    return heavy_b60[0]


def spinning(duration: float = 2.0, dt: float = 0.01, yaw_rate: float = 0.5,
             pitch: float = 0.0, depth: float = 4.0) -> Trajectory:
    """Ground truth of a vehicle turning in place at a constant yaw rate ψ̇, pitched."""
    t = np.arange(round(duration / dt) + 1, dtype=float) * dt
    n = len(t)
    euler = np.column_stack([np.zeros(n), np.full(n, pitch), yaw_rate * t])
    # body rates of ψ̇ at constant θ, φ = 0: p = −sin θ ψ̇, q = 0, r = cos θ ψ̇
    nu = np.tile([0.0, 0.0, 0.0, -np.sin(pitch) * yaw_rate, 0.0, np.cos(pitch) * yaw_rate],
                 (n, 1))
    return Trajectory(t=t, position=np.tile([1.0, 2.0, depth], (n, 1)),
                      quaternion=matrix_to_quat(matrix_from_euler(euler)), nu=nu,
                      nu_dot=np.zeros((n, 6)), tau=np.zeros((n, 6)), rotor_speed=np.zeros((n, 0)),
                      thrust=np.zeros((n, 0)), current=np.zeros((n, 3)), memory=np.zeros((n, 0)),
                      thruster_names=())


# --- the sensors: section ---------------------------------------------------------------------


def write_vehicle(tmp_path: Path, sensors: object) -> Path:
    doc = yaml.safe_load(vehicle_path("bluerov2_heavy").read_text())
    doc["sensors"] = sensors
    path = tmp_path / "mounted.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_sensors_section_is_read_with_defaults(tmp_path: Path) -> None:
    preset = load_vehicle("bluerov2_heavy")
    assert preset.mounting == Mounting()
    # the preset's commented sensors: block, uncommented, is the defaults
    text = vehicle_path("bluerov2_heavy").read_text()
    block = text[text.index("# sensors:"):]
    uncommented = text.replace(block, "\n".join(line[2:] for line in block.splitlines()))
    (tmp_path / "uncommented.yaml").write_text(uncommented)
    assert yaml.safe_load(uncommented)["sensors"]["dvl"]["frame_id"] == "dvl_link"
    assert load_vehicle(tmp_path / "uncommented.yaml").mounting == Mounting()
    assert (preset.mounting.imu.frame_id, preset.mounting.dvl.frame_id,
            preset.mounting.pressure.frame_id) == ("imu_link", "dvl_link", "pressure_link")
    v = load_vehicle(write_vehicle(tmp_path, {
        "dvl": {"frame_id": "dvl", "position": [0.3, 0, 0.15], "rpy": [0, 0, 0.5]},
        "pressure": {"position": [-0.1, 0.0, 0.0]}}))
    assert v.mounting.dvl == SensorMount("dvl", (0.3, 0.0, 0.15), (0.0, 0.0, 0.5))
    assert v.mounting.imu == SensorMount("imu_link")
    assert v.mounting.pressure.position == (-0.1, 0.0, 0.0)
    assert "sensors" not in v.extra
    np.testing.assert_allclose(v.mounting.dvl.rotation @ [1.0, 0.0, 0.0],
                               [np.cos(0.5), np.sin(0.5), 0.0])


@pytest.mark.parametrize(("sensors", "field"), [
    ({"dvl": {"position": [0.3, 0.0]}}, "sensors.dvl.position"),
    ({"imu": {"rpy": [0.0, ".nan", 0.0]}}, "sensors.imu.rpy"),
    ({"imu": {"position": [0.0, float("inf"), 0.0]}}, "sensors.imu.position"),
    ({"dvl": {"frame_id": ""}}, "sensors.dvl.frame_id"),
    ({"pressure": {"rpy": [0, 0, 0]}}, "sensors.pressure.rpy"),
    ({"sonar": {}}, "sensors.sonar"),
    ([1, 2], "sensors"),
])
def test_bad_sensors_section_names_the_field_and_the_file(tmp_path: Path, sensors: object,
                                                          field: str) -> None:
    path = write_vehicle(tmp_path, sensors)
    with pytest.raises(ConfigError) as err:
        load_vehicle(path)
    assert err.value.field == field and str(path) in str(err.value)


# --- the simulator's off-centre sensors against hand-computed truth ------------------------------


def test_off_centre_sensors_measure_their_own_point_and_axes() -> None:
    """A vehicle turning in place at r = 0.5 rad/s: the DVL 0.3 m ahead sees ω × r, the IMU
    0.3 m ahead the centripetal −ω² r in its own (yawed 90°) axes, the pressure sensor 0.15 m
    below the origin reads 0.15 m deeper; on a pitched vehicle its depth follows R r."""
    mount = Mounting.from_dict({
        "dvl": {"position": [0.3, 0.0, 0.15]},
        "imu": {"position": [0.3, 0.0, 0.0], "rpy": [0.0, 0.0, np.pi / 2]},
        "pressure": {"position": [0.0, 0.0, 0.15]}})
    rec = measure(spinning(), RHO, G, EXACT, mounting=mount)
    dvl, imu, pres = rec["dvl/twist"], rec["imu/data"], rec["pressure"]
    assert isinstance(dvl, TwistSeries) and isinstance(imu, ImuSeries)
    assert isinstance(pres, PressureSeries)
    # DVL, FRD: ω × r = [0, 0, 0.5] × [0.3, 0, 0.15] = [0, 0.15, 0]; FLU [0, −0.15, 0]
    np.testing.assert_allclose(dvl.linear, np.tile([0.0, -0.15, 0.0], (17, 1)), atol=1e-12)
    # specific force of the point, body FRD: −ω² r − Rᵀ g = [−0.075, 0, −g]; in the IMU's axes
    # (x_s = y_b, y_s = −x_b): [0, 0.075, −g]; FLU [0, −0.075, g]
    np.testing.assert_allclose(imu.linear_acceleration, np.tile([0.0, -0.075, G], (401, 1)),
                               atol=1e-9)
    np.testing.assert_allclose(imu.angular_velocity, np.tile([0.0, 0.0, -0.5], (401, 1)),
                               atol=1e-12)
    assert dvl.frame_id == "dvl_link" and imu.frame_id == "imu_link"
    np.testing.assert_allclose(pres.fluid_pressure, ATM + RHO * G * 4.15, rtol=1e-12)
    # pitched 0.3 rad, pressure sensor 0.3 m ahead: (R r)_z = −0.3 sin θ
    ahead = Mounting.from_dict({"pressure": {"position": [0.3, 0.0, 0.0]}})
    p = measure(spinning(yaw_rate=0.0, pitch=0.3), RHO, G, EXACT, mounting=ahead)["pressure"]
    assert isinstance(p, PressureSeries)
    np.testing.assert_allclose(p.fluid_pressure, ATM + RHO * G * (4.0 - 0.3 * np.sin(0.3)),
                               rtol=1e-12)


def test_streaming_simulator_mounts_sensors_like_measure(vehicle: Vehicle) -> None:
    """The sim node's SensorStream (via LiveSimulation, from the vehicle's sensors:) gives the
    messages measure() gives for the same mounting."""
    from dampest_ros.core.simulation.stream import SensorStream

    traj = run(vehicle, make_excitation("B", vehicle, 10.0, seed=1))
    want = measure(traj, RHO, G, EXACT, mounting=MOUNTED)
    got = SensorStream(RHO, G, EXACT, mounting=MOUNTED).add(traj)
    for topic in ("imu/data", "dvl/twist", "pressure"):
        assert got[topic].frame_id == want[topic].frame_id
        for name, a in want[topic].per_message().items():
            np.testing.assert_allclose(getattr(got[topic], name), a, rtol=1e-12, atol=1e-12,
                                       err_msg=f"{topic} {name}")


# --- preprocessing and identification ------------------------------------------------------------


def test_offline_preprocessing_removes_the_mounting(vehicle: Vehicle, flight: Trajectory) -> None:
    """Noise-free sensors: with the mounting, ν, ν̇ and depth equal those of centred
    sensors to a fraction of their spread; without it, the DVL lever arm alone is wrong by
    ω × r (≈ 0.1 m/s RMS on this flight)."""
    g, rho = vehicle.body.gravity, vehicle.body.rho
    centred = preprocess(measure(flight, rho, g, EXACT), vehicle)
    mounted = preprocess(measure(flight, rho, g, EXACT, mounting=MOUNTED),
                         replace(vehicle, mounting=MOUNTED))
    np.testing.assert_array_equal(mounted.t, centred.t)
    spread = np.std(centred.nu, axis=0)
    assert np.all(np.sqrt(np.mean((mounted.nu - centred.nu) ** 2, axis=0)) < 0.01 * spread)
    spread_dot = np.std(centred.nu_dot, axis=0)
    err_dot = np.sqrt(np.mean((mounted.nu_dot - centred.nu_dot) ** 2, axis=0))
    assert np.all(err_dot < 0.05 * spread_dot), err_dot / spread_dot
    assert np.max(np.abs(mounted.depth - centred.depth)) < 2e-3  # m
    lever = preprocess(measure(flight, rho, g, EXACT, mounting=LEVER), vehicle)
    assert np.sqrt(np.mean((lever.nu[:, 1] - centred.nu[:, 1]) ** 2)) > 0.05  # m/s


def far(a: Fit, b: Fit) -> np.ndarray:
    """|θ_a − θ_b| in units of their combined σ, per coefficient."""
    return np.asarray(np.abs(a.theta - b.theta)
                      / np.sqrt(np.diag(a.cov) + np.diag(b.cov)), dtype=float)


def test_identification_with_mounted_sensors_equals_the_centred_case(
        vehicle: Vehicle, flight: Trajectory) -> None:
    """Realistic noise, 60 s of protocol B: a 0.3 m DVL offset and a rotated, off-centre IMU,
    corrected, give θ within σ of centred sensors (combined σ of the two fits); the DVL offset
    left out of the preprocessing moves θ by many σ of the centred fit."""
    g, rho = vehicle.body.gravity, vehicle.body.rho

    def identify(rec_mount: Mounting | None, pre_mount: Mounting | None) -> Fit:
        rec = measure(flight, rho, g, seed=3, mounting=rec_mount)
        s = preprocess(rec, replace(vehicle, mounting=pre_mount or Mounting()))
        return fit(s, vehicle.damping, vehicle.body, FitOptions())

    centred = identify(None, None)
    assert np.all(np.abs(centred.theta - vehicle.theta) < 4 * np.sqrt(np.diag(centred.cov))
                  + 0.01 * np.abs(vehicle.theta))
    assert np.all(far(identify(MOUNTED, MOUNTED), centred) < 1.0)
    wrong = identify(LEVER, None)
    assert np.max(np.abs(wrong.theta - centred.theta) / np.sqrt(np.diag(centred.cov))) > 20.0


def test_online_preprocessing_removes_the_mounting(
        vehicle: Vehicle, flight: Trajectory,
        heavy_b60_online: tuple[OnlinePreprocessor, list[OnlineSample]]) -> None:
    """The online path (the preprocess node's code): mounted and corrected, θ within σ of
    centred sensors (the session's centred run of the same flight and seed); uncorrected,
    the DVL disagrees with the inertial velocity and is gated out, so hardly a sample is
    usable."""
    g, rho = vehicle.body.gravity, vehicle.body.rho

    def online(rec_mount: Mounting, pre_mount: Mounting | None, until: float = np.inf
               ) -> tuple[OnlinePreprocessor, list]:
        pre = OnlinePreprocessor(vehicle.thrusters, g, rho, mounting=pre_mount)
        rec = measure(flight, rho, g, seed=3, mounting=rec_mount)
        return pre, pre.run({k: s.select(np.flatnonzero(s.stamp < until))
                             for k, s in rec.items()})

    c = heavy_b60_online[1]
    _, m = online(MOUNTED, MOUNTED)
    fc, fm = (fit(to_samples(x, 50.0), vehicle.damping, vehicle.body, FitOptions())
              for x in (c, m))
    assert np.all(far(fm, fc) < 1.0), far(fm, fc)
    usable = sum(s.usable for s in c)
    assert usable > 2000 and sum(s.usable for s in m) > 0.95 * usable
    pre, u = online(LEVER, None, until=20.0)  # a third of the flight shows it
    assert sum(s.usable for s in u) < 0.1 * usable / 3 and pre.counts["dvl_outliers"] > 50


# --- frame_id ------------------------------------------------------------------------------------


def short(vehicle: Vehicle) -> Recording:
    traj = run(vehicle, make_excitation("B", vehicle, 20.0, seed=5))
    return measure(traj, vehicle.body.rho, vehicle.body.gravity, seed=5)


def test_foreign_frame_ids_are_counted_and_reported_once(vehicle: Vehicle) -> None:
    """Against the frame_ids a vehicle file declares; without a sensors: section any frame_id
    is taken silently (the usual log stamps every sensor base_link)."""
    g, rho = vehicle.body.gravity, vehicle.body.rho
    rec = short(vehicle)
    rec["dvl/twist"] = replace(rec["dvl/twist"], frame_id="dvl")
    rec["imu/data"] = replace(rec["imu/data"], frame_id="base_link")
    quiet: list[str] = []
    report: dict[str, float] = {}
    preprocess(rec, vehicle, report=report, notes=quiet)
    assert quiet == [] and not any(k.startswith("frame_id") for k in report)
    pre = OnlinePreprocessor(vehicle.thrusters, g, rho)
    pre.run(rec)
    assert pre.counts["frame_id_mismatch"] == 0
    vehicle = replace(vehicle, mounting=Mounting.from_dict(
        {k: {"frame_id": f"{k}_link"} for k in ("imu", "dvl", "pressure")}))
    rec["imu/data"] = replace(rec["imu/data"], frame_id="imu_link")
    notes: list[str] = []
    same = preprocess(rec, vehicle, report=report, notes=notes)
    n_dvl = len(rec["dvl/twist"])
    assert notes == [f"dvl/twist: {n_dvl} message(s) with header.frame_id 'dvl', expected "
                     "'dvl_link' (the sensors: section of the vehicle file); used with the "
                     "configured mounting"]
    assert report["frame_id_mismatch dvl/twist"] == n_dvl
    # counted, not changed: the samples are those of the right frame_id
    rec["dvl/twist"] = replace(rec["dvl/twist"], frame_id="dvl_link")
    np.testing.assert_array_equal(same.nu, preprocess(rec, vehicle).nu)
    # the IMU's, counted once per message the output covers
    rec["imu/data"] = replace(rec["imu/data"], frame_id="imu")
    notes.clear()
    preprocess(rec, vehicle, notes=notes)
    (line,) = notes
    assert line.startswith("imu/data: ") and "'imu', expected 'imu_link'" in line
    # online: a counter, and one event per topic
    pre = OnlinePreprocessor(vehicle.thrusters, g, rho, mounting=vehicle.mounting)
    pre.run(rec)
    assert pre.counts["frame_id_mismatch"] == len(rec["imu/data"])
    assert [e for e in pre.events if "frame_id" in e] == [
        "imu: 1 message(s) with header.frame_id 'imu', expected 'imu_link' (the sensors: "
        "section of the vehicle file); used with the configured mounting (counted as "
        "frame_id_mismatch, reported once)"]


# --- a DVL on geometry_msgs/TwistStamped --------------------------------------------------------


def write_twist_stamped_bag(path: Path, rec: Recording) -> Path:
    """A bag like write_bag's, but the DVL topic as geometry_msgs/msg/TwistStamped, serialized
    by rosbags' own serializer (not the codec under test)."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    from dampest_ros.io import cdr

    store = cdr.typestore()
    Twist, Stamped = store.types["geometry_msgs/msg/Twist"], \
        store.types["geometry_msgs/msg/TwistStamped"]
    Header, Time = store.types["std_msgs/msg/Header"], store.types["builtin_interfaces/msg/Time"]
    Vector3 = store.types["geometry_msgs/msg/Vector3"]
    dvl = rec["dvl/twist"]
    assert isinstance(dvl, TwistSeries)
    sec, nsec = cdr.stamps_to_ros(dvl.stamp)
    twist_msgs = [bytes(store.serialize_cdr(Stamped(
        header=Header(stamp=Time(sec=int(s), nanosec=int(ns)), frame_id=dvl.frame_id),
        twist=Twist(linear=Vector3(*map(float, lin)), angular=Vector3(*map(float, ang)))),
        "geometry_msgs/msg/TwistStamped"))
        for s, ns, lin, ang in zip(sec, nsec, dvl.linear, dvl.angular, strict=True)]
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    rows = []
    for k, (topic, series) in enumerate(rec.items()):
        msgtype = "geometry_msgs/msg/TwistStamped" if topic == "dvl/twist" \
            else cdr.message_type(series)
        conn = writer.add_connection("/" + topic, msgtype, typestore=store)
        msgs = twist_msgs if topic == "dvl/twist" else cdr.encode(series)
        rows += [(int(t), k, conn, m) for t, m in zip(cdr.stamps_to_ns(series.stamp), msgs,
                                                       strict=True)]
    for t, _, conn, m in sorted(rows, key=lambda r: (r[0], r[1])):
        writer.write(conn, t, m)
    writer.close()
    return path


def test_dvl_as_twist_stamped_reads_and_preprocesses_like_twist_with_covariance(
        vehicle: Vehicle, tmp_path: Path) -> None:
    from dampest_ros.io.bag import bag_summary, read_bag, role_type_errors

    g, rho = vehicle.body.gravity, vehicle.body.rho
    rec = {k: s for k, s in short(vehicle).items() if k != "truth/odom"}
    bag = write_twist_stamped_bag(tmp_path / "twist_stamped", rec)
    summary = bag_summary(bag)
    assert summary.topics["/dvl/twist"].msgtype == "geometry_msgs/msg/TwistStamped"
    assert role_type_errors(summary, {"imu": "imu/data", "dvl": "dvl/twist",
                                      "thrusters": "thrusters/state"}) == []
    back = read_bag(bag)
    dvl = back["dvl/twist"]
    assert isinstance(dvl, TwistSeries) and dvl.frame_id == "dvl_link"
    np.testing.assert_array_equal(dvl.stamp, rec["dvl/twist"].stamp)
    np.testing.assert_array_equal(dvl.linear, rec["dvl/twist"].linear)  # type: ignore[attr-defined]
    want = preprocess(rec, vehicle)
    got = preprocess(back, vehicle)
    np.testing.assert_array_equal(got.nu, want.nu)
    # online: no covariance in a TwistStamped, so the configured DVL noise weighs it
    samples = OnlinePreprocessor(vehicle.thrusters, g, rho).run(back)
    assert sum(s.usable for s in samples) > 500
