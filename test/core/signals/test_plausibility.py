"""Frame plausibility (dampest_ros.core.signals.plausibility): silent on clean logs of both
simulators, one line naming topic and field for each common frame mistake."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dampest_ros.core.signals.measurements import ImuSeries, OdometrySeries, Series
from dampest_ros.core.signals.plausibility import FrameNotes, frame_notes
from dampest_ros.core.simulation.excitation import make_excitation
from dampest_ros.core.simulation.sensors import measure
from dampest_ros.core.simulation.simulate import run
from dampest_ros.io.yaml_io import load_vehicle

G = 9.81


@pytest.fixture(scope="module", params=[("bluerov2_heavy", "native"),
                                        ("torpedo_auv", "mujoco")], ids=["native", "mujoco"])
def recording(request: pytest.FixtureRequest) -> dict[str, Series]:
    """60 s of protocol B with the default sensor noise (the MuJoCo torpedo: physics we did
    not write)."""
    name, backend = request.param
    v = load_vehicle(name)
    traj = run(v, make_excitation("B", v, 60.0, seed=1), backend=backend)
    return measure(traj, v.body.rho, v.body.gravity, seed=1)


def imu(recording: dict[str, Series]) -> ImuSeries:
    s = recording["imu/data"]
    assert isinstance(s, ImuSeries)
    return s


def test_a_clean_log_gives_no_line(recording: dict[str, Series]) -> None:
    assert frame_notes(recording, G) == FrameNotes([], [])


def test_an_frd_accelerometer_in_flu_messages_is_named(recording: dict[str, Series]) -> None:
    s = imu(recording)
    bad = replace(s, linear_acceleration=s.linear_acceleration * [1.0, -1.0, -1.0])
    (line,) = frame_notes({"imu/data": bad}, G).errors
    assert line.startswith("imu/data: linear_acceleration points down in the world (median -9.")
    assert "FRD accelerometer inside FLU messages" in line


def test_gravity_removed_is_named(recording: dict[str, Series]) -> None:
    s = imu(recording)
    R_up = np.array([0.0, 0.0, G])
    level = replace(s, linear_acceleration=s.linear_acceleration - R_up)  # near level
    (line,) = frame_notes({"imu/data": level}, G).errors
    assert "has no gravity" in line


def test_an_frd_gyro_in_flu_messages_is_named(recording: dict[str, Series]) -> None:
    s = imu(recording)
    bad = replace(s, angular_velocity=s.angular_velocity * [1.0, -1.0, -1.0])
    (line,) = frame_notes({"imu/data": bad}, G).errors
    assert line.startswith("imu/data: angular_velocity turns against the orientation's heading")
    slope = float(line.split("(slope ")[1].split()[0])
    assert -1.1 < slope < -0.8  # measured -0.94 (native), -0.96 (MuJoCo)


def test_an_ned_orientation_in_an_enu_message_is_named(recording: dict[str, Series]) -> None:
    """The FRD→NED quaternion where FLU→ENU belongs: for a near-level vehicle the vertical
    agrees, the heading runs backwards."""
    s = imu(recording)
    bad = replace(s, orientation=s.orientation * [1.0, -1.0, -1.0, 1.0])
    lines = frame_notes({"imu/data": bad}, G).errors
    assert any("turns against the orientation's heading" in line for line in lines), lines


def test_a_field_never_filled_is_named(recording: dict[str, Series]) -> None:
    dvl = recording["dvl/twist"]
    empty = replace(dvl, linear=np.zeros_like(dvl.linear))
    (line,) = frame_notes({"dvl/twist": empty}, G).warnings
    assert line.startswith(f"dvl/twist: linear[0, 1, 2] is zero in all {len(dvl)} messages")
    frozen = replace(dvl, linear=dvl.linear * [1.0, 1.0, 0.0] + [0.0, 0.0, 0.3])
    (line,) = frame_notes({"dvl/twist": frozen}, G).warnings
    assert line.startswith("dvl/twist: linear[2] is constant")


@pytest.mark.parametrize("field", ["angular_velocity", "linear_acceleration"])
def test_an_imu_without_gyro_or_accelerometer_gives_no_line(recording: dict[str, Series],
                                                              field: str) -> None:
    # all zero: no such sensor, which the preprocessing replaces and names (signals.sources)
    s = imu(recording)
    empty = replace(s, **{field: np.zeros_like(getattr(s, field))})
    assert frame_notes({"imu/data": empty}, G) == FrameNotes([], [])


def test_a_ned_position_in_an_enu_message_is_named(recording: dict[str, Series]) -> None:
    """z that rises with the pressure: NED inside ENU (the clean log's z falls with it)."""
    odom, pressure = recording["truth/odom"], recording["pressure"]
    assert isinstance(odom, OdometrySeries)
    clean = frame_notes({"truth/odom": odom, "pressure": pressure}, G)
    assert clean.errors == []
    ned = replace(odom, position=odom.position * [1.0, 1.0, -1.0])
    (line,) = frame_notes({"truth/odom": ned, "pressure": pressure}, G).errors
    assert line.startswith("truth/odom: pose.position.z rises as the pressure on pressure grows")
    assert "NED (down) inside an ENU message" in line
