"""Node faults: bad parameters at start and at runtime, two nodes of one name, the
estimator's drop counters, resume from the saved model, orphaned temporary files, SIGINT and
SIGTERM. Every case asserts the exit status, the line logged, the counter or the value kept.

In-process nodes run on ROS_DOMAIN_ID 81 (localhost only); node processes as well."""

from __future__ import annotations

import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip("rclpy")

from rclpy.parameter import Parameter  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from dampest_ros.core.identification.model import Model  # noqa: E402
from dampest_ros.io.yaml_io import load_model, load_vehicle, save_model  # noqa: E402
from dampest_ros.ros.arm_feedforward_node import ArmFeedforwardNode  # noqa: E402
from dampest_ros.ros.common import (  # noqa: E402
    DIAGNOSTICS_TOPIC,
    DUPLICATE_WINDOW,
    ParamNode,
)
from dampest_ros.ros.controller_node import ControllerNode  # noqa: E402
from dampest_ros.ros.estimator_node import EstimatorNode  # noqa: E402
from dampest_ros.ros.model_server_node import ModelServerNode  # noqa: E402
from dampest_ros.ros.preprocess_node import PreprocessNode  # noqa: E402
from dampest_ros.ros.recorder_node import RecorderNode  # noqa: E402
from dampest_ros.ros.replay_node import ReplayNode  # noqa: E402
from dampest_ros.ros.sim_node import SimNode  # noqa: E402

DOMAIN = "81"
NODES: dict[str, type[ParamNode]] = {
    c.NODE_NAME: c for c in (SimNode, PreprocessNode, EstimatorNode, ControllerNode,
                             ArmFeedforwardNode, ModelServerNode, RecorderNode, ReplayNode)}




@pytest.fixture
def model_file(tmp_path: Path) -> Path:
    """The BlueROV2 Heavy's nominal damping as a model file (version 4)."""
    v = load_vehicle("bluerov2_heavy")
    return save_model(tmp_path / "nominal.yaml", Model(v.damping.parameter_names, v.theta,
                                                       0.1 * np.abs(v.theta) + 0.01, v.body.M,
                                                       damping=v.damping, version=4))


def needed(name: str, tmp_path: Path, sim_bag: Path, model_file: Path) -> dict[str, Any]:
    """The parameters a node needs to start (files in ``tmp_path``)."""
    need: dict[str, dict[str, Any]] = {
        "estimator_node": {"save_path": str(tmp_path / "est.yaml"), "resume": False},
        "model_server_node": {"model_file": str(model_file)},
        "recorder_node": {"output": str(tmp_path / "bag")},
        "replay_node": {"bag": str(sim_bag)}}
    return need.get(name, {})


def start(children: Any, name: str, params: dict[str, Any], log: Path, *extra: str
          ) -> subprocess.Popen[bytes]:
    """A node process of the ``children`` fixture (its output in ``log``)."""
    args = [a for k, v in params.items() for a in ("-p", f"{k}:={v}")]
    return children.start([sys.executable, "-m", f"dampest_ros.ros.{name}", "--ros-args",
                           *args, *extra], log=log, env=children.ros_env(DOMAIN))


def on_graph(node: tuple[str, str], monkeypatch: pytest.MonkeyPatch, timeout: float = 60.0
             ) -> None:
    """Wait until ``node`` (name, namespace) is on DOMAIN's graph (localhost)."""
    monkeypatch.setenv("ROS_DOMAIN_ID", DOMAIN)
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = rclpy.Context()
    rclpy.init(context=context)
    probe = rclpy.create_node("test_node_faults_probe", context=context)
    try:
        end = time.monotonic() + timeout
        while node not in probe.get_node_names_and_namespaces():
            assert time.monotonic() < end, f"{node} not on the graph within {timeout} s"
            time.sleep(0.1)
    finally:
        probe.destroy_node()
        rclpy.shutdown(context=context)


# --- bad parameters ----------------------------------------------------------------------------

START_CASES = [
    # (node, parameter, value, the reason logged); the first two were rclpy tracebacks
    ("estimator_node", "forgetting_factor", "1.5",
     "forgetting_factor must be in [0.9, 1.0], got 1.5"),
    ("estimator_node", "chunk", "2.5", "chunk must be an integer, got 2.5"),
    ("estimator_node", "vehicle", "nope", "vehicle: no vehicle preset 'nope'; presets: "),
    ("sim_node", "duration", "1e7", "duration must be in [1.0, 1000000.0], got 10000000.0"),
    ("sim_node", "protocol", "Z", "protocol must be one of "),
    ("preprocess_node", "settle", "-1.0", "settle must be in [0.0, 60.0], got -1.0"),
    ("controller_node", "reference", "[1.0,0.0]",
     "reference needs 6 finite numbers (u, v, w, p, q, r), got [1.0, 0.0]"),
    ("arm_feedforward_node", "arm", "nope",
     "arm: arm 'nope' is neither a preset (ur5) nor an existing .urdf file"),
    ("arm_feedforward_node", "timeout", "0.0", "timeout must be in [0.1, 60.0], got 0.0"),
    ("recorder_node", "topics", "imu", "topics must be a list, e.g. [a, b], got 'imu'"),
    ("replay_node", "rate", "0", "rate must be in [0.01, 1000.0], got 0"),
    ("model_server_node", "model_file", "/nonexistent.yaml",
     "model_file: [Errno 2] No such file or directory: '/nonexistent.yaml'"),
]


@pytest.mark.parametrize(("name", "param", "value", "reason"), START_CASES,
                         ids=[f"{c[0]}-{c[1]}" for c in START_CASES])
def test_bad_parameter_at_start_is_one_logged_line_and_status_2(
        name: str, param: str, value: str, reason: str, tmp_path: Path, sim_bag: Path,
        model_file: Path, capfd: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Was: a traceback and status 1 (rclpy's InvalidParameterValueException for an
    out-of-range double, InvalidParameterTypeException for 2.5 given to an integer)."""
    monkeypatch.setenv("ROS_DOMAIN_ID", DOMAIN)
    module = __import__(f"dampest_ros.ros.{name}", fromlist=["main"])
    params = {**needed(name, tmp_path, sim_bag, model_file), param: value}
    argv = [name, "--ros-args", *[a for k, v in params.items() for a in ("-p", f"{k}:={v}")]]
    with pytest.raises(SystemExit) as done:
        module.main(argv)
    assert done.value.code == 2
    lines = [x for x in capfd.readouterr().err.splitlines() if x.strip()]
    assert len(lines) == 1, lines
    m = re.fullmatch(rf"\[ERROR\] \[[0-9.]+\] \[{name}\]: cannot start: parameter (.*)",
                     lines[0])
    assert m is not None and m.group(1).startswith(reason), lines[0]


def test_bad_parameter_at_start_exits_2_as_a_process(tmp_path: Path, children: Any) -> None:
    """The same as the installed executable runs: exit status 2, one line, no traceback."""
    proc = start(children, "estimator_node", {"forgetting_factor": "1.5"}, tmp_path / "log")
    assert proc.wait(timeout=60) == 2
    out = (tmp_path / "log").read_text()
    assert "Traceback" not in out and len(out.strip().splitlines()) == 1, out
    assert out.strip().endswith("cannot start: parameter forgetting_factor must be in [0.9, "
                                "1.0], got 1.5")


def test_every_ranged_and_choice_parameter_is_rejected_at_runtime_with_its_reason(
        context: Any, tmp_path: Path, sim_bag: Path, model_file: Path) -> None:
    """Every node, every parameter with a range (a value above it) or choices (one not
    among them): the set fails with a reason naming the parameter, the value stays."""
    tried = 0
    for name, cls in NODES.items():
        overrides = [Parameter(k, value=v)
                     for k, v in needed(name, tmp_path, sim_bag, model_file).items()]
        node = cls(context=context, parameter_overrides=overrides)  # type: ignore[call-arg]
        try:
            for spec in cls.PARAMS:  # type: ignore[attr-defined]
                if spec.high is not None and not isinstance(spec.default, bool):
                    bad: Any = (int(spec.high) + 1 if isinstance(spec.default, int)
                                else 2.0 * spec.high + 1.0)
                elif spec.choices:
                    bad = "not_a_choice"
                else:
                    continue
                before = node.get_parameter(spec.name).value
                result = node.set_parameters([Parameter(spec.name, value=bad)])[0]
                assert not result.successful, (name, spec.name)
                if spec.read_only:
                    assert result.reason == f"Trying to set a read-only parameter: {spec.name}."
                elif spec.choices:
                    assert result.reason.startswith(f"{spec.name} must be one of "), result
                else:  # rclpy's range check (doubles) or ours (integers)
                    assert re.match(rf"(Parameter )?{spec.name} (must be in|out of range)",
                                    result.reason), result.reason
                assert node.get_parameter(spec.name).value == before
                tried += 1
        finally:
            node.destroy_node()
    assert tried == 44  # every ranged or choice parameter of the eight nodes


# --- two nodes of one name -----------------------------------------------------------------


def test_a_second_node_of_the_same_name_is_refused(tmp_path: Path, children: Any,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """Was: no warning; a client alternated between two estimators' models. The one that
    starts second logs one line and exits 2; the first runs on and stops cleanly."""
    first = start(children, "controller_node", {}, tmp_path / "first.log", "-r", "__ns:=/dup81")
    try:
        # the first on the graph and past its own watch (a loaded machine takes seconds to
        # start it; a second started inside the first's window makes both refuse)
        on_graph(("controller_node", "/dup81"), monkeypatch)
        time.sleep(DUPLICATE_WINDOW + 0.5)
        second = start(children, "controller_node", {}, tmp_path / "second.log", "-r",
                       "__ns:=/dup81")
        assert second.wait(timeout=60) == 2
        out = (tmp_path / "second.log").read_text().strip()
        assert out.endswith(
            "[controller_node]: cannot start: another node named /dup81/controller_node is "
            "running (two would both answer its services and parameters); stop it, or give "
            "this one another name or namespace: --ros-args -r __node:=NAME or -r "
            "__ns:=/NAMESPACE"), out
        assert len(out.splitlines()) == 1 and first.poll() is None
    finally:
        assert children.stop(first) == 0
    assert "Traceback" not in (tmp_path / "first.log").read_text()


# --- estimator: counters, resume, temporary files --------------------------------------------


def feed(est: EstimatorNode, stamps_ms: list[int], skip: dict[str, list[int]] | None = None,
         nan: dict[str, list[int]] | None = None) -> None:
    """Complete samples at ``stamps_ms`` (FLU), minus the streams ``skip`` names, with NaN in
    those ``nan`` names."""
    rng = np.random.default_rng(1)
    for ms in stamps_ms:
        for stream in ("velocity", "acceleration", "wrench", "attitude"):
            if ms in (skip or {}).get(stream, []):
                continue
            value = np.array([0.0, 0.0, 0.0, 1.0]) if stream == "attitude" else \
                rng.normal(0.0, 0.1, 6)
            if ms in (nan or {}).get(stream, []):
                value[0] = math.nan
            est._on_sample(stream, ms * 1_000_000, value)


def test_estimator_publishes_every_drop_counter_on_absolute_diagnostics(
        context: Any, tmp_path: Path) -> None:
    """Was: out-of-order and duplicate samples dropped with no published counter, on a
    relative 'diagnostics' topic (invisible to the aggregator when namespaced)."""
    est = EstimatorNode(context=context, cli_args=["--ros-args", "-r", "__ns:=/fault81"],
                        parameter_overrides=[Parameter("save_path", value=str(tmp_path / "m")),
                                             Parameter("resume", value=False)])
    sent: list[Any] = []
    est.pub_diag.publish = sent.append  # type: ignore[method-assign,assignment]
    try:
        only_velocity = {"acceleration": [11900, 9020], "wrench": [11900, 9020],
                         "attitude": [11900, 9020]}
        feed(est, list(range(10000, 12000, 20)))             # 100 samples at 50 Hz
        feed(est, [11900], skip=only_velocity)                # a duplicate, out of order
        feed(est, [12000], nan={"wrench": [12000]})           # 12000 never completes
        feed(est, [12020])                                    # so 12000 is unmatched
        feed(est, [9020], skip=only_velocity)                 # the clock jumps back 3 s
        est._publish()
        assert est.pub_diag.topic_name == DIAGNOSTICS_TOPIC == "/diagnostics"
        (status,) = sent[-1].status
        assert status.hardware_id == "/fault81/estimator_node"
        values = {kv.key: kv.value for kv in status.values}
        counts = {k[6:]: int(v) for k, v in values.items() if k.startswith("count.")}
        # used: the samples past the regression's 1 s of settling, 11.00 to 11.98 s (12.02 s
        # follows a gap and settles anew)
        assert counts == {"velocity": 104, "acceleration": 102, "wrench": 102,
                          "attitude": 102, "matched": 101, "unmatched": 1,
                          "rejected_nonfinite": 1, "used": 50, "dropped_out_of_order": 1,
                          "rejected_outliers": 0, "clock_jumps": 1, "resume_refused": 0,
                          "lost_in_transport": 0}
        assert values["resume"] == "off"
    finally:
        est.destroy_node()


def estimator(context: Any, save: Path, **params: Any) -> EstimatorNode:
    return EstimatorNode(context=context, parameter_overrides=[
        Parameter("save_path", value=str(save)),
        *[Parameter(k, value=v) for k, v in params.items()]])


def diagnostics(est: EstimatorNode) -> dict[str, str]:
    sent: list[Any] = []
    est.pub_diag.publish = sent.append  # type: ignore[method-assign,assignment]
    est._publish()
    return {kv.key: kv.value for kv in sent[-1].status[0].values}


def test_estimator_resumes_from_its_saved_model_with_its_version(context: Any,
                                                                  tmp_path: Path) -> None:
    """Was: a restart began from the prior at version 1. A file of another vehicle or other
    terms, or with a NaN, is refused with the reason, counted, and the prior used."""
    save = tmp_path / "model.yaml"
    est = estimator(context, save)
    try:
        assert diagnostics(est)["resume"] == f"no model file at {save}"
        feed(est, list(range(20, 2020, 20)))
        for _ in range(2):
            est._publish(force=True)
        res = est._srv_save(Trigger.Request(), Trigger.Response())
        assert res.success and est.version == 3, res.message
        saved = load_model(save)
    finally:
        est.destroy_node()
    assert saved.version == 3
    est = estimator(context, save)
    try:
        assert est.version == 3
        np.testing.assert_array_equal(est.estimator.prior_theta, saved.theta)
        np.testing.assert_array_equal(est.estimator.prior_std, saved.theta_std)
        values = diagnostics(est)
        assert values["resume"] == f"version 3 from {save}"
        assert values["count.resume_refused"] == "0" and est.version == 4
    finally:
        est.destroy_node()
    nominal = load_vehicle("bluerov2_heavy")
    bad = tmp_path / "nan.yaml"
    doc = yaml.safe_load(save.read_text())
    doc["/**"]["ros__parameters"]["model"]["theta"][0] = math.nan
    bad.write_text(yaml.safe_dump(doc))
    cases = [
        (save, {"terms": "linear"}, "its coefficients are not those of vehicle bluerov2_heavy "
         "with terms 'linear' (missing [], not estimated here ['X_uu', "),
        (save, {"vehicle": "bluerov2_heavy_mujoco"}, f"{save} belongs to vehicle_damping "
         "'bluerov2_heavy' ("),
        (bad, {}, "model.theta: not finite: X_u = nan"),
    ]
    for path, params, reason in cases:
        est = estimator(context, path, **params)
        try:
            values = diagnostics(est)
            assert values["resume"].startswith(f"refused {path}: "), values["resume"]
            assert reason in values["resume"], values["resume"]
            assert values["count.resume_refused"] == "1" and est.version == 1
            if not params:
                np.testing.assert_array_equal(est.estimator.prior_theta, nominal.theta)
        finally:
            est.destroy_node()
    est = estimator(context, save, resume=False)
    try:
        assert est.version == 0 and diagnostics(est)["resume"] == "off"
    finally:
        est.destroy_node()


def test_estimator_removes_temporary_files_of_a_killed_save(context: Any,
                                                            tmp_path: Path) -> None:
    """Was: SIGKILL during ~/save left .tmp files. A minute-old one is removed at start; a
    younger one (another process may be writing it) is kept."""
    save = tmp_path / "model.yaml"
    old, young = tmp_path / ".model.yaml.k1l2.tmp", tmp_path / ".model.yaml.w3r4.tmp"
    for f in (old, young):
        f.write_text("partial")
    os.utime(old, (time.time() - 120, time.time() - 120))
    est = estimator(context, save)
    est.destroy_node()
    assert sorted(p.name for p in tmp_path.iterdir()) == [young.name]


# --- SIGINT and SIGTERM ------------------------------------------------------------------------


INT_FIRST = ("sim_node", "estimator_node", "recorder_node", "model_server_node")


@pytest.mark.parametrize("swapped", [False, pytest.param(True, marks=pytest.mark.slow)],
                         ids=["int-first", "term-first"])
def test_every_node_stops_cleanly_on_sigint_and_sigterm_while_busy(
        swapped: bool, tmp_path: Path, sim_bag: Path, model_file: Path, children: Any
) -> None:
    """Was: 'RCLError: publisher's context is invalid', status 1 (sim_node,
    preprocess_node). The eight nodes run together (sim at 20x real time, replay at 5x); four
    get SIGINT, four SIGTERM at once (the other way round in the slow case), and each ends
    with status 0 and no traceback (arm_feedforward_node waits for an arm model that never
    comes)."""
    ns = f"/sig{int(swapped)}_81"
    params: dict[str, dict[str, Any]] = {
        "sim_node": {"rate_factor": "20.0"}, "preprocess_node": {},
        "estimator_node": {"save_path": str(tmp_path / "est.yaml"), "publish_rate": "10.0"},
        "controller_node": {}, "model_server_node": {"model_file": str(model_file)},
        "arm_feedforward_node": {"model_node": "arm_estimator_node"},
        "recorder_node": {"output": str(tmp_path / "bag"), "topics": "[all]"},
        "replay_node": {"bag": str(sim_bag), "rate": "5.0", "loop": "true",
                        "remap": "['/truth/odom:=/replayed']"}}
    procs = {n: start(children, n, p, tmp_path / f"{n}.log", "-r", f"__ns:={ns}")
             for n, p in params.items()}
    logs = {n: tmp_path / f"{n}.log" for n in procs}
    end = time.monotonic() + 60.0  # busy: the estimator has published a model
    while time.monotonic() < end and "protocol" not in logs["sim_node"].read_text():
        time.sleep(0.2)
    time.sleep(2.0)
    for n, p in procs.items():
        p.send_signal(signal.SIGINT if (n in INT_FIRST) != swapped else signal.SIGTERM)
    codes = {n: children.stop(p, sig=None, timeout=60) for n, p in procs.items()}
    texts = {n: f.read_text() for n, f in logs.items()}
    assert codes == dict.fromkeys(procs, 0), texts
    # Fast DDS's own log lines ("[RTPS_TRANSPORT_SHM Error] Failed init_port ...: its
    # shared-memory port lock timed out with eight participants starting at once on two
    # cores; it falls back to UDP) are the middleware's, not a failure of the node's
    bad = {n: [line for line in t.splitlines() if ("Traceback" in line or "Error" in line)
               and "[RTPS_" not in line] for n, t in texts.items()}
    assert not any(bad.values()), {n: lines for n, lines in bad.items() if lines}
    assert "closed " in texts["recorder_node"]  # the bag was closed, not left for reindex


# --- sim_node memory -------------------------------------------------------------------------


def container_sizes(root: Any, depth: int = 4) -> dict[str, int]:
    """Length of every list, tuple, dict, set and deque and size of every array reachable
    from ``root`` through the attributes of dampest_ros objects (``depth`` steps)."""
    import collections

    out: dict[str, int] = {}
    seen: set[int] = set()

    def walk(obj: Any, path: str, d: int) -> None:
        if id(obj) in seen or d > depth:
            return
        seen.add(id(obj))
        if isinstance(obj, np.ndarray):
            out[path] = obj.size
            return
        if isinstance(obj, list | tuple | dict | set | collections.deque):
            out[path] = len(obj)
            items = obj.items() if isinstance(obj, dict) else enumerate(obj) \
                if not isinstance(obj, set) and len(obj) < 50 else []
            for k, v in items:
                walk(v, f"{path}[{k}]", d + 1)
        elif type(obj).__module__.startswith("dampest_ros") and hasattr(obj, "__dict__"):
            for k, v in vars(obj).items():
                walk(v, f"{path}.{k}", d + 1)

    walk(root, "node", 0)
    return out


def test_sim_node_holds_no_growing_container(context: Any) -> None:
    """Was: memory growing with the run. Between 10 s and 40 s of simulation, no list,
    dict, deque or array of the node, its simulation, plant and sensor stream changes size
    (79 of them; flown 1000x real time, 2 s of simulation per tick). The protocol is
    generated block by block (dampest_ros.core.simulation.excitation; its held bytes are tested
    against the duration in test/core/simulation/test_excitation.py)."""
    sim = SimNode(context=context, parameter_overrides=[
        Parameter("rate_factor", value=1000.0), Parameter("max_lag", value=2.0),
        Parameter("duration", value=600.0), Parameter("publish_clock", value=False)])
    try:
        while sim.live.t < 10.0:
            sim._tick()
        before = container_sizes(sim)
        while sim.live.t < 40.0:
            sim._tick()
        after = container_sizes(sim)
        assert sum(sim.counts.values()) > 9000  # what was published meanwhile
    finally:
        sim.destroy_node()
    assert len(before) > 50 and after == before


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_while_a_node_is_still_starting_ends_it_quietly(sig: int, children: Any
                                                                  ) -> None:
    """Was: a Ctrl-C 0.3 s after the start, while the node still imported scipy, ended it with
    a KeyboardInterrupt traceback and status −2 (the console-script entry now catches it)."""
    code = "from dampest_ros.ros.entry import sim_node; sim_node()"
    proc = children.start([sys.executable, "-c", code], stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True)
    time.sleep(0.3)
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err[-2000:]
    assert "Traceback" not in out + err


def test_an_integer_for_a_double_parameter_is_that_double(context: Any) -> None:
    """'-p gain:=2' and 'ros2 param set … gain 3' set 2.0 and 3.0: the parameter stays a
    double (it became an integer, and a later 2.5 was then refused)."""
    from dampest_ros.ros.common import Param

    specs = [Param("gain", 1.5, "a gain", low=0.0, high=10.0),
             Param("axis", [1.0, 0.0, 0.0], "an axis")]
    node = ParamNode("double_probe", specs, context=context, parameter_overrides=[
        Parameter("gain", value=2), Parameter("axis", value=[0, 1, 0])])
    try:
        gain = node.get_parameter("gain")
        assert gain.type_ == Parameter.Type.DOUBLE and gain.value == 2.0
        assert node.get_parameter("axis").value == [0.0, 1.0, 0.0]
        for value in (3, 2.5):
            (result,) = node.set_parameters([Parameter("gain", value=value)])
            assert result.successful, result.reason
            gain = node.get_parameter("gain")
            assert gain.type_ == Parameter.Type.DOUBLE and gain.value == float(value)
        (result,) = node.set_parameters([Parameter("gain", value=11)])
        assert not result.successful and "range" in result.reason and "11" in result.reason
    finally:
        node.destroy_node()
