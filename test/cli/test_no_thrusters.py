"""A vehicle without thrusters: τ from tau_* CSV columns or a body-wrench topic
(geometry_msgs/WrenchStamped, FLU, --wrench-topic) identifies as with thrusters; what needs
thrusters (simulate, thruster telemetry) refuses with one line and exit 2. Seeded simulation
of the BlueROV2 Heavy, protocol B."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from dampest_ros.cli.main import main
from dampest_ros.core.online.estimator import CORRELATION_SECONDS, EstimatorConfig, OnlineEstimator
from dampest_ros.core.physics import frames
from dampest_ros.core.physics.vehicle import Vehicle, measured_wrench_scale
from dampest_ros.core.signals.measurements import JointSeries, WrenchSeries
from dampest_ros.core.signals.preprocess import thruster_wrench
from dampest_ros.io.bag import read_bag, write_bag
from dampest_ros.io.yaml_io import load_model, load_vehicle, save_model, vehicle_path

HEAVY = load_vehicle("bluerov2_heavy")


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """150 s of protocol B (seed 5) as a bag and a tau CSV; the same bag with τ on a
    WrenchStamped ``wrench`` topic instead of thrusters/state; the preset without thrusters."""
    root = tmp_path_factory.mktemp("no_thrusters")
    assert main(["simulate", "--vehicle", "bluerov2_heavy", "--protocol", "B", "--duration",
                 "150", "--seed", "5", "--out", str(root / "sim"),
                 "--csv", str(root / "sim.csv")]) == 0
    wrench_bag(root / "sim", root / "wrench_bag", HEAVY)
    doc = yaml.safe_load(vehicle_path("bluerov2_heavy").read_text())
    del doc["thrusters"]
    (root / "bare.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return root


def wrench_bag(src: Path, dst: Path, vehicle: Vehicle) -> Path:
    """Bag ``src`` with τ on a WrenchStamped ``wrench`` topic instead of thrusters/state:
    the body wrench the thrusters gave (FRD), as a vehicle would log it (FLU, same stamps)."""
    rec = read_bag(src)
    joints = rec.pop("thrusters/state")
    assert isinstance(joints, JointSeries) and vehicle.thrusters is not None
    tau_flu = frames.body_twist(thruster_wrench(joints, vehicle.thrusters))
    rec["wrench"] = WrenchSeries(joints.stamp, "base_link", tau_flu[:, :3], tau_flu[:, 3:])
    rec.pop("truth/odom", None)
    return write_bag(dst, rec)


def identify(src: Path, vehicle: str, out: Path, *extra: str) -> np.ndarray:
    assert main(["identify", str(src), "--vehicle", vehicle, "--out", str(out), *extra]) == 0
    return load_model(out).theta


def test_tau_csv_identifies_without_thrusters_as_with(run: Path) -> None:
    with_thr = identify(run / "sim.csv", "bluerov2_heavy", run / "csv_thr.yaml")
    bare = identify(run / "sim.csv", str(run / "bare.yaml"), run / "csv_bare.yaml")
    np.testing.assert_allclose(bare, with_thr, rtol=1e-9, atol=1e-9)
    # and the model carries the added mass and its switches of the vehicle
    m = load_model(run / "csv_bare.yaml")
    np.testing.assert_array_equal(m.M_A, HEAVY.body.added_mass)
    assert m.added_mass_terms is not None and m.added_mass_terms.all


def test_wrench_bag_identifies_without_thrusters_as_the_thruster_bag(run: Path) -> None:
    """τ from the wrench topic (FLU → FRD, window mean before the stamp as for thruster
    telemetry) gives the thrusters' θ to 1e-9, within its σ of the truth."""
    ref = identify(run / "sim", "bluerov2_heavy", run / "bag_thr.yaml")
    got = identify(run / "wrench_bag", str(run / "bare.yaml"), run / "bag_bare.yaml",
                   "--wrench-topic", "wrench")
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9)
    m, truth = load_model(run / "bag_bare.yaml"), load_model(run / "sim" / "truth_model.yaml")
    assert m.parameter_names == truth.parameter_names
    z = np.abs(m.theta - truth.theta) / m.theta_std
    big = np.abs(truth.theta) > 1.0
    assert np.all(z[big] < 4.0), dict(zip(np.array(m.parameter_names)[big], z[big],
                                          strict=True))


@pytest.mark.slow
def test_rls_on_a_wrench_bag_without_thrusters_is_the_rls_on_the_thruster_bag(
        run: Path) -> None:
    """The online preprocessing (preprocess_node's core) takes τ from the wrench topic in
    place of thrusters/state, message for message: with the same vehicle the RLS gives the
    same θ to 1e-9; without thrusters (noise weights from the measured τ) within σ."""
    ref = identify(run / "sim", "bluerov2_heavy", run / "rls_thr.yaml", "--method", "rls")
    same = identify(run / "wrench_bag", "bluerov2_heavy", run / "rls_wrench.yaml",
                    "--method", "rls", "--wrench-topic", "wrench")
    np.testing.assert_allclose(same, ref, rtol=1e-9, atol=1e-9)
    got = identify(run / "wrench_bag", str(run / "bare.yaml"), run / "rls_bare.yaml",
                   "--method", "rls", "--wrench-topic", "wrench")
    std = load_model(run / "rls_bare.yaml").theta_std
    assert np.all(np.abs(got - ref) < std), (got - ref) / std
    truth = load_model(run / "sim" / "truth_model.yaml").theta
    np.testing.assert_allclose(got[truth > 10.0], truth[truth > 10.0], rtol=0.02)


def test_validate_and_gap_take_a_tau_csv_and_a_wrench_bag_without_thrusters(
        run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    truth = str(run / "sim" / "truth_model.yaml")
    bare = str(run / "bare.yaml")
    assert main(["validate", truth, str(run / "sim.csv"), "--vehicle", bare]) == 0
    assert main(["validate", truth, str(run / "wrench_bag"), "--vehicle", bare,
                 "--wrench-topic", "wrench"]) == 0
    out = capsys.readouterr().out
    r2 = [float(line.split()[1]) for line in out.splitlines()
          if line.split()[:1] and line.split()[0] in ("u/X", "w/Z", "r/N")]
    assert len(r2) == 6 and min(r2) > 0.99, out
    # a plant without M_A ν̇ (MuJoCo-like): gap's model keeps the vehicle's switches
    doc = yaml.safe_load((run / "bare.yaml").read_text())
    doc["vehicle"]["added_mass_terms"] = {"inertial": False, "coriolis": True, "munk": True}
    (run / "bare_switched.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    assert main(["gap", str(run / "wrench_bag"), "--model", truth, "--vehicle",
                 str(run / "bare_switched.yaml"), "--wrench-topic", "wrench", "--candidates",
                 "thrusters,buoyancy", "--max-steps", "1", "--out", str(run / "gap.yaml")]) == 0
    assert "rotor speeds" in capsys.readouterr().out
    final = load_model(run / "gap.yaml")
    assert final.added_mass_terms is not None and not final.added_mass_terms.inertial
    np.testing.assert_allclose(final.M_A, HEAVY.body.added_mass, atol=1e-9)


def test_what_needs_thrusters_refuses_in_one_line(run: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    bare = str(run / "bare.yaml")
    capsys.readouterr()
    assert main(["simulate", "--vehicle", bare, "--duration", "10",
                 "--out", str(run / "never")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "thrusters: " in err and "thrusters: section" in err
    assert not (run / "never").exists()
    # a bag without --wrench-topic: τ would come from thruster telemetry
    assert main(["identify", str(run / "wrench_bag"), "--vehicle", bare]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--wrench-topic" in err
    # the online path (RLS) likewise
    assert main(["identify", str(run / "wrench_bag"), "--vehicle", bare, "--method", "rls"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--wrench-topic" in err
    # a wrench topic that is not in the bag names the topics that are
    assert main(["identify", str(run / "wrench_bag"), "--vehicle", bare,
                 "--wrench-topic", "body_wrench"]) == 2
    err = capsys.readouterr().err
    assert "body_wrench" in err and "missing" in err


def test_inspect_knows_the_wrench_topic(run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(run / "wrench_bag")]) == 1
    assert "thrusters/state" in capsys.readouterr().out
    assert main(["inspect", str(run / "wrench_bag"), "--wrench-topic", "wrench"]) == 0
    assert "IMU, DVL and body wrench topics present" in capsys.readouterr().out


def test_estimator_without_thrusters_weights_by_the_measured_tau(run: Path) -> None:
    """The RLS noise weights come from the first CORRELATION_SECONDS of measured τ
    ((1 % of its 99th percentile)² per DOF), never from invented thrusters; with thrusters
    they stay (1 % of the largest thrust)²."""
    bare = load_vehicle(run / "bare.yaml")
    cfg = EstimatorConfig(rate=50.0, cutoff=2.0)
    est = OnlineEstimator(bare, config=cfg)
    rng = np.random.default_rng(3)
    n = int(CORRELATION_SECONDS * cfg.rate) + 20
    tau = rng.normal(0.0, [30.0, 20.0, 40.0, 0.5, 0.4, 2.0], (n, 6))
    q = np.array([0.0, 0.0, 0.0, 1.0])
    used = 0
    for k in range(n):
        stamp = 1_000_000_000 + k * 20_000_000
        for stream, value in (("velocity", rng.normal(0, 0.1, 6)),
                              ("acceleration", rng.normal(0, 0.1, 6)),
                              ("wrench", tau[k]), ("attitude", q)):
            used += est.add(stream, stamp, value)
        if k == n - 30:
            assert used == 0  # the RLS waits for the data that scale it
    assert used > 0
    first = tau[:int(CORRELATION_SECONDS * cfg.rate)]
    want = (0.01 * measured_wrench_scale(first)) ** 2
    np.testing.assert_allclose(est.rls.config.noise_var, want, rtol=1e-12)
    np.testing.assert_allclose(want[0], (0.01 * np.percentile(np.abs(first[:, 0]), 99)) ** 2,
                               rtol=1e-12)
    # the estimator's model file (~/save) carries the added mass and its switches
    saved = load_model(save_model(run / "estimator.yaml", est.to_model(3)))
    np.testing.assert_array_equal(saved.M_A, bare.body.added_mass)
    assert saved.added_mass_terms == bare.body.added_mass_terms
    np.testing.assert_array_equal(saved.theta, est.theta)
    heavy = OnlineEstimator(HEAVY, config=cfg)
    assert HEAVY.thrusters is not None
    np.testing.assert_allclose(heavy.rls.config.noise_var,
                               (0.01 * HEAVY.thrusters.max_wrench) ** 2, rtol=1e-12)


def test_preprocess_node_takes_the_wrench_topic_without_thrusters(run: Path) -> None:
    """preprocess_node with wrench_topic on a vehicle without thrusters: the bag's messages,
    serialized and fed to its raw callbacks (through its stamp-order stage), give the samples
    of the offline OnlinePreprocessor on the same messages, τ included, to the last bit;
    without wrench_topic the node refuses to start, naming the parameter."""
    pytest.importorskip("rclpy")
    import rclpy
    from rclpy.parameter import Parameter
    from rclpy.serialization import serialize_message

    from dampest_ros.core.online.preprocessor import OnlinePreprocessor
    from dampest_ros.core.physics.rigid_body import ConfigError
    from dampest_ros.ros.convert import publications
    from dampest_ros.ros.preprocess_node import PreprocessNode

    rec = {k: s.select(np.flatnonzero(s.stamp < 40.0))
           for k, s in read_bag(run / "wrench_bag").items()}
    bare = load_vehicle(run / "bare.yaml")
    want = OnlinePreprocessor(None, bare.body.gravity, bare.body.rho).run(
        rec, {"wrench": "wrench"})
    assert len(want) > 1000
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=71)
    try:
        with pytest.raises(ConfigError, match="wrench_topic"):
            PreprocessNode(context=ctx, parameter_overrides=[
                Parameter("vehicle", value=str(run / "bare.yaml"))])
        node = PreprocessNode(context=ctx, parameter_overrides=[
            Parameter("vehicle", value=str(run / "bare.yaml")),
            Parameter("wrench_topic", value="wrench")])
        got: list = []
        node._publish = got.extend  # type: ignore[method-assign]
        feed = {"imu/data": node._on_imu, "dvl/twist": node._on_dvl,
                "pressure": node._on_pressure, "wrench": node._on_wrench}
        for topic, msg in publications(rec):
            feed[topic](serialize_message(msg))
        node._process(node.order.flush())
        assert node.pre.counts["wrench"] == len(rec["wrench"])
        assert node.pre.counts["thrusters"] == 0
        assert len(got) == len(want)
        for a, b in zip(got, want, strict=True):
            assert a.t == b.t and a.usable == b.usable
            np.testing.assert_array_equal(a.tau, b.tau)
            np.testing.assert_array_equal(a.nu, b.nu)
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_a_commanded_wrench_that_leads_by_half_a_second_is_found_and_removed(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A vehicle that logs the wrench it commands (the thrust acts 0.5 s later): --delay auto
    on the wrench topic finds 0.5 s with its σ, and the truth is back within 3σ of every
    coefficient the truth has; a vehicle file without thrusters."""
    sim = tmp_path / "sim"
    assert main(["simulate", "--vehicle", "bluerov2_heavy", "--protocol", "B", "--duration",
                 "150", "--seed", "8", "--out", str(sim), "--effects", "{delay: 0.5}"]) == 0
    wrench_bag(sim, tmp_path / "commanded", HEAVY)
    doc = yaml.safe_load(vehicle_path("bluerov2_heavy").read_text())
    del doc["thrusters"]
    (tmp_path / "bare.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    capsys.readouterr()
    out = tmp_path / "model.yaml"
    identify(tmp_path / "commanded", str(tmp_path / "bare.yaml"), out, "--wrench-topic",
             "wrench", "--delay", "auto")
    line = capsys.readouterr().err.split("after the thrust:")[1].splitlines()[0]
    delay_ms, std_ms = (float(x) for x in line.split(" (")[0].replace("ms", "").split("±"))
    assert abs(delay_ms - 500.0) <= 10.0 and 0.0 < std_ms < 2.0, line
    est, truth = load_model(out), load_model(sim / "truth_model.yaml")
    for name, value, sd, t in zip(est.parameter_names, est.theta, est.theta_std, truth.theta,
                                  strict=True):
        if t:
            assert abs(value - t) <= 3.0 * sd, (name, value, sd, t)


def test_the_commanded_wrench_lead_is_found_on_the_mujoco_torpedo(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The same on physics we did not write (MuJoCo's torpedo, 120 s, thrust acting 0.5 s
    after the logged wrench): measured 503.3 ± 2.6 ms."""
    sim = tmp_path / "sim"
    torpedo = load_vehicle("torpedo_auv")
    assert main(["simulate", "--backend", "mujoco", "--vehicle", "torpedo_auv", "--protocol",
                 "B", "--duration", "120", "--seed", "3", "--out", str(sim), "--effects",
                 "{delay: 0.5}"]) == 0
    wrench_bag(sim, tmp_path / "commanded", torpedo)
    capsys.readouterr()
    assert main(["identify", str(tmp_path / "commanded"), "--vehicle", "torpedo_auv",
                 "--wrench-topic", "wrench", "--delay", "auto"]) == 0
    line = capsys.readouterr().err.split("after the thrust:")[1].splitlines()[0]
    delay_ms, std_ms = (float(x) for x in line.split(" (")[0].replace("ms", "").split("±"))
    assert abs(delay_ms - 500.0) <= max(3.0 * std_ms, 10.0) and std_ms < 10.0, line
