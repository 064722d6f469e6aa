"""Plausibility of a log's frames: the common mistakes, caught before they become numbers.

A log in the wrong frames identifies without complaint and gives nonsense (a FLU/ENU log read
as FRD/NED gave a heave R² of −240). These checks look at the IMU series as ROS messages
should carry them (REP-103/105: body FLU, world ENU; ``linear_acceleration`` the specific
force, +g upwards at rest) and say, in one line each, what disagrees, in which topic and
field, and the likely cause:

- **gravity sign**: the specific force turned into the world by the orientation points up,
  |f| ≈ g at rest. Pointing down: an FRD accelerometer inside FLU messages (or −f logged);
  about zero: gravity removed (linear acceleration instead of specific force).
- **tilt**: at quasi-static samples (| |f| − g | < 0.1 g) the body's "up" from the
  orientation, Rᵀ e_z, and from the accelerometer, f / |f|, agree within 15°.
- **yaw rate**: the gyro's rate about the world's up axis, (R ω)_z, follows the derivative of
  the orientation's heading ψ = atan2(R₂₁, R₁₁); slope below −0.5: one of them is FRD/NED.
- **depth**: with a position (nav_msgs/Odometry) and a pressure sensor, z (ENU: up) falls
  as the pressure grows; rising with it: NED z inside an ENU message.
- **constant fields**: a field of a used topic that never changes over the log (all zeros:
  not filled). An IMU's all-zero gyro or accelerometer is not among them: the preprocessing
  replaces it and says so (:mod:`.sources`).

Nothing here changes data: the caller prints the lines (:func:`frame_notes`); the command
line refuses a log with a frame mistake unless told the frames are right.
:func:`unusable_samples` says why preprocessed samples cannot be compared with a model at all
(non-finite values, velocities or forces that never change).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.frames import quat_to_matrix
from dampest_ros.core.signals.measurements import (
    ImuSeries,
    OdometrySeries,
    PoseSeries,
    PressureSeries,
    Series,
    TwistSeries,
    WrenchSeries,
)
from dampest_ros.core.signals.samples import Samples

FloatArray = NDArray[np.float64]

#: Largest angle (deg) between the orientation's and the accelerometer's "up" at rest.
TILT_TOLERANCE = 15.0
#: RMS heading rate (rad/s) below which the yaw-rate check has nothing to compare.
MIN_HEADING_RATE = 0.02
#: Window (s) over which heading change and integrated yaw rate are compared.
YAW_WINDOW = 1.0


def gravity_note(topic: str, up_force: FloatArray, gravity: float) -> str | None:
    """The gravity-sign line for the specific force's world-up component, or None.

    Parameters
    ----------
    topic : str
    up_force : ndarray, shape (N,)
        (R f)_z, the specific force along the world's up axis (m/s²).
    gravity : float
        g (m/s²).
    """
    median = float(np.median(up_force))
    if median < -0.5 * gravity:
        return (f"{topic}: linear_acceleration points down in the world (median {median:.3g} "
                "m/s² along ENU up): an FRD accelerometer inside FLU messages, or −f logged; "
                "sensor_msgs/Imu carries the specific force, +g up at rest (REP-103)")
    if abs(median) < 0.2 * gravity:
        return (f"{topic}: linear_acceleration has no gravity (median {median:.3g} m/s² along "
                "ENU up): gravity removed by the driver; sensor_msgs/Imu carries the specific "
                "force, +g up at rest")
    return None


def tilt_note(topic: str, R: FloatArray, f: FloatArray, gravity: float) -> str | None:
    """The tilt line when orientation and accelerometer disagree about "up", or None.

    Parameters
    ----------
    topic : str
    R : ndarray, shape (N, 3, 3)
        Body (FLU) → world (ENU) rotations of the orientation.
    f : ndarray, shape (N, 3)
        Specific force in the body (m/s²).
    gravity : float
    """
    norm = np.linalg.norm(f, axis=1)
    still = np.abs(norm - gravity) < 0.1 * gravity
    if still.sum() < 10:
        return None
    up_q = R[still, 2, :]  # Rᵀ e_z: the world's up in body axes
    up_f = f[still] / norm[still, None]
    angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", up_q, up_f), -1.0, 1.0)))
    median = float(np.median(angle))
    if median <= TILT_TOLERANCE:
        return None
    return (f"{topic}: orientation and linear_acceleration disagree about the vertical by "
            f"{median:.0f}° (median over {int(still.sum())} samples at rest): the orientation "
            "is likely NED/FRD inside an ENU/FLU message, or the IMU's axes are not the "
            "body's (give its rpy in the vehicle file's sensors: section)")


def yaw_rate_note(topic: str, t: FloatArray, R: FloatArray, w: FloatArray) -> str | None:
    """The yaw-rate line when the gyro turns against the heading, or None.

    Compared over :data:`YAW_WINDOW` windows, where sensor noise has averaged out: the
    heading's change Δψ against the integral of the gyro's rate about the world's up axis,
    ∫(R ω)_z dt (equal to Δψ but for −∫φ̇ sin θ dt).

    Parameters
    ----------
    topic : str
    t : ndarray, shape (N,)
        Stamps (s), increasing.
    R : ndarray, shape (N, 3, 3)
        Body → world rotations.
    w : ndarray, shape (N, 3)
        Angular velocity in the body (rad/s).
    """
    if len(t) < 3 or np.any(np.diff(t) <= 0):
        return None
    heading = np.unwrap(np.arctan2(R[:, 1, 0], R[:, 0, 0]))
    up_rate = np.einsum("ij,ij->i", R[:, 2, :], w)  # (R ω)_z
    # ∫(R ω)_z dt by the trapezoid rule
    turned = np.concatenate([[0.0], np.cumsum(0.5 * (up_rate[1:] + up_rate[:-1])
                                              * np.diff(t))])
    at = np.searchsorted(t, np.arange(t[0], t[-1], YAW_WINDOW))
    d_heading, d_turned = np.diff(heading[at]), np.diff(turned[at])
    if d_heading.size < 5 or float(np.sqrt(np.mean(d_heading**2))) < (
            MIN_HEADING_RATE * YAW_WINDOW):
        return None
    # least-squares slope of the gyro's turn on the heading's change
    slope = float(np.dot(d_turned, d_heading) / np.dot(d_heading, d_heading))
    if slope >= -0.5:
        return None
    return (f"{topic}: angular_velocity turns against the orientation's heading (slope "
            f"{slope:.2f} of ∫(R ω)_z dt on Δψ over {YAW_WINDOW:g} s, 1 expected): the gyro "
            "is FRD inside FLU messages, or the orientation is NED")


#: The fields identification reads, per message type (others, such as a DVL's unfilled
#: angular velocity, may well be constant).
USED_FIELDS: dict[type[Series], tuple[str, ...]] = {
    ImuSeries: ("orientation", "angular_velocity", "linear_acceleration"),
    TwistSeries: ("linear",),
    PressureSeries: ("fluid_pressure",),
    WrenchSeries: ("force", "torque"),
    OdometrySeries: ("orientation", "linear"),
    PoseSeries: ("orientation",),
}
#: Fields whose all-zero values mean "no such sensor": the preprocessing substitutes them.
SUBSTITUTED_FIELDS: dict[type[Series], tuple[str, ...]] = {
    ImuSeries: ("angular_velocity", "linear_acceleration"),
}


#: Pressure spread (Pa, about 1 cm of water) below which depth and z are not compared.
MIN_PRESSURE_SPREAD = 100.0


def depth_note(pressure_topic: str, pressure: PressureSeries, odom_topic: str,
               odom: OdometrySeries) -> str | None:
    """The depth line when a position's z rises as the pressure grows, or None.

    In ENU, z is up: deeper water (more pressure) means a lower z, so the two correlate
    negatively; a correlation above +0.5 says the position is NED (down) in an ENU message.

    Parameters
    ----------
    pressure_topic, odom_topic : str
    pressure : PressureSeries
        Absolute pressure (Pa).
    odom : OdometrySeries
        Position (m, ENU).
    """
    if len(pressure) < 10 or len(odom) < 10 or np.ptp(pressure.fluid_pressure) < (
            MIN_PRESSURE_SPREAD) or np.any(np.diff(odom.stamp) <= 0):
        return None
    z = np.interp(pressure.stamp, odom.stamp, odom.position[:, 2])
    if np.ptp(z) == 0:
        return None
    corr = float(np.corrcoef(pressure.fluid_pressure, z)[0, 1])
    if not corr > 0.5:
        return None
    return (f"{odom_topic}: pose.position.z rises as the pressure on {pressure_topic} grows "
            f"(correlation {corr:+.2f}, −1 expected): z is NED (down) inside an ENU message")


def constant_notes(topic: str, series: Series) -> list[str]:
    """One line per used field (:data:`USED_FIELDS`) of ``series`` that does not change over
    the log, a vector field's columns named by index."""
    notes = []
    for name in USED_FIELDS.get(type(series), ()):
        values = getattr(series, name)
        if len(values) < 2 or (name in SUBSTITUTED_FIELDS.get(type(series), ())
                               and not np.any(values)):
            continue
        cols = values.reshape(len(values), -1)
        fixed = np.flatnonzero(np.ptp(cols, axis=0) == 0)
        if fixed.size == 0:
            continue
        where = name if cols.shape[1] == 1 else f"{name}[{', '.join(map(str, fixed))}]"
        zero = bool(np.all(cols[:, fixed] == 0))
        notes.append(f"{topic}: {where} is {'zero' if zero else 'constant'} in all "
                     f"{len(values)} messages: not filled by the driver, stuck, or never "
                     "excited; identification takes it as measured")
    return notes


@dataclass(frozen=True)
class FrameNotes:
    """What the checks found: ``errors``, frame mistakes that make identification wrong
    (gravity sign or gravity removed, tilt, yaw rate), and ``warnings``, fields that never
    change; one line each, naming topic and field."""

    errors: list[str]
    warnings: list[str]


def frame_notes(series: Mapping[str, Series], gravity: float) -> FrameNotes:
    """Every plausibility line for the topics a log feeds identification with.

    Parameters
    ----------
    series : mapping of str to Series
        Topic → its messages (ROS frames), e.g. the first minutes of each used topic.
    gravity : float
        g (m/s²).

    Returns
    -------
    FrameNotes
        Empty lists when nothing looks wrong.
    """
    errors: list[str] = []
    warnings: list[str] = []
    for topic, s in series.items():
        if len(s) == 0:
            continue
        constant = constant_notes(topic, s)
        warnings += constant
        if not isinstance(s, ImuSeries) or not np.any(s.linear_acceleration) or any(
                n.split(": ")[1].startswith(("orientation", "linear_acceleration"))
                for n in constant):
            continue
        R = quat_to_matrix(s.orientation[:, [3, 0, 1, 2]])  # [x, y, z, w] → [w, x, y, z]
        f = s.linear_acceleration
        gravity_line = gravity_note(topic, np.einsum("ij,ij->i", R[:, 2, :], f), gravity)
        tilt = None if gravity_line else tilt_note(topic, R, f, gravity)
        yaw = yaw_rate_note(topic, s.stamp, R, s.angular_velocity)
        errors += [n for n in (gravity_line, tilt, yaw) if n]
    pressures = [(t, s) for t, s in series.items() if isinstance(s, PressureSeries)]
    positions = [(t, s) for t, s in series.items() if isinstance(s, OdometrySeries)]
    for (pt, p), (ot, o) in ((a, b) for a in pressures for b in positions):
        line = depth_note(pt, p, ot, o)
        errors += [line] if line else []
    return FrameNotes(errors, warnings)


#: Quantities of a sample, as :func:`unusable_samples` names them, with the largest magnitude
#: any vehicle reaches (m/s and rad/s, m/s² and rad/s², N and N·m).
_QUANTITIES = (("velocity ν", "nu", "u v w p q r", 1e3),
               ("acceleration ν̇", "nu_dot", "u v w p q r", 1e5),
               ("force τ", "tau", "X Y Z K M N", 1e12))


def unusable_samples(samples: Samples) -> str | None:
    """Why ``samples`` cannot be compared with a model (None: they can): a velocity,
    acceleration or force that is not finite or beyond any vehicle's (the first named with
    its time: e.g. a 1e308 cell), or velocities or forces constant over the whole log (an
    all-zero log, columns never filled)."""
    for what, field, axes, limit in _QUANTITIES:
        values = getattr(samples, field)
        bad = ~(np.abs(values) <= limit)
        if bad.any():
            k, j = np.argwhere(bad)[0]
            return (f"{what} {axes.split()[j]} is {values[k, j]:.6g} at t = "
                    f"{samples.t[k]:.6g} s ({int(bad.any(axis=1).sum())} samples not finite "
                    f"or over {limit:g}): a damaged cell in the log? fix or drop those rows")
    for what, field, _, _ in (_QUANTITIES[0], _QUANTITIES[2]):
        values = getattr(samples, field)
        if len(values) and np.all(np.ptp(values, axis=0) == 0.0):
            return (f"{what} is constant over the whole log "
                    f"({np.round(values[0], 6).tolist()}): nothing moved, or the columns or "
                    "topics were never filled")
    return None
