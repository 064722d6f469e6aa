"""sim_node, preprocess_node and estimator_node as separate processes (the colcon-installed
executables of the session's colcon_install, test/conftest.py) over DDS; this test process is
the client: it reads model.* with GetParameters (dampest_ros.client) and sets an invalid
forgetting factor."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from rcl_interfaces.srv import SetParameters  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from dampest_ros.client import ModelClient  # noqa: E402
from dampest_ros.io.yaml_io import load_vehicle  # noqa: E402

DOMAIN = "78"
SIM_SECONDS = 60.0
RATE = 3.0


@pytest.fixture(scope="module")
def processes(colcon_install: Path, tmp_path_factory: pytest.TempPathFactory,
              module_children: Any) -> Iterator[dict[str, object]]:
    site = next(colcon_install.glob("lib/python3*/site-packages"))
    env = dict(os.environ, ROS_DOMAIN_ID=DOMAIN, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               OPENBLAS_NUM_THREADS="1", PYTHONUNBUFFERED="1")
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(site), env.get("PYTHONPATH")) if p)
    exe = colcon_install / "lib" / "dampest_ros"
    logs = tmp_path_factory.mktemp("logs")
    cmds = {
        "sim_node": ["-p", f"rate_factor:={RATE}", "-p", f"duration:={SIM_SECONDS:.0f}",
                     "-p", "seed:=5"],
        "preprocess_node": [],
        "estimator_node": ["-p", "use_sim_time:=true", "-p", "forgetting_factor:=1.0",
                           "-p", "publish_rate:=1.0"],
    }
    procs = {}
    for name, args in reversed(cmds.items()):  # consumers first, the simulator last
        procs[name] = module_children.start([str(exe / name), "--ros-args", *args],
                                            log=logs / f"{name}.log", env=env)
        time.sleep(0.5 if name != "sim_node" else 0.0)
    os.environ["ROS_DOMAIN_ID"] = DOMAIN
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    context = rclpy.Context()
    rclpy.init(context=context)
    start = time.monotonic()
    probe = rclpy.create_node("test_multiprocess_probe", context=context)
    while (set(procs) - set(probe.get_node_names())) and time.monotonic() < start + 60.0:
        time.sleep(0.1)  # every node running (a signal before its interpreter runs kills it)
    probe.destroy_node()
    yield {"procs": procs, "logs": logs, "context": context, "start": start}
    for p in procs.values():
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    for p in procs.values():
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            module_children.kill(p)
    rclpy.try_shutdown(context=context)


@pytest.mark.slow
def test_client_reads_a_converged_model(processes: dict) -> None:
    context = processes["context"]
    node = rclpy.create_node("test_client", context=context)
    from rclpy.executors import SingleThreadedExecutor
    ex = SingleThreadedExecutor(context=context)
    ex.add_node(node)
    client = ModelClient(node, "estimator_node")
    # wait for the simulated run to end (sim time / rate) plus the pipeline's latency
    end = processes["start"] + SIM_SECONDS / RATE + 25.0
    first = None
    while time.monotonic() < end:
        ex.spin_once(timeout_sec=0.1)
        if client.available and first is None:
            first = client.version
        if client.available and client.version >= SIM_SECONDS - 12:
            break
    logs = {n: (processes["logs"] / f"{n}.log").read_text()[-2000:] for n in processes["procs"]}
    assert client.available, logs
    m = client.model
    v = load_vehicle("bluerov2_heavy")
    truth = dict(zip(v.damping.parameter_names, v.theta, strict=True))
    print(f"\nmodel version {m.version} (first seen {first})")
    for name, th, sd in zip(m.parameter_names, m.theta, m.theta_std, strict=True):
        print(f"{name:5s} {th:10.4f} ± {sd:.4f}  truth {truth[name]:.4f}")
    assert m.version >= SIM_SECONDS - 12, logs  # one publication per simulated second
    for name in ("X_uu", "Y_vv", "Z_ww", "K_pp", "N_rr"):
        assert m.value(name) == pytest.approx(truth[name], rel=0.05), name
    np.testing.assert_allclose(m.M, v.body.M)
    # the client follows the publications: a later version arrives by itself
    version = client.version
    end = time.monotonic() + 5.0
    while client.version == version and time.monotonic() < end:
        ex.spin_once(timeout_sec=0.1)
    # (after the simulation ended the estimator stops publishing new versions: either is fine)
    node.destroy_node()


def test_invalid_forgetting_factor_is_rejected(processes: dict) -> None:
    context = processes["context"]
    node = rclpy.create_node("test_setter", context=context)
    from rclpy.executors import SingleThreadedExecutor
    ex = SingleThreadedExecutor(context=context)
    ex.add_node(node)
    cli = node.create_client(SetParameters, "estimator_node/set_parameters")
    assert cli.wait_for_service(timeout_sec=20.0)
    future = cli.call_async(SetParameters.Request(parameters=[
        Parameter("forgetting_factor", value=1.5).to_parameter_msg()]))
    end = time.monotonic() + 10.0
    while not future.done() and time.monotonic() < end:
        ex.spin_once(timeout_sec=0.1)
    result = future.result().results[0]
    assert not result.successful
    print(f"\nrejected: {result.reason}")
    assert "forgetting_factor" in result.reason and "1.5" in result.reason
    node.destroy_node()


def test_nodes_stop_cleanly_on_sigint(processes: dict) -> None:
    procs = processes["procs"]
    for name, p in procs.items():
        assert p.poll() is None, f"{name} died: " + (processes["logs"] /
                                                      f"{name}.log").read_text()[-2000:]
    for p in procs.values():
        p.send_signal(signal.SIGINT)
    for name, p in procs.items():
        assert p.wait(timeout=15) == 0, name + ": " + (processes["logs"] / f"{name}.log"
                                                       ).read_text()[-2000:]
