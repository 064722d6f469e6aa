"""preprocess_node and sensor mounting: the node takes the vehicle file's sensors:
section, a DVL on geometry_msgs/TwistStamped (parameter dvl_type), and counts messages whose
header.frame_id is not the configured one (diagnostics frame_id_mismatch, one warning)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from dampest_ros.core.online.preprocessor import OnlinePreprocessor
from dampest_ros.core.signals.measurements import TwistSeries
from dampest_ros.core.simulation.excitation import make_excitation
from dampest_ros.core.simulation.sensors import measure
from dampest_ros.core.simulation.simulate import run
from dampest_ros.io.cdr import stamps_to_ns
from dampest_ros.io.yaml_io import load_vehicle, vehicle_path

rclpy = pytest.importorskip("rclpy")

SENSORS = {"dvl": {"frame_id": "dvl_link", "position": [0.3, 0.0, 0.15]},
           "imu": {"position": [0.1, -0.05, 0.05], "rpy": [0.0, 0.2, 1.5707963267948966]}}


def test_node_with_mounting_twist_stamped_dvl_and_foreign_frame_ids(tmp_path: Path) -> None:
    """30 s of a mounted BlueROV2 Heavy fed to the node's raw callbacks, the DVL serialized as
    TwistStamped with the frame_id 'dvl': the samples equal OnlinePreprocessor.run on the same
    recording (mounting applied, same vehicle file) to the last bit, and every DVL message is
    counted as frame_id_mismatch, reported in the diagnostics and warned about once."""
    from geometry_msgs.msg import TwistStamped
    from rclpy.parameter import Parameter
    from rclpy.serialization import serialize_message

    from dampest_ros.ros.common import to_time
    from dampest_ros.ros.convert import header_frame_id, publications
    from dampest_ros.ros.preprocess_node import PreprocessNode

    doc = yaml.safe_load(vehicle_path("bluerov2_heavy").read_text())
    doc["sensors"] = SENSORS
    path = tmp_path / "mounted.yaml"
    path.write_text(yaml.safe_dump(doc))
    vehicle = load_vehicle(path)
    g, rho = vehicle.body.gravity, vehicle.body.rho
    traj = run(vehicle, make_excitation("B", vehicle, 30.0, seed=2))
    rec = measure(traj, rho, g, seed=2, mounting=vehicle.mounting)
    del rec["truth/odom"]
    for s in rec.values():  # stamps as a message carries them (whole ns), as a bag gives them
        s.stamp = stamps_to_ns(s.stamp) / 1e9
    dvl = rec["dvl/twist"]
    assert isinstance(dvl, TwistSeries)
    # what the node must reproduce: the DVL without a covariance (as TwistStamped carries)
    want_rec = dict(rec)
    want_rec["dvl/twist"] = TwistSeries(dvl.stamp, "dvl", dvl.linear, dvl.angular)
    want_pre = OnlinePreprocessor(vehicle.thrusters, g, rho, mounting=vehicle.mounting)
    want = want_pre.run(want_rec)
    assert sum(s.usable for s in want) > 1000

    def twist_stamped(i: int) -> Any:
        m = TwistStamped()
        m.header.stamp = to_time(float(dvl.stamp[i]))
        m.header.frame_id = "dvl"
        (m.twist.linear.x, m.twist.linear.y, m.twist.linear.z) = dvl.linear[i].tolist()
        return m

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=86)
    try:
        node = PreprocessNode(context=ctx, parameter_overrides=[
            Parameter("vehicle", value=str(path)), Parameter("dvl_type", value="TwistStamped")])
        got: list = []
        node._publish = got.extend  # type: ignore[method-assign,assignment]
        feed = {"imu/data": node._on_imu, "pressure": node._on_pressure}
        k = 0
        for topic, msg in publications(rec):
            if topic == "dvl/twist":
                data = serialize_message(twist_stamped(k))
                assert header_frame_id(data) == "dvl"
                node._on_dvl_twist(data)
                k += 1
            elif topic == "thrusters/state":
                node._on_thrusters(msg)
            else:
                feed[topic](serialize_message(msg))
        node._process(node.order.flush())
        assert k == len(dvl)
        assert node.pre.counts == want_pre.counts
        assert node.pre.counts["frame_id_mismatch"] == len(dvl)
        assert len(got) == len(want)
        for a, b in zip(got, want, strict=True):
            assert a.t == b.t and a.usable == b.usable
            np.testing.assert_array_equal(a.nu, b.nu)
            np.testing.assert_array_equal(a.depth, b.depth)
        published: list = []
        node.pub_diag.publish = published.append  # type: ignore[method-assign,assignment]
        node._publish_diagnostics()
        values = {kv.key: kv.value for kv in published[0].status[0].values}
        assert values["frame_id_mismatch"] == str(len(dvl))
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
