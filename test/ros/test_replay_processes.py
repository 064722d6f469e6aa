"""A bag replayed through separate processes, as launch/replay.launch.py runs it: ``dampest
replay BAG --clock`` plays the sensor topics, preprocess_node and estimator_node (λ = 1) run
on its /clock. When the bag ends /clock stops; what the nodes hold then (the stamp-order
window, samples not yet in a publication) must still reach model.*: two replays give the same
model.* as each other and as ``dampest identify BAG --method rls --forgetting-factor 1``, and
every message is counted on the way (played = heard, samples published = matched = used).

Runs on its own ROS_DOMAIN_ID, localhost only; this test process reads model.* with
GetParameters (dampest_ros.client.ModelClient) and the counts on /diagnostics.
"""

from __future__ import annotations

import re
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402

from dampest_ros.cli.main import main  # noqa: E402
from dampest_ros.client import ModelClient  # noqa: E402
from dampest_ros.io.bag import bag_summary  # noqa: E402
from dampest_ros.io.yaml_io import load_model  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
BAG = REPO / "bags" / "sample"
DOMAIN = "59"
#: bag seconds per wall second (30 s of bag in 15 s)
RATE = 2.0
ROLES = {"imu/data": "imu", "dvl/twist": "dvl", "pressure": "pressure",
         "thrusters/state": "thrusters"}
CLI = "import sys; from dampest_ros.cli.main import main; sys.exit(main(sys.argv[1:]))"
#: the agreement asked, max |Δθ_i| / max(|θ_i|, σ_i), as in test_one_code_path (reached:
#: about 1e-9, the rounding of RLS updates taken in differently cut chunks)
TOLERANCE = 1e-6


class Listener:
    """A node of this process on the test domain (``base``, a ``domain_node``): model.* of
    estimator_node and the last /diagnostics values of each status."""

    def __init__(self, base: Any) -> None:
        self.base = base
        self.node, self.executor = base.node, base.executor
        self.client = ModelClient(self.node, "estimator_node")
        self.status: dict[str, dict[str, str]] = {}
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, 100)

    def _on_diag(self, msg: DiagnosticArray) -> None:
        for s in msg.status:
            self.status[s.name.split(":")[0]] = {kv.key: kv.value for kv in s.values}

    def count(self, node: str, key: str) -> int:
        return int(float(self.status.get(node, {}).get(key, -1)))

    def spin_until(self, done: Callable[[], bool], timeout: float) -> bool:
        end = time.monotonic() + timeout
        while not done():
            if time.monotonic() > end:
                return False
            self.executor.spin_once(timeout_sec=0.05)
        return True

    def close(self) -> None:
        self.client.close()
        self.base.close()


def replay(children: Any, domain_node: Any, tmp: Path) -> dict[str, Any]:
    """One replay of :data:`BAG` through fresh nodes: model.*, counts and logs.

    The replay waits a second after its publishers have matched the preprocessor: the
    sensor topics are best effort, and the subscriber's side of the match may come later
    (its first messages were lost so, 0.6 s of bag in one run of five without the delay).
    """
    tmp.mkdir()
    common = ["-p", "use_sim_time:=true"]
    nodes = {"preprocess_node": common,
             "estimator_node": [*common, "-p", "forgetting_factor:=1.0", "-p",
                                "resume:=false", "-p", f"save_path:={tmp / 'model.yaml'}"]}
    for name, args in nodes.items():
        children.start([sys.executable, "-m", f"dampest_ros.ros.{name}", "--ros-args", *args],
                       log=tmp / f"{name}.log", env=children.ros_env(DOMAIN))
    ros = Listener(domain_node(DOMAIN, "replay_processes_test"))
    try:
        play = children.run([sys.executable, "-c", CLI, "replay", str(BAG), "--clock",
                             "--rate", str(RATE), "--topics", *ROLES,
                             "--wait-for-subscribers-timeout", "60", "--delay", "1"],
                            timeout=180, env=children.ros_env(DOMAIN), capture_output=True,
                            text=True)

        def logs() -> dict[str, str]:
            return {n: (tmp / f"{n}.log").read_text() for n in nodes}

        assert play.returncode == 0, (play.stderr, logs())
        published = re.search(r"finished: published (\d+)/(\d+)", play.stderr)
        assert published is not None, play.stderr
        # the end of the bag reaches model.*: every message played is heard, every sample
        # published is matched, and model.* is that of the last one (no publication timer
        # runs on the stopped /clock)
        played = int(published[1])
        delivered = ros.spin_until(lambda: (
            ros.client.available
            and sum(ros.count("preprocess_node", r) for r in ROLES.values()) == played
            and ros.count("estimator_node", "count.matched")
            == ros.count("preprocess_node", "published")
            and ros.client.version == ros.count("estimator_node", "model.version")), 30.0)
        assert delivered, f"{ros.status}\n{play.stderr}\n{logs()}"
        m = ros.client.model
        return {"theta": m.theta, "std": m.theta_std, "names": list(m.parameter_names),
                "played": played, "total": int(published[2]),
                "pre": ros.status["preprocess_node"], "est": ros.status["estimator_node"],
                "samples": ros.count("estimator_node", "samples"), "version": m.version}
    finally:
        ros.close()
        children.close()


def distance(theta: Any, ref: Any, std: Any) -> tuple[float, float]:
    """max |Δθ_i| / max(|θ_i|, σ_i) and max |Δθ_i| / |θ_i| of ``theta`` from ``ref`` (σ
    the standard deviations of ``ref``)."""
    dt = np.abs(np.asarray(theta) - np.asarray(ref))
    return (float(np.max(dt / np.maximum(np.abs(ref), std))),
            float(np.max(dt / np.abs(ref))))


@pytest.mark.slow
def test_two_replays_through_processes_equal_offline_rls(children: Any, domain_node: Any,
                                                         tmp_path: Path) -> None:
    out = tmp_path / "offline.yaml"
    assert main(["identify", str(BAG), "--vehicle", "bluerov2_heavy", "--method", "rls",
                 "--forgetting-factor", "1", "--out", str(out)]) == 0
    offline = load_model(out)
    runs = [replay(children, domain_node, tmp_path / f"run{k}") for k in (1, 2)]
    in_bag = {t.lstrip("/"): s.count for t, s in bag_summary(BAG).topics.items()}
    for run in runs:
        # every sensor message played was heard, every sample published was matched, and
        # used as offline (the first ones fill the regression filter)
        assert run["played"] == run["total"] == sum(in_bag[t] for t in ROLES)
        assert {r: int(run["pre"][r]) for r in ROLES.values()} == {
            r: in_bag[t] for t, r in ROLES.items()}
        published = int(run["pre"]["published"])
        assert int(run["est"]["count.matched"]) == published
        assert int(run["est"]["count.lost_in_transport"]) == 0
        assert run["samples"] == int(run["est"]["count.used"]) == offline.extra["samples"]
        assert run["names"] == offline.parameter_names
    x_u = offline.parameter_names.index("X_u")
    for k, run in enumerate(runs, 1):
        dist, plain = distance(run["theta"], offline.theta, offline.theta_std)
        print(f"\nreplay {k}: X_u {run['theta'][x_u]:.6f} (offline {offline.theta[x_u]:.6f}), "
              f"max |Δθ|/max(|θ|, σ) = {dist:.1e}, max |Δθ|/|θ| = {plain:.1e}, "
              f"{run['samples']} samples, model version {run['version']}")
        assert dist <= TOLERANCE
    # the two replays: the RLS takes the samples in chunks cut at its publications, whose
    # times differ from run to run; the rounding differs in the last digits (1e-9 relative
    # seen on coefficients near zero, 1e-12 on the others)
    dist, plain = distance(runs[1]["theta"], runs[0]["theta"], runs[0]["std"])
    print(f"replay 2 vs 1: max |Δθ|/max(|θ|, σ) = {dist:.1e}, max |Δθ|/|θ| = {plain:.1e}")
    assert dist <= TOLERANCE
