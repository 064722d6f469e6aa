"""Logs without a raw IMU/DVL pair (dampest_ros.core.signals.sources through dampest
identify): a navigation state's Odometry alone, an IMU without accelerometer or without gyro,
a DVL value held between updates. Each bag is written with rosbags' own writer and
serialiser from one seeded flight of the native and of the MuJoCo simulator, and must give
the θ of the clean IMU+DVL bag of the same flight within its σ."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from dampest_ros.cli.main import main
from dampest_ros.core.physics import frames
from dampest_ros.core.signals.measurements import (
    ImuSeries,
    JointSeries,
    OdometrySeries,
    PressureSeries,
    Series,
    TwistSeries,
)
from dampest_ros.core.simulation.excitation import make_excitation
from dampest_ros.core.simulation.sensors import SensorConfig, measure
from dampest_ros.core.simulation.simulate import run
from dampest_ros.io.cdr import stamps_to_ros, typestore
from dampest_ros.io.yaml_io import load_model, load_vehicle

#: (backend, vehicle preset) of the flights
FLIGHTS = [("native", "bluerov2_heavy"), ("mujoco", "bluerov2_heavy_mujoco")]
DURATION = 150.0
#: navigation-state noise: velocity (m/s) and attitude (rad) per message
ODOM_VELOCITY_NOISE, ODOM_ATTITUDE_NOISE = 0.005, 0.002


def _header(ts: Any, t: float, frame_id: str) -> Any:
    sec, nsec = stamps_to_ros(np.array([t]))
    return ts.types["std_msgs/msg/Header"](
        ts.types["builtin_interfaces/msg/Time"](int(sec[0]), int(nsec[0])), frame_id)


def _vec(ts: Any, v: np.ndarray) -> Any:
    return ts.types["geometry_msgs/msg/Vector3"](*map(float, v))


def _quat(ts: Any, q: np.ndarray) -> Any:
    return ts.types["geometry_msgs/msg/Quaternion"](*map(float, q))


def _messages(ts: Any, s: Series) -> list[Any]:
    """rosbags message objects of a series, built field by field (independent of our CDR)."""
    T = ts.types
    if isinstance(s, ImuSeries):
        cov = np.zeros(9)
        return [T["sensor_msgs/msg/Imu"](_header(ts, t, s.frame_id), _quat(ts, q), cov,
                                         _vec(ts, w), cov, _vec(ts, a), cov)
                for t, q, w, a in zip(s.stamp, s.orientation, s.angular_velocity,
                                      s.linear_acceleration, strict=True)]
    if isinstance(s, TwistSeries):
        return [T["geometry_msgs/msg/TwistWithCovarianceStamped"](
            _header(ts, t, s.frame_id), T["geometry_msgs/msg/TwistWithCovariance"](
                T["geometry_msgs/msg/Twist"](_vec(ts, v), _vec(ts, w)), s.covariance))
            for t, v, w in zip(s.stamp, s.linear, s.angular, strict=True)]
    if isinstance(s, OdometrySeries):
        cov = np.zeros(36)
        return [T["nav_msgs/msg/Odometry"](
            _header(ts, t, s.frame_id), s.child_frame_id, T["geometry_msgs/msg/PoseWithCovariance"](
                T["geometry_msgs/msg/Pose"](T["geometry_msgs/msg/Point"](*map(float, p)),
                                            _quat(ts, q)), cov),
            T["geometry_msgs/msg/TwistWithCovariance"](
                T["geometry_msgs/msg/Twist"](_vec(ts, v), _vec(ts, w)), cov))
            for t, p, q, v, w in zip(s.stamp, s.position, s.orientation, s.linear, s.angular,
                                     strict=True)]
    if isinstance(s, PressureSeries):
        return [T["sensor_msgs/msg/FluidPressure"](_header(ts, t, s.frame_id), float(p),
                                                   s.variance)
                for t, p in zip(s.stamp, s.fluid_pressure, strict=True)]
    assert isinstance(s, JointSeries)
    return [T["sensor_msgs/msg/JointState"](_header(ts, t, s.frame_id), list(s.names),
                                            np.zeros(0), v, e)
            for t, v, e in zip(s.stamp, s.velocity, s.effort, strict=True)]


def write_with_rosbags(path: Path, rec: dict[str, Series],
                       serialized: dict[int, list[bytes]] | None = None) -> Path:
    """An MCAP rosbag2 bag of ``rec`` by rosbags' Writer and serialize_cdr. ``serialized``:
    the messages of each series serialised so far, by ``id(series)``, for the bags of one
    flight that share series (which must stay alive while it is used)."""
    cache: dict[int, list[bytes]] = {} if serialized is None else serialized
    ts = typestore()
    names = {ImuSeries: "sensor_msgs/msg/Imu", OdometrySeries: "nav_msgs/msg/Odometry",
             TwistSeries: "geometry_msgs/msg/TwistWithCovarianceStamped",
             PressureSeries: "sensor_msgs/msg/FluidPressure",
             JointSeries: "sensor_msgs/msg/JointState"}
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        for topic, s in rec.items():
            msgtype = names[type(s)]
            conn = w.add_connection(f"/{topic}", msgtype, typestore=ts)
            if id(s) not in cache:
                cache[id(s)] = [bytes(ts.serialize_cdr(m, msgtype)) for m in _messages(ts, s)]
            for t, data in zip(s.stamp, cache[id(s)], strict=True):
                w.write(conn, round(t * 1e9), data)
    return path


def navigation_state(odom: OdometrySeries, seed: int) -> OdometrySeries:
    """A state estimator's Odometry: the truth with velocity and attitude noise, the angular
    rate left empty (zero)."""
    rng = np.random.default_rng(seed)
    n = len(odom)
    q = frames.quat_mul(odom.orientation[:, [3, 0, 1, 2]],
                        frames.small_rotation(ODOM_ATTITUDE_NOISE * rng.standard_normal((n, 3))))
    return replace(odom, frame_id="odom", orientation=frames.wxyz_to_xyzw(q),
                   linear=odom.linear + ODOM_VELOCITY_NOISE * rng.standard_normal((n, 3)),
                   angular=np.zeros((n, 3)))


def held(dvl: TwistSeries, rate: float) -> TwistSeries:
    """The DVL republished at ``rate`` Hz: each message repeats the last DVL value."""
    t = np.arange(dvl.stamp[0], dvl.stamp[-1], 1.0 / rate)
    last = np.searchsorted(dvl.stamp, t + 1e-9, side="right") - 1
    return replace(dvl, stamp=t, linear=dvl.linear[last], angular=dvl.angular[last])


@dataclass
class Flight:
    """One flight's bags (by case) and the clean bag's fit."""

    root: Path
    vehicle: str
    backend: str
    bags: dict[str, Path]
    theta: np.ndarray
    std: np.ndarray


def _cases(rec: dict[str, Series], rec6: dict[str, Series], seed: int
           ) -> dict[str, dict[str, Series]]:
    imu, thr = rec["imu/data"], rec["thrusters/state"]
    assert isinstance(imu, ImuSeries) and isinstance(rec["truth/odom"], OdometrySeries)
    dvl6 = rec6["dvl/twist"]
    assert isinstance(dvl6, TwistSeries)
    sensors = {k: rec[k] for k in ("imu/data", "dvl/twist", "pressure", "thrusters/state")}
    return {
        "clean": sensors,
        "odometry": {"nav/odom": navigation_state(rec["truth/odom"], seed),
                     "thrusters/state": thr},
        "no_accelerometer": {**sensors, "imu/data": replace(
            imu, linear_acceleration=np.zeros_like(imu.linear_acceleration))},
        "no_gyro": {**sensors, "imu/data": replace(
            imu, angular_velocity=np.zeros_like(imu.angular_velocity))},
        "held_dvl": {**sensors, "dvl/twist": held(dvl6, 50.0)},
    }


@pytest.fixture(scope="module", params=FLIGHTS, ids=[b for b, _ in FLIGHTS])
def flight(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Flight:
    backend, name = request.param
    root = tmp_path_factory.mktemp(backend)
    vehicle = load_vehicle(name)
    seed = 11
    traj = run(vehicle, make_excitation("B", vehicle, DURATION, seed=seed), backend=backend)
    rec = measure(traj, vehicle.body.rho, vehicle.body.gravity, seed=seed)
    rec6 = measure(traj, vehicle.body.rho, vehicle.body.gravity, SensorConfig(dvl_rate=6.0),
                   seed=seed)
    cases, serialized = _cases(rec, rec6, seed), {}  # the series the bags share: once
    bags = {case: write_with_rosbags(root / case, r, serialized) for case, r in cases.items()}
    # the preset's terms alone (--no-select) in every case: the same parameters to compare,
    # where the default would add MuJoCo's terms chosen by each log's own selection
    assert main(["identify", str(bags["clean"]), "--vehicle", name, "--no-select",
                 "--out", str(root / "clean.yaml")]) == 0
    clean = load_model(root / "clean.yaml")
    return Flight(root, name, backend, bags, clean.theta, clean.theta_std)


#: case → its topic options and the substitution lines it must print
CASES: dict[str, tuple[list[str], list[str]]] = {
    "odometry": (["--imu-topic", "/nav/odom", "--dvl-topic", "/nav/odom"],
                 ["no accelerometer in nav/odom (Odometry has none): u̇, v̇, ẇ from the "
                  "zero-phase derivative of the Odometry velocity in nav/odom",
                  "no gyro in nav/odom (twist.twist.angular all zero): p, q, r from the "
                  "zero-phase derivative of the Odometry attitude"]),
    "no_accelerometer": ([], ["no accelerometer in imu/data (linear_acceleration all zero): "
                              "u̇, v̇, ẇ from the zero-phase derivative of the DVL velocity"]),
    "no_gyro": ([], ["no gyro in imu/data (angular_velocity all zero): p, q, r from the "
                     "zero-phase derivative of the Imu attitude"]),
    "held_dvl": ([], ["velocity held between updates in dvl/twist:"]),
}
#: Largest |Δθ| / σ accepted, σ = √(σ_case² + σ_clean²): the Odometry and the 6 Hz DVL
#: carry noise of their own. Measured (seed 11, 150 s of protocol B), native: Odometry 2.09,
#: no accelerometer 0.97, no gyro 0.74, held DVL 1.41; MuJoCo ≤ 0.06 (its σ is wide: the
#: plant's structural misfit)
BOUND = 3.0


@pytest.mark.parametrize("case", list(CASES))
def test_log_without_raw_sensors_identifies_like_the_clean_bag(
        flight: Flight, case: str, capsys: pytest.CaptureFixture[str]) -> None:
    options, lines = CASES[case]
    out = flight.root / f"{case}.yaml"
    capsys.readouterr()
    assert main(["identify", str(flight.bags[case]), "--vehicle", flight.vehicle, *options,
                 "--no-select", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    for line in lines:
        assert f"{case}: {line}" in err, err
    est = load_model(out)
    for line in lines:  # recorded in the model's provenance
        assert any(s.startswith(line) for s in est.extra["substitutions"]), est.extra
    delta = np.abs(est.theta - flight.theta)
    ratio = delta / np.hypot(est.theta_std, flight.std)
    worst = int(np.argmax(ratio))
    print(f"{flight.backend} {case}: max |Δθ|/σ = {ratio[worst]:.2f} "
          f"({est.parameter_names[worst]}), own σ {np.max(delta / est.theta_std):.2f}")
    assert ratio[worst] <= BOUND, (est.parameter_names[worst], ratio[worst])
    if case == "held_dvl":
        rate = float(err.split("update rate ")[1].split(" Hz")[0])
        assert abs(rate - 6.0) < 0.3, err


def test_clean_bag_prints_no_substitution(flight: Flight,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    assert "substitutions" not in load_model(flight.root / "clean.yaml").extra
    assert main(["identify", str(flight.bags["clean"]), "--vehicle", flight.vehicle]) == 0
    err = capsys.readouterr().err
    assert "no accelerometer" not in err and "no gyro" not in err and "held" not in err


def test_rls_refuses_a_navigation_state_in_one_line(flight: Flight,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["identify", str(flight.bags["odometry"]), "--vehicle", flight.vehicle,
                 "--imu-topic", "/nav/odom", "--dvl-topic", "/nav/odom",
                 "--method", "rls"]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--method rls reads an IMU and a DVL" in line and "batch method" in line


def test_an_frd_accelerometer_in_flu_messages_is_refused_by_name(
        flight: Flight, capsys: pytest.CaptureFixture[str]) -> None:
    """The accelerometer's y and z flipped (FRD inside FLU messages): the log is refused in
    one line naming the topic, the field and the cause (the fit would take the flipped
    specific force as measured); --accept-frames takes it as it is, with the warning."""
    from dampest_ros.io.bag import read_bag

    rec = read_bag(flight.bags["clean"])
    imu = rec["imu/data"]
    assert isinstance(imu, ImuSeries)
    rec["imu/data"] = replace(imu, linear_acceleration=imu.linear_acceleration
                              * [1.0, -1.0, -1.0])
    bag = write_with_rosbags(flight.root / "frd_accelerometer", rec)
    capsys.readouterr()
    assert main(["identify", str(bag), "--vehicle", flight.vehicle]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "imu/data: linear_acceleration points down in the world" in line, line
    assert "FRD accelerometer inside FLU messages" in line and "--accept-frames" in line
    assert main(["identify", str(bag), "--vehicle", flight.vehicle, "--accept-frames"]) == 0
    assert "warning: imu/data: linear_acceleration points down" in capsys.readouterr().err
