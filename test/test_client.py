"""dampest_ros.client evaluates every static damping term of a model: from a YAML file and
from the parameters of a model_server_node and of a live estimator_node (model.terms.* carry
the structure)."""

from __future__ import annotations

import contextlib
import math
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from dampest_ros.client import STALE_RETRIES, ArmModelClient, ModelClient
from dampest_ros.core.arm.base import base_parameters, random_states
from dampest_ros.core.arm.model import arm_model_identity
from dampest_ros.core.arm.online import ArmEstimate
from dampest_ros.core.arm.regressor import full_parameters, regressor
from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import ConfigError, coriolis_force
from dampest_ros.core.physics.vehicle import damping_from_spec
from dampest_ros.io.arm import load_arm, save_arm_model
from dampest_ros.io.yaml_io import damping_spec, load_vehicle, save_model, vehicle_path

#: The test data: a second arm (z1like.urdf and its MJCF).
DATA = Path(__file__).parent / "data"

SPEC: dict[str, Any] = {
    "linear": {"X_u": 0, "Y_v": 0, "Z_w": 0, "K_p": 0, "M_q": 0, "N_r": 0, "Y_r": 0},
    "quadratic": {"X_uu": 0, "Y_vv": 0, "Z_ww": 0, "K_pp": 0, "M_qq": 0, "N_rr": 0},
    "cross": [{"row": "Y", "col": "v", "alpha": "|r|", "name": "Y_vr"},
              {"row": "N", "col": "r", "alpha": "v"},
              {"row": "X", "col": "u", "alpha": "|U|"}],
    "added": {},
    "residual": {"modes": [[1, 0, 1, 0, 0, 0], [0, 1, 0, 0, 0, 1], [0, 0, 1, 0, 1, 0]]},
}


def model_and_file(path: Path, seed: int = 3) -> tuple[DampingModel, np.ndarray, np.ndarray,
                                                       np.ndarray]:
    """Every static term kind with random coefficients, written to ``path``."""
    model, _ = damping_from_spec(SPEC)
    rng = np.random.default_rng(seed)
    theta = rng.uniform(0.1, 50.0, model.n_params)
    std = rng.uniform(0.01, 1.0, model.n_params)
    M = load_vehicle("bluerov2_heavy").body.M
    save_model(path, Model(model.parameter_names, theta, std, M, damping=model, version=4))
    return model, theta, std, M


def check_client(client: ModelClient, model: DampingModel, theta: np.ndarray, std: np.ndarray,
                 M: np.ndarray) -> None:
    """D(ν), D(ν)ν, its σ and the feed-forward equal the core model's on random ν."""
    nu = np.random.default_rng(7).normal(0.0, [0.5, 0.4, 0.3, 0.6, 0.5, 0.7], (40, 6))
    np.testing.assert_allclose(client.damping_force(nu), model.force(nu, theta),
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(client.damping_force(nu[3]), model.force(nu[3:4], theta)[0],
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(client.D(nu), model.matrix(nu, theta), rtol=1e-12, atol=1e-12)
    Phi = model.regressor(nu)
    np.testing.assert_allclose(client.damping_force_std(nu),
                               np.sqrt((Phi**2 * std**2).sum(axis=2)), rtol=1e-12)
    np.testing.assert_allclose(client.feedforward(nu),
                               model.force(nu, theta) + coriolis_force(M, nu),
                               rtol=1e-12, atol=1e-12)


def test_yaml_client_evaluates_cross_added_and_residual_terms(tmp_path: Path) -> None:
    path = tmp_path / "model.yaml"
    model, theta, std, M = model_and_file(path)
    assert {t.kind for t in model.terms} == {"linear", "quadratic", "cross", "added",
                                             "residual"}
    client = ModelClient.from_yaml(path)
    assert client.version == 4 and client.model.parameter_names == model.parameter_names
    check_client(client, model, theta, std, M)
    # the cross and residual terms matter at these speeds (the test would see them missing)
    nu = np.array([[0.5, 0.3, 0.2, 0.1, 0.2, 0.6]])
    static = DampingModel([t for t in model.terms if t.kind in ("linear", "quadratic")])
    full, part = model.force(nu, theta)[0], static.force(nu, theta[:static.n_params])[0]
    assert np.max(np.abs(full - part)) > 1.0


@contextlib.contextmanager
def three_servers(model_file: Path, vehicle_file: Path, tag: str
                  ) -> Iterator[tuple[Any, list[ModelClient], list[Any],
                                      Callable[[Callable[[], bool]], None]]]:
    """A model_server_node with ``model_file`` as its model_file parameter, a second one
    given it as --params-file (``params_server``) and an estimator_node on ``vehicle_file``,
    in a namespace of their own; yields (rclpy, clients of the three, the three nodes,
    spin_until) once all three clients are available or 10 s have passed."""
    rclpy = pytest.importorskip("rclpy")
    from rclpy.executors import SingleThreadedExecutor

    from dampest_ros.ros.estimator_node import EstimatorNode
    from dampest_ros.ros.model_server_node import ModelServerNode

    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", "77")
    ns = f"/test_{tag}_{os.getpid()}"  # no other test run's server answers
    context = rclpy.Context()
    rclpy.init(context=context)
    ex = SingleThreadedExecutor(context=context)
    nodes: list[Any] = []
    try:
        by_file = ModelServerNode(context=context, cli_args=[
            "--ros-args", "-r", f"__ns:={ns}", "-p", f"model_file:={model_file}"])
        by_params = ModelServerNode(context=context, cli_args=[
            "--ros-args", "-r", f"__ns:={ns}", "-r", "__node:=params_server",
            "--params-file", str(model_file)])
        est = EstimatorNode(context=context, cli_args=["--ros-args", "-r", f"__ns:={ns}"],
                            parameter_overrides=[rclpy.parameter.Parameter(
                                "vehicle", value=str(vehicle_file))])
        probe = rclpy.create_node("probe", namespace=ns, context=context)
        nodes += [by_file, by_params, est, probe]
        for n in nodes:
            ex.add_node(n)
        clients = [ModelClient(probe, s) for s in ("model_server_node", "params_server",
                                                   "estimator_node")]

        def spin_until(done: Callable[[], bool]) -> None:
            end = time.monotonic() + 10.0
            while not done() and time.monotonic() < end:
                ex.spin_once(timeout_sec=0.05)

        spin_until(lambda: all(c.available for c in clients))
        yield rclpy, clients, [by_file, by_params, est], spin_until
    finally:
        ex.shutdown()
        for n in nodes:
            n.destroy_node()
        rclpy.try_shutdown(context=context)


def test_model_server_and_estimator_parameters_give_the_same_model(tmp_path: Path) -> None:
    import yaml

    path = tmp_path / "model.yaml"
    model, theta, std, M = model_and_file(path)
    # a vehicle whose nominal damping is that model: the estimator's prior, before any data
    doc = yaml.safe_load(vehicle_path("bluerov2_heavy").read_text())
    doc["damping"] = damping_spec(model, theta)
    vehicle = tmp_path / "vehicle.yaml"
    vehicle.write_text(yaml.safe_dump(doc, sort_keys=False))
    # the file as model_file, and the same file as --params-file of a second server
    with three_servers(path, vehicle, "client") as (rclpy, clients, servers, spin_until):
        by_file, _, est = servers
        for c in clients[:2]:
            assert c.available, c.errors
            assert c.version == 4 and c.model.damping.kinds == model.kinds
            check_client(c, model, theta, std, M)
        assert "model.terms.cross.rows" in by_file._served
        e = est.estimator
        assert clients[2].available, clients[2].errors
        assert clients[2].model.damping.kinds == model.kinds
        check_client(clients[2], model, theta, e.theta_std, M)
        # the estimator restricted to the linear and quadratic terms: its cross, added and
        # residual parameters go, the client follows to the new structure
        version = clients[2].version
        est.set_parameters([rclpy.parameter.Parameter("terms", value="linear,quadratic")])
        spin_until(lambda: clients[2].version > version)
        assert clients[2].version > version, clients[2].errors
        assert not est.has_parameter("model.terms.cross.rows")
        assert est.estimator.model.kinds == ["linear", "quadratic"]
        kept = [model.parameter_names.index(n) for n in est.estimator.names]
        check_client(clients[2], est.estimator.model, theta[kept], est.estimator.theta_std, M)
        # another file without cross/added/residual terms: the terms' parameters go, the
        # client follows the version bump to the new structure
        small = tmp_path / "small.yaml"
        v = load_vehicle("bluerov2_heavy")
        save_model(small, Model(v.damping.parameter_names, 2.0 * v.theta, np.ones(12), v.body.M,
                                damping=v.damping))
        by_file.set_parameters([rclpy.parameter.Parameter("model_file", value=str(small))])
        spin_until(lambda: clients[0].version == 5)
        assert clients[0].version == 5, clients[0].errors
        assert not by_file.has_parameter("model.terms.cross.rows")
        check_client(clients[0], v.damping, 2.0 * v.theta, np.ones(12), v.body.M)


@pytest.mark.parametrize("zero", [None, [["X", "q"], ["X", "r"], ["Z", "q"], ["Y", "r"]]])
def test_added_mass_switches_reach_the_client_from_file_and_parameters(
        tmp_path: Path, zero: list[list[str]] | None) -> None:
    """A plant without Munk moments and without M_A ν̇ (and, second case, without the C_A
    entries X←q, X←r, Z←q, Y←r): the client's C(ν)ν and feed-forward equal the core
    RigidBody's to 1e-12 from the YAML file, from a model_server_node (by file and by
    --params-file) and from an estimator_node on that vehicle (model.M_A and
    model.added_mass_terms.* served as parameters, the entries as a 36-int coriolis_mask)."""
    import yaml

    from dampest_ros.core.physics.rigid_body import AddedMassTerms

    switches: dict[str, Any] = {"inertial": False, "coriolis": True, "munk": False}
    if zero is not None:
        switches["coriolis_zero"] = zero
    doc = yaml.safe_load(vehicle_path("bluerov2_heavy").read_text())
    doc["vehicle"]["added_mass_terms"] = switches
    vehicle_file = tmp_path / "vehicle.yaml"
    vehicle_file.write_text(yaml.safe_dump(doc, sort_keys=False))
    v = load_vehicle(vehicle_file)
    terms = AddedMassTerms.from_dict(switches)
    assert v.body.added_mass_terms == terms
    path = save_model(tmp_path / "model.yaml", Model(v.damping.parameter_names, v.theta,
                                                     np.ones(v.theta.size), v.body.M,
                                                     damping=v.damping, M_A=v.body.added_mass,
                                                     added_mass_terms=v.body.added_mass_terms))
    nu = np.random.default_rng(11).normal(0.0, [0.8, 0.6, 0.4, 0.5, 0.5, 0.6], (40, 6))
    want = v.body.coriolis_force(nu)
    # the Munk moments are what the switch removes: N = (Y_v̇ − X_u̇) u v is large here
    assert np.abs(coriolis_force(v.body.M, nu) - want).max() > 0.1

    def check(c: ModelClient) -> None:
        np.testing.assert_allclose(c.model.coriolis_force(nu), want, rtol=0, atol=1e-12)
        np.testing.assert_allclose(c.feedforward(nu), v.damping.force(nu, c.model.theta) + want,
                                   rtol=0, atol=1e-12)

    check(ModelClient.from_yaml(path))
    with three_servers(path, vehicle_file, "switches") as (_, clients, servers, _spin):
        for c, server in zip(clients, servers, strict=True):
            assert c.available, c.errors
            assert server._served["model.added_mass_terms.munk"] is False
            assert server._served["model.added_mass_terms.inertial"] is False
            assert len(server._served["model.M_A"]) == 36
            mask = server._served.get("model.added_mass_terms.coriolis_mask")
            assert mask == (None if zero is None else terms.mask.astype(int).ravel().tolist())
            assert c.model.added_mass_terms == terms
            check(c)


def nan_file(path: Path, good: Path) -> Path:
    """``good`` with model.theta[0] = NaN (written as YAML's .nan)."""
    import yaml

    doc = yaml.safe_load(good.read_text())
    doc["/**"]["ros__parameters"]["model"]["theta"][0] = float("nan")
    path.write_text(yaml.safe_dump(doc))
    return path


def test_model_server_refuses_a_non_finite_model_at_start(tmp_path: Path, children: Any
                                                          ) -> None:
    """A NaN in a model file's theta was served by model_server_node. At start, by
    model_file or by --params-file, the node logs one error naming the entry and exits with
    status 2, no traceback."""
    import sys

    pytest.importorskip("rclpy")
    good = tmp_path / "good.yaml"
    model_and_file(good)
    bad = nan_file(tmp_path / "bad.yaml", good)
    env = dict(os.environ, ROS_DOMAIN_ID="78", ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    for args in (["-p", f"model_file:={bad}"], ["--params-file", str(bad)]):
        proc = children.run([sys.executable, "-m", "dampest_ros.ros.model_server_node",
                             "--ros-args", *args], capture_output=True, text=True,
                            timeout=60, env=env)
        out = proc.stdout + proc.stderr
        assert proc.returncode == 2, out
        assert "Traceback" not in out and "cannot start" in out, out
        assert "model.theta: not finite: X_u = nan" in out, out
        assert len([x for x in out.splitlines() if x.strip()]) == 1, out


def test_bad_model_at_runtime_is_refused_and_the_client_keeps_the_last_good_one(
        tmp_path: Path) -> None:
    """At runtime model_server_node rejects a model_file with a NaN (the reason in the
    result) and keeps serving its model; a client whose server publishes a NaN theta refuses
    that update, keeps the last good model and says why. The client exposes which
    coefficients the data determined (model.identified, served as a parameter)."""
    rclpy = pytest.importorskip("rclpy")
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from dampest_ros.io.yaml_io import load_model, model_parameters
    from dampest_ros.ros.model_server_node import ModelServerNode

    v = load_vehicle("bluerov2_heavy")
    names = v.damping.parameter_names
    held = {"Y_vv": "poorly determined", "K_pp": "no excitation"}
    std = np.array([np.nan if n in held else 0.5 for n in names])
    good = save_model(tmp_path / "good.yaml", Model(names, v.theta, std, v.body.M,
                                                    damping=v.damping, version=4, held=held))
    bad = nan_file(tmp_path / "bad.yaml", good)
    with pytest.raises(ConfigError, match=r"model\.theta: not finite: X_u = nan"):
        ModelClient.from_yaml(bad)
    mask = [n not in held for n in names]
    assert ModelClient.from_yaml(good).identified.tolist() == mask
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", "77")
    ns = f"/test_refuse_{os.getpid()}"
    context = rclpy.Context()
    rclpy.init(context=context)
    ex = SingleThreadedExecutor(context=context)
    nodes: list[Any] = []
    try:
        server = ModelServerNode(context=context, cli_args=[
            "--ros-args", "-r", f"__ns:={ns}", "-p", f"model_file:={good}"])
        # a server that publishes whatever it is given (as a faulty estimator would)
        m = load_model(good)
        fake = rclpy.create_node("fake_server", namespace=ns, context=context)
        for name, value in model_parameters(Model(names, m.theta, m.theta_std, m.M,
                                                  damping=m.damping, version=4, held=held)).items():
            fake.declare_parameter(name, value)
        probe = rclpy.create_node("probe", namespace=ns, context=context)
        nodes += [server, fake, probe]
        for n in nodes:
            ex.add_node(n)
        clients = [ModelClient(probe, s) for s in ("model_server_node", "fake_server")]

        def spin_until(done: Callable[[], bool]) -> None:
            end = time.monotonic() + 10.0
            while not done() and time.monotonic() < end:
                ex.spin_once(timeout_sec=0.05)

        spin_until(lambda: all(c.available for c in clients))
        nu = np.array([0.5, -0.2, 0.1, 0.3, 0.0, -0.4])
        want = v.damping.force(nu[None, :], v.theta)[0]
        for c in clients:
            assert c.available, c.errors
            assert c.identified.tolist() == mask and c.held == held
            np.testing.assert_allclose(c.damping_force(nu), want, rtol=1e-12)
        assert server._served["model.identified"] == mask
        assert server._served["model.held.names"] == list(held)
        # model_server_node: the bad file is rejected with the reason, the model stays
        result = server.set_parameters([Parameter("model_file", value=str(bad))])[0]
        assert not result.successful
        assert result.reason.startswith(f"model_file: {bad}:")
        assert ": model.theta: not finite: X_u = nan" in result.reason
        assert server.version == 4 and server.p("model_file") == str(good)
        # the faulty server publishes a NaN theta: the client keeps version 4 and says why
        theta = list(fake.get_parameter("model.theta").value)
        theta[0] = float("nan")
        fake.set_parameters([Parameter("model.theta", value=theta),
                             Parameter("model.version", value=5)])
        spin_until(lambda: bool(clients[1].errors))
        assert clients[1].errors and "model.theta: not finite: X_u = nan" in \
            clients[1].errors[-1]
        assert clients[1].version == 4
        np.testing.assert_allclose(clients[1].damping_force(nu), want, rtol=1e-12)
        # nothing answered by a server that is there: the names changed between the list and
        # the get; the client lists again, quietly, and has the model again
        empty = SimpleNamespace(result=lambda: SimpleNamespace(values=[]))
        refreshes, errors = clients[0].refreshes, len(clients[0].errors)
        clients[0]._on_response(["model.theta", "model.version"], empty)
        assert clients[0]._stale == 1
        spin_until(lambda: clients[0].refreshes > refreshes)
        assert clients[0]._stale == 0 and len(clients[0].errors) == errors
        # a server stopping while asked (nothing, again and again): kept, logged, not refused
        clients[1]._stale = STALE_RETRIES
        clients[1]._on_response(["model.theta", "model.version"], empty)
        assert len(clients[1].errors) == 1 and clients[1].version == 4
    finally:
        ex.shutdown()
        for n in nodes:
            n.destroy_node()
        rclpy.try_shutdown(context=context)


def test_client_reports_the_age_of_its_model_and_a_lost_server(tmp_path: Path) -> None:
    """A client whose server died kept 'available' true. With timeout=1 s: the age
    grows from the model's arrival; 1 s after the server left the graph the client is lost
    (available false, the last model kept and evaluated); a new server makes it available
    again with a fresh model."""
    rclpy = pytest.importorskip("rclpy")
    from rclpy.executors import SingleThreadedExecutor

    from dampest_ros.ros.model_server_node import ModelServerNode

    path = tmp_path / "model.yaml"
    model, theta, std, M = model_and_file(path)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", "77")
    ns = f"/test_lost_{os.getpid()}"
    context = rclpy.Context()
    rclpy.init(context=context)
    ex = SingleThreadedExecutor(context=context)
    args = ["--ros-args", "-r", f"__ns:={ns}", "-p", f"model_file:={path}"]
    server = ModelServerNode(context=context, cli_args=args)
    probe = rclpy.create_node("probe", namespace=ns, context=context)
    try:
        ex.add_node(server)
        ex.add_node(probe)
        client = ModelClient(probe, "model_server_node", timeout=1.0)
        assert math.isnan(client.age) and not client.available

        def spin_for(seconds: float, done: Callable[[], bool] = lambda: False) -> float:
            t0 = time.monotonic()
            while not done() and time.monotonic() - t0 < seconds:
                ex.spin_once(timeout_sec=0.05)
            return time.monotonic() - t0

        spin_for(10.0, lambda: client.available)
        assert client.available and client.version == 4 and not client.lost
        age0 = client.age
        spin_for(0.5)
        assert client.age - age0 == pytest.approx(0.5, abs=0.1)
        ex.remove_node(server)
        server.destroy_node()
        gone = spin_for(10.0, lambda: client.lost)
        assert client.lost and not client.available
        assert 1.0 <= gone < 3.0  # the timeout plus the graph update and a check period
        check_client(client, model, theta, std, M)  # the last model is kept
        server = ModelServerNode(context=context, cli_args=args)
        ex.add_node(server)
        refreshes = client.refreshes
        spin_for(10.0, lambda: client.available)
        assert client.available and client.refreshes == refreshes + 1 and client.age < 1.0
    finally:
        ex.shutdown()
        for n in (server, probe):
            n.destroy_node()
        rclpy.try_shutdown(context=context)


def test_a_client_for_one_vehicle_refuses_another_vehicles_model(tmp_path: Path) -> None:
    """A controller of platform_a pointed at a server of the BlueROV2 Heavy's model: the
    model is refused with both names (a wrong feed-forward is worse than none); a client of
    the Heavy takes it."""
    heavy = load_vehicle("bluerov2_heavy")
    path = save_model(tmp_path / "heavy.yaml", Model(
        heavy.damping.parameter_names, heavy.theta, 0.1 * np.abs(heavy.theta) + 0.01,
        heavy.body.M, damping=heavy.damping, identity=heavy.identity))
    with served(model_server(path), "identity") as (ex, _, probe):
        other = ModelClient(probe, "model_server_node",
                            vehicle=load_vehicle("platform_a").identity)
        same = ModelClient(probe, "model_server_node", vehicle=heavy.identity)
        end = time.monotonic() + 10.0
        while not (same.available and other.errors) and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        assert same.available, same.errors
        assert not other.available and other.errors, other.errors
        assert "belongs to vehicle_damping 'bluerov2_heavy'" in other.errors[0]
        assert "'platform_a'" in other.errors[0]


@contextlib.contextmanager
def served(start: Callable[[Any, str], Any], tag: str) -> Iterator[tuple[Any, Any, Any]]:
    """A server node ``start(context, namespace)`` and a node ``probe`` in a namespace of
    their own, in one executor the test spins: (executor, server, probe)."""
    rclpy = pytest.importorskip("rclpy")
    from rclpy.executors import SingleThreadedExecutor

    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", "77")
    ns = f"/test_{tag}_{os.getpid()}"
    context = rclpy.Context()
    rclpy.init(context=context)
    ex = SingleThreadedExecutor(context=context)
    try:
        server = start(context, ns)
        probe = rclpy.create_node("probe", namespace=ns, context=context)
        for n in (server, probe):
            ex.add_node(n)
        yield ex, server, probe
    finally:
        ex.shutdown()
        rclpy.try_shutdown(context=context)


def model_server(model_file: Path) -> Callable[[Any, str], Any]:
    """:func:`served`'s start of a model_server_node on ``model_file``."""
    def start(context: Any, ns: str) -> Any:
        from dampest_ros.ros.model_server_node import ModelServerNode

        return ModelServerNode(context=context, cli_args=[
            "--ros-args", "-r", f"__ns:={ns}", "-p", f"model_file:={model_file}"])
    return start


@contextlib.contextmanager
def spun_in_background(tag: str, model_file: Path) -> Iterator[tuple[Any, Any, str]]:
    """In a namespace of their own: a model_server_node on ``model_file``, a second one named
    ``params_server``, a node named ``sim_node`` that publishes imu/data and dvl/twist but
    declares no model, and a probe node; an executor spins them in a background thread, as
    a controller's would. Yields (rclpy, the probe, the namespace)."""
    rclpy = pytest.importorskip("rclpy")
    import threading

    from geometry_msgs.msg import TwistWithCovarianceStamped
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import Imu

    from dampest_ros.ros.model_server_node import ModelServerNode

    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", "77")
    ns = f"/test_{tag}_{os.getpid()}"
    context = rclpy.Context()
    rclpy.init(context=context)
    ex = SingleThreadedExecutor(context=context)
    sim = rclpy.create_node("sim_node", namespace=ns, context=context)
    sim.create_publisher(Imu, "imu/data", 10)
    sim.create_publisher(TwistWithCovarianceStamped, "dvl/twist", 10)
    nodes = [sim, rclpy.create_node("probe", namespace=ns, context=context),
             *(ModelServerNode(context=context, cli_args=[
                 "--ros-args", "-r", f"__ns:={ns}", "-r", f"__node:={name}",
                 "-p", f"model_file:={model_file}"])
               for name in ("params_server", "model_server_node"))]
    for n in nodes:
        ex.add_node(n)
    thread = threading.Thread(target=ex.spin, daemon=True)
    thread.start()
    try:
        yield rclpy, nodes[1], ns
    finally:
        ex.shutdown()
        thread.join(timeout=5.0)
        for n in nodes:
            n.destroy_node()
        rclpy.try_shutdown(context=context)


def test_a_client_pointed_at_the_wrong_node_says_what_is_wrong(tmp_path: Path) -> None:
    """A client of a node that is not a model server, or of a name no node has, said only
    'no model within 3 s'. It names the node that declares no model.* (and what it
    publishes), or lists the nodes that do, closest name first, with the domain looked on."""
    from dampest_ros.client import ModelUnavailableError

    path = tmp_path / "model.yaml"
    model_and_file(path)
    with spun_in_background("wrong", path) as (_, probe, ns):
        sim_client = ModelClient(probe, "sim_node")
        with pytest.raises(ModelUnavailableError) as sim:
            sim_client.wait(3.0)
        assert str(sim.value) == (
            f"no model from sim_node within 3 s: ModelUnavailableError: {ns}/sim_node "
            f"declares no model.* parameters: it is not a model server; it publishes "
            f"{ns}/dvl/twist, {ns}/imu/data. Point the client at model_server_node (serves a "
            f"saved model file) or estimator_node (identifies the model live)")
        t0 = time.monotonic()
        with pytest.raises(ModelUnavailableError) as typo:
            ModelClient(probe, "model_servr_node").wait(3.0)
        took = time.monotonic() - t0
        domain = os.environ["ROS_DOMAIN_ID"]
        assert str(typo.value).startswith(
            f"no model from model_servr_node within 3 s: no node {ns}/model_servr_node on the "
            f"graph of ROS_DOMAIN_ID {domain}; nodes with model.* parameters: "
            f"{ns}/model_server_node, {ns}/params_server")
        assert "sim_node," not in str(typo.value) and "another ROS_DOMAIN_ID" in str(typo.value)
        assert 3.0 <= took < 3.0 + 2.5       # the wait, then at most PROBE_TIME of asking
        # the right name still works from the same probe
        assert ModelClient(probe, "model_server_node").wait(10.0).version == 4


# --- the arm's model -------------------------------------------------------------------------


def ur5_model_file(path: Path, coulomb_width: float = 0.05, seed: int = 4
                   ) -> tuple[Path, ArmEstimate]:
    """A UR5 arm model file: the nominal base parameters with torque offsets, moved by 10 %
    (seeded), so that no term is what the client could take from the URDF."""
    desc = load_arm("ur5")
    base = base_parameters(desc.model)
    kept = [base.names[i] for i in base.independent]
    rng = np.random.default_rng(seed)
    theta = base.of(full_parameters(desc.model, desc.dynamics, rng.normal(0.0, 0.5, 6)))
    theta = theta * (1.0 + 0.1 * rng.normal(size=theta.size))
    est = ArmEstimate(desc.model.names, kept, theta, 0.01 * np.abs(theta) + 1e-3,
                      np.ones(theta.size, dtype=bool), base.mapping(), 3,
                      arm_model_identity("ur5", desc.model, kept), coulomb_width)
    return save_arm_model(path, est, "ur5"), est


def core_torque(est: ArmEstimate, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
                ) -> np.ndarray:
    """The core's Y_b(q, q̇, q̈) θ of a UR5 model, shape (N, 6)."""
    arm = load_arm("ur5").model
    Y = base_parameters(arm).columns(regressor(arm, q, qd, qdd, est.coulomb_width))
    return Y @ est.theta


def test_arm_client_from_yaml_is_the_cores_regressor_times_theta(tmp_path: Path) -> None:
    """From a file: τ = Y_b θ to 1e-12 on random states (one state and many), the offsets
    only when asked for; a file of another arm is refused naming both."""
    path, est = ur5_model_file(tmp_path / "ur5.yaml")
    client = ArmModelClient.from_yaml(path, "ur5")
    q, qd, qdd = random_states(6, 40, seed=11)
    want = core_torque(est, q, qd, qdd)
    np.testing.assert_allclose(client.feedforward(q, qd, qdd, offsets=True), want,
                               rtol=0, atol=1e-12)
    off = np.array([est.theta[est.parameter_names.index(f"{j}.off")]
                    for j in est.joint_names])
    np.testing.assert_allclose(client.feedforward(q, qd, qdd), want - off, rtol=0, atol=1e-12)
    np.testing.assert_allclose(client.feedforward(q[3], qd[3], qdd[3]), want[3] - off,
                               rtol=0, atol=1e-12)
    assert client.model.coulomb_width == 0.05
    with pytest.raises(ConfigError, match=r"belongs to arm 'ur5'.*not to the arm in use "
                                          r"'.*z1like\.urdf'"):
        ArmModelClient.from_yaml(path, str(DATA / "z1like.urdf"))


def test_model_server_serves_an_arm_model_to_the_arm_client(tmp_path: Path) -> None:
    """model_server_node given a UR5 arm model file holds arm_estimator_node's model.*
    contract and publishes the file on dampest/arm_model; a UR5 client's feed-forward is the
    core's Y_b θ to 1e-12 on random states, a client of another arm refuses the model with
    both names."""
    pytest.importorskip("rclpy")
    from std_msgs.msg import String

    from dampest_ros.ros.common import LATCHED_QOS

    path, est = ur5_model_file(tmp_path / "ur5.yaml")
    with served(model_server(path), "arm_server") as (ex, server, probe):
        texts: list[str] = []
        probe.create_subscription(String, "dampest/arm_model", lambda m: texts.append(m.data),
                                  LATCHED_QOS)
        same = ArmModelClient(probe, "model_server_node", arm="ur5")
        other = ArmModelClient(probe, "model_server_node", arm=str(DATA / "z1like.urdf"))
        end = time.monotonic() + 10.0
        while not (same.available and other.errors and texts) and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        assert same.available, same.errors
        assert server.get_parameter("model.kind").value == "arm_base_parameters"
        assert server.get_parameter("model.coulomb_width").value == 0.05
        assert "kind: arm_base_parameters" in texts[-1] and "model_server_node" in texts[-1]
        q, qd, qdd = random_states(6, 40, seed=12)
        np.testing.assert_allclose(same.feedforward(q, qd, qdd, offsets=True),
                                   core_torque(est, q, qd, qdd), rtol=0, atol=1e-12)
        assert same.version == 3 and same.model.parameter_names == est.parameter_names
        assert not other.available and other.errors, other.errors
        assert "belongs to arm 'ur5'" in other.errors[0]
        assert "z1like.urdf'" in other.errors[0]


def test_the_arm_client_reads_arm_estimator_node_alike(tmp_path: Path) -> None:
    """arm_estimator_node's model.* (before any data: its prior, a UR5 model file) reach the
    same client: the feed-forward is the prior's Y_b θ to 1e-12 with the node's Coulomb
    width."""
    pytest.importorskip("rclpy")
    from rclpy.parameter import Parameter

    from dampest_ros.ros.arm_estimator_node import ArmEstimatorNode

    path, est = ur5_model_file(tmp_path / "ur5.yaml")

    def start(context: Any, ns: str) -> Any:
        return ArmEstimatorNode(context=context, namespace=ns, parameter_overrides=[
            Parameter("prior", value=str(path)), Parameter("resume", value=False),
            Parameter("coulomb_width", value=0.05),
            Parameter("save_path", value=str(tmp_path / "saved.yaml"))])

    with served(start, "arm_estimator") as (ex, _, probe):
        client = ArmModelClient(probe, arm="ur5")
        end = time.monotonic() + 10.0
        while not (client.available or client.errors) and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        assert client.available, client.errors
        q, qd, qdd = random_states(6, 40, seed=13)
        np.testing.assert_allclose(client.feedforward(q, qd, qdd, offsets=True),
                                   core_torque(est, q, qd, qdd), rtol=0, atol=1e-12)
        assert client.version == 0 and client.model.coulomb_width == 0.05
