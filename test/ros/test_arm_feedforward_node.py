"""arm_feedforward_node in-process: a UR5 arm model file served by model_server_node; desired
joint states published on joint_reference with the joints in another order than the model's
come back on effort_feedforward as the core's Y_b(q, q̇, q̈) θ in the model's joint order, q̈
the backward difference of q̇ over the stamps. A message missing a joint or naming an unknown
one, a non-finite one and one stamped before its predecessor are counted and refused; without
a model, or with its server lost, nothing is published and the reason is logged once."""

from __future__ import annotations

import itertools
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from dampest_ros.core.arm.base import base_parameters, random_states  # noqa: E402
from dampest_ros.core.arm.model import arm_model_identity  # noqa: E402
from dampest_ros.core.arm.online import ArmEstimate  # noqa: E402
from dampest_ros.core.arm.regressor import full_parameters, regressor  # noqa: E402
from dampest_ros.io.arm import load_arm, save_arm_model  # noqa: E402
from dampest_ros.ros.arm_feedforward_node import ArmFeedforwardNode  # noqa: E402
from dampest_ros.ros.common import RELIABLE_QOS, to_time  # noqa: E402
from dampest_ros.ros.model_server_node import ModelServerNode  # noqa: E402

DT = 0.002  # s between the two references of a pair
#: The order the messages list the joints in (the model's reversed).
ORDER = [5, 2, 0, 4, 1, 3]


def ur5_model(path: Path) -> ArmEstimate:
    """A UR5 arm model file at ``path``: the nominal base parameters with torque offsets and
    a Coulomb width, moved by 10 % (seeded) so that nothing equals the URDF's; its estimate."""
    desc = load_arm("ur5")
    base = base_parameters(desc.model)
    kept = [base.names[i] for i in base.independent]
    rng = np.random.default_rng(21)
    theta = base.of(full_parameters(desc.model, desc.dynamics, rng.normal(0.0, 0.5, 6)))
    theta = theta * (1.0 + 0.1 * rng.normal(size=theta.size))
    est = ArmEstimate(desc.model.names, kept, theta, 0.01 * np.abs(theta) + 1e-3,
                      np.ones(theta.size, dtype=bool), base.mapping(), 2,
                      arm_model_identity("ur5", desc.model, kept), 0.05)
    save_arm_model(path, est, "ur5")
    return est


def core_torque(est: ArmEstimate, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                offsets: bool) -> np.ndarray:
    """The core's Y_b(q, q̇, q̈) θ (the offsets zeroed unless ``offsets``), model order."""
    arm = load_arm("ur5").model
    theta = est.theta if offsets else np.where(
        [n.endswith(".off") for n in est.parameter_names], 0.0, est.theta)
    Y = base_parameters(arm).columns(regressor(arm, q[None], qd[None], qdd[None],
                                               est.coulomb_width))
    return (Y @ theta)[0]


#: Numbers the graphs of this process.
GRAPHS = itertools.count()


class Graph:
    """A model server (when given a file), an arm_feedforward_node and a probe in a namespace
    of their own, spun by the test."""

    def __init__(self, tag: str, model_file: Path | None, spin: Callable[..., bool],
                 **params: Any) -> None:
        os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        os.environ.setdefault("ROS_DOMAIN_ID", "94")
        # a namespace no earlier graph used: a server of an earlier test, destroyed in another
        # context, can stay on this one's graph until its lease ends
        self.ns = ns = f"/ff_{tag}_{os.getpid()}_{next(GRAPHS)}"
        self._spin = spin
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.ex = SingleThreadedExecutor(context=self.context)
        self.nodes: list[Any] = []
        if model_file is not None:
            self.nodes.append(ModelServerNode(context=self.context, cli_args=[
                "--ros-args", "-r", f"__ns:={ns}", "-p", f"model_file:={model_file}"]))
        self.ff = ArmFeedforwardNode(context=self.context, namespace=ns, parameter_overrides=[
            Parameter(k, value=v) for k, v in params.items()])
        self.probe = rclpy.create_node("probe", namespace=ns, context=self.context)
        self.nodes += [self.ff, self.probe]
        for n in self.nodes:
            self.ex.add_node(n)
        self.got: list[np.ndarray] = []
        self.probe.create_subscription(Float64MultiArray, "effort_feedforward",
                                       lambda m: self.got.append(np.array(m.data)),
                                       RELIABLE_QOS)
        self.pub = self.probe.create_publisher(JointState, "joint_reference", RELIABLE_QOS)

    def spin_until(self, done: Callable[[], bool], timeout: float = 10.0) -> bool:
        """Spin this graph until ``done()`` or ``timeout`` s (the ``spin_until`` fixture)."""
        return self._spin(self.ex, done, timeout)

    def send(self, t: float, names: list[str], q: np.ndarray, qd: np.ndarray) -> None:
        """Publish one reference; spin until the node has taken it."""
        seen = self.ff.rejected.counts.copy(), self.ff.commands, self.ff._previous
        msg = JointState(name=names, position=list(q), velocity=list(qd))
        msg.header.stamp = to_time(t)
        self.pub.publish(msg)
        assert self.spin_until(lambda: (self.ff.rejected.counts, self.ff.commands,
                                        self.ff._previous) != seen), "not taken"

    def close(self) -> None:
        self.ex.shutdown()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def served(tmp_path: Path, spin_until: Callable[..., bool]
           ) -> Iterator[tuple[Graph, ArmEstimate]]:
    est = ur5_model(tmp_path / "ur5.yaml")
    graph = Graph("served", tmp_path / "ur5.yaml", spin_until, timeout=0.5)
    try:
        assert graph.spin_until(lambda: graph.ff.client.available), graph.ff.client.errors
        yield graph, est
    finally:
        graph.close()


def test_published_torques_are_the_cores_regressor_times_theta_in_model_order(
        served: tuple[Graph, ArmEstimate]) -> None:
    graph, est = served
    names = [est.joint_names[i] for i in ORDER]
    q, qd, _ = random_states(6, 3, seed=5)
    graph.send(1.0, names, q[0][ORDER], qd[0][ORDER])  # starts the difference
    for k in (1, 2):  # the second after offsets:=true
        if k == 2:
            assert graph.ff.set_parameters([Parameter("offsets", value=True)])[0].successful
        graph.send(1.0 + k * DT, names, q[k][ORDER], qd[k][ORDER])
        assert graph.spin_until(lambda k=k: len(graph.got) == k)
        want = core_torque(est, q[k], qd[k], (qd[k] - qd[k - 1]) / DT, offsets=k == 2)
        np.testing.assert_allclose(graph.got[k - 1], want, rtol=0, atol=1e-9)
        assert np.abs(want).max() > 1.0  # a real torque, not a vanishing one
    assert graph.ff.commands == 2 and not any(graph.ff.rejected.counts.values())


def test_refused_references_are_counted_and_publish_nothing(
        served: tuple[Graph, ArmEstimate], capfd: pytest.CaptureFixture[str]) -> None:
    graph, est = served
    names = list(est.joint_names)
    q, qd, _ = random_states(6, 2, seed=6)
    graph.send(1.0, names, q[0], qd[0])
    graph.send(1.0 + DT, names[:5], q[1][:5], qd[1][:5])  # no wrist_3_joint
    graph.send(1.1, [*names[:5], "gripper_joint"], q[1], qd[1])
    graph.send(1.2, names, q[1], qd[1] * np.nan)
    graph.send(1.3, names, q[0], qd[0])  # starts a difference anew
    graph.send(1.3 - DT, names, q[1], qd[1])  # before its predecessor
    graph.send(1.4, names, q[1][:5], qd[1])  # five positions for six joints
    counts = graph.ff.rejected.counts
    assert counts == {"rejected_joints_joint_reference": 2, "rejected_fields_joint_reference": 1,
                      "rejected_stamp_joint_reference": 1,
                      "rejected_nonfinite_joint_reference": 1}
    graph.spin_until(lambda: False, 0.3)
    assert graph.got == [] and graph.ff.commands == 0
    err = capfd.readouterr().err
    assert "missing ['wrist_3_joint'], unknown []" in err
    assert "missing ['wrist_3_joint'], unknown ['gripper_joint']" not in err  # first only
    assert err.count("count.rejected_joints_joint_reference") == 1


def test_without_a_model_nothing_is_published_and_why_is_said_once(
        capfd: pytest.CaptureFixture[str], spin_until: Callable[..., bool]) -> None:
    graph = Graph("none", None, spin_until, model_node="no_such_server")
    try:
        names = list(graph.ff.names)
        q, qd, _ = random_states(6, 3, seed=7)
        for k in range(3):
            graph.send(1.0 + k * DT, names, q[k], qd[k])
        graph.spin_until(lambda: False, 0.3)
        assert graph.got == [] and graph.ff.commands == 0
        lines = [x for x in capfd.readouterr().err.splitlines() if "no arm model" in x]
        assert len(lines) == 1, lines
        # the nodes listed: this graph's probe, and any of an earlier test's graph that its
        # context's end has not yet taken off this one's
        head, nodes = lines[0].split(" (nodes there: ")
        assert head.endswith(f"no arm model, publishing nothing: no node {graph.ns}"
                             "/no_such_server on the graph of ROS_DOMAIN_ID "
                             f"{os.environ['ROS_DOMAIN_ID']}"), lines[0]
        assert f"{graph.ns}/probe" in nodes.split(")")[0].split(", ")
        assert nodes.endswith("); start model_server_node (serves a saved arm model file) or "
                              "arm_estimator_node (identifies the arm live)"), lines[0]
    finally:
        graph.close()


def test_a_lost_server_stops_the_feedforward_and_says_so_once(
        served: tuple[Graph, ArmEstimate], capfd: pytest.CaptureFixture[str]) -> None:
    graph, est = served
    names = list(est.joint_names)
    q, qd, _ = random_states(6, 4, seed=8)
    graph.send(1.0, names, q[0], qd[0])
    graph.send(1.0 + DT, names, q[1], qd[1])
    assert graph.spin_until(lambda: len(graph.got) == 1)
    server = graph.nodes[0]
    graph.ex.remove_node(server)
    server.destroy_node()
    assert graph.spin_until(lambda: graph.ff.client.lost)
    for k in (2, 3):
        graph.send(1.0 + k * DT, names, q[k], qd[k])
    graph.spin_until(lambda: False, 0.3)
    assert len(graph.got) == 1 and graph.ff.commands == 1
    lines = [x for x in capfd.readouterr().err.splitlines() if "no arm model" in x]
    assert len(lines) == 1 and lines[0].endswith(
        "no arm model, publishing nothing: model server model_server_node lost: not in the "
        "graph for 0.5 s; publishing resumes when it is back"), lines
