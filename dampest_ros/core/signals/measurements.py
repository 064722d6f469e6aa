"""Column-wise containers for time series of sensor messages, in ROS frames (REP-103/105).

These are what the simulator's sensor models produce, what bags and CSV files are read into
and written from, and what the preprocessing consumes. One instance holds one topic; arrays
are stacked over messages (axis 0). Stamps are seconds (float64) on the bag/sim clock.

Frames: body vectors are FLU (``base_link``), world vectors ENU (``odom``); quaternions are
stored [x, y, z, w] as in geometry_msgs/Quaternion.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def _rows(*arrays: FloatArray) -> int:
    n = {a.shape[0] for a in arrays}
    if len(n) != 1:
        raise ValueError(f"arrays disagree in length: {sorted(n)}")
    return n.pop()


@dataclass
class Series:
    """Base: a stamped series. Subclasses add array fields of length N on axis 0."""

    stamp: FloatArray
    frame_id: str = ""

    def __len__(self) -> int:
        return int(self.stamp.shape[0])

    def arrays(self) -> dict[str, FloatArray]:
        """All array fields (including ``stamp``) by name."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if isinstance(getattr(self, f.name), np.ndarray)}

    def per_message(self) -> dict[str, FloatArray]:
        """The array fields with one row per message: all but the shared ``*covariance``."""
        return {k: a for k, a in self.arrays().items() if not k.endswith("covariance")}

    def select(self, mask: NDArray[np.bool_] | NDArray[np.int64]) -> Series:
        """A copy keeping the rows in ``mask`` (boolean or index array)."""
        kw = {f.name: getattr(self, f.name) for f in fields(self)}
        for name, arr in self.per_message().items():
            if arr.ndim >= 1 and arr.shape[0] == len(self):
                kw[name] = arr[mask]
        return type(self)(**kw)

    def validate(self) -> None:
        """Raise ValueError if the array lengths disagree."""
        _rows(*[a for a in self.per_message().values() if a.ndim >= 1 and a.shape[0] != 0]
              or [self.stamp])


@dataclass
class ImuSeries(Series):
    """sensor_msgs/Imu: orientation (N, 4) xyzw, angular_velocity (N, 3) rad/s FLU,
    linear_acceleration (N, 3) m/s² FLU (specific force: reads +g on z at rest), and the
    three 9-element row-major covariances (shared by all messages)."""

    orientation: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    angular_velocity: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    linear_acceleration: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    orientation_covariance: FloatArray = field(default_factory=lambda: np.zeros(9))
    angular_velocity_covariance: FloatArray = field(default_factory=lambda: np.zeros(9))
    linear_acceleration_covariance: FloatArray = field(default_factory=lambda: np.zeros(9))


@dataclass
class TwistSeries(Series):
    """geometry_msgs/TwistWithCovarianceStamped: linear (N, 3) m/s, angular (N, 3) rad/s,
    covariance (36,) row-major (shared)."""

    linear: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    angular: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    covariance: FloatArray = field(default_factory=lambda: np.zeros(36))


@dataclass
class PressureSeries(Series):
    """sensor_msgs/FluidPressure: fluid_pressure (N,) Pa (absolute), variance (shared)."""

    fluid_pressure: FloatArray = field(default_factory=lambda: np.zeros(0))
    variance: float = 0.0


@dataclass
class JointSeries(Series):
    """sensor_msgs/JointState: names, velocity (N, n), effort (N, n) and position (N, n)
    or (N, 0). Thrusters: velocity rotor speed rad/s, effort thrust N, no position. Arm
    joints: position rad, velocity rad/s, effort N m."""

    names: tuple[str, ...] = ()
    velocity: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    effort: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    position: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))

    def __post_init__(self) -> None:
        if self.position.size == 0:  # no positions: (N, 0), one empty row per message
            self.position = np.zeros((len(self.stamp), 0))


@dataclass
class OdometrySeries(Series):
    """nav_msgs/Odometry: position (N, 3) ENU m, orientation (N, 4) xyzw FLU→ENU,
    linear (N, 3) and angular (N, 3) body-frame FLU velocity; child frame ``base_link``."""

    child_frame_id: str = "base_link"
    position: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    orientation: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    linear: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    angular: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))


@dataclass
class PoseSeries(Series):
    """geometry_msgs/PoseStamped: position (N, 3) m and orientation (N, 4) xyzw of the body
    (``base_link``, FLU) in the header's world frame (ENU)."""

    position: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    orientation: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))


@dataclass
class WrenchSeries(Series):
    """geometry_msgs/WrenchStamped: force (N, 3) N, torque (N, 3) N·m, FLU."""

    force: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    torque: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))


@dataclass
class AccelSeries(Series):
    """geometry_msgs/AccelWithCovarianceStamped: linear (N, 3) m/s², angular (N, 3)
    rad/s², covariance (36,) (shared), FLU."""

    linear: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    angular: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    covariance: FloatArray = field(default_factory=lambda: np.zeros(36))


#: Default topic names (relative) and their series class, from the topic contract.
TOPIC_TYPES: dict[str, tuple[str, type[Series]]] = {
    "truth/odom": ("nav_msgs/msg/Odometry", OdometrySeries),
    "imu/data": ("sensor_msgs/msg/Imu", ImuSeries),
    "dvl/twist": ("geometry_msgs/msg/TwistWithCovarianceStamped", TwistSeries),
    "pressure": ("sensor_msgs/msg/FluidPressure", PressureSeries),
    "thrusters/state": ("sensor_msgs/msg/JointState", JointSeries),
    "truth/hydro_wrench": ("geometry_msgs/msg/WrenchStamped", WrenchSeries),
    "dampest/velocity": ("geometry_msgs/msg/TwistWithCovarianceStamped", TwistSeries),
    "dampest/acceleration": ("geometry_msgs/msg/AccelWithCovarianceStamped", AccelSeries),
    "dampest/wrench": ("geometry_msgs/msg/WrenchStamped", WrenchSeries),
    # optional input: the body wrench of a vehicle that logs τ instead of thruster telemetry
    "wrench": ("geometry_msgs/msg/WrenchStamped", WrenchSeries),
}

#: A recording: topic name → series.
Recording = dict[str, Series]


def stamp_order(stamps: Sequence[FloatArray]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The rows of several stamp arrays (one per topic) merged into one stamp order.

    Parameters
    ----------
    stamps : sequence of ndarray, shapes (n_k,)
        Stamps (s) of each topic.

    Returns
    -------
    which, row : ndarray, shape (Σ n_k,)
        Array index and row of every stamp, by stamp; equal stamps keep the order of
        ``stamps``.
    """
    sizes = [len(s) for s in stamps]
    which = np.repeat(np.arange(len(sizes), dtype=np.int64), sizes)
    row = np.concatenate([np.arange(n, dtype=np.int64) for n in sizes] or
                         [np.zeros(0, dtype=np.int64)])
    t = np.concatenate([np.asarray(s, dtype=float) for s in stamps] or [np.zeros(0)])
    order = np.argsort(t, kind="stable")
    return which[order], row[order]
