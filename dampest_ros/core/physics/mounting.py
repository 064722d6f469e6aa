"""Sensor mounting: where the IMU, the DVL and the pressure sensor sit on the vehicle, and the
rigid-body kinematics between a sensor's point and axes and the body origin.

The vehicle file's optional ``sensors:`` section (``docs/architecture.md §4``)::

    sensors:
      imu: {frame_id: imu_link, position: [x, y, z], rpy: [roll, pitch, yaw]}
      dvl: {frame_id: dvl_link, position: [x, y, z], rpy: [roll, pitch, yaw]}
      pressure: {frame_id: pressure_link, position: [x, y, z]}

Positions are metres from the body origin in the vehicle file's body frame, Fossen's FRD (the
frame of the thruster positions and r_g, r_b). ``rpy`` (rad) are the ZYX Euler angles of the
sensor's axes in that FRD frame: R_bs = Rz(yaw) Ry(pitch) Rx(roll) takes a vector in the
sensor's axes to the body's. A sensor's message holds FLU vectors of its own frame
(REP-103), converted to the sensor's FRD axes by :mod:`dampest_ros.core.physics.frames` like any
body vector. (A URDF joint of the same sensor, written in FLU, has xyz = (x, −y, −z) and
rpy = (roll, −pitch, −yaw).) Defaults: every sensor at the origin, aligned with the body,
frame ids ``imu_link``, ``dvl_link``, ``pressure_link``.

With ω, ω̇ the body rates (FRD), r a sensor's position and R its R_bs:

- DVL: the velocity of its point, in its axes: v_s = R_bsᵀ (v + ω × r); so
  v = R_bs v_s − ω × r.
- IMU: gyro ω_s = R_bsᵀ ω; accelerometer, the specific force of its point:
  f_s = R_bsᵀ (f + ω̇ × r + ω × (ω × r)); its orientation is that of its axes,
  R_ns = R_nb R_bs.
- Pressure: the depth of its point, z_s = z + (R_nb r)_z (NED).

The preprocessing (offline and online) and the simulator use these functions, one direction
each, so the two can never disagree.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.frames import cross, matrix_from_euler
from dampest_ros.core.physics.rigid_body import ConfigError

FloatArray = NDArray[np.float64]

#: frame_id of each sensor's messages when the vehicle file does not give one.
DEFAULT_FRAME_IDS: dict[str, str] = {"imu": "imu_link", "dvl": "dvl_link",
                                     "pressure": "pressure_link"}

_ORIGIN = (0.0, 0.0, 0.0)


def _three(where: str, value: Any) -> tuple[float, float, float]:
    """Three finite numbers, or ConfigError naming ``where``."""
    try:
        v = tuple(float(x) for x in value)
    except (TypeError, ValueError):
        raise ConfigError(where, f"must be 3 numbers, got {value!r}") from None
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise ConfigError(where, f"must be 3 finite numbers, got {value!r}")
    return v[0], v[1], v[2]


@dataclass(frozen=True)
class SensorMount:
    """Where one sensor sits.

    Attributes
    ----------
    frame_id : str
        The ``header.frame_id`` its messages carry.
    position : tuple of 3 float
        Its point from the body origin (m, FRD).
    rpy : tuple of 3 float
        ZYX Euler angles (rad) of its axes in the body frame (FRD).
    declared : bool
        Whether the vehicle file gives ``frame_id``: only then is a message of another
        frame_id a mistake worth a warning (:meth:`foreign`); the usual log stamps every
        sensor ``base_link``, and a vehicle file without a ``sensors:`` section says nothing
        about it.
    """

    frame_id: str
    position: tuple[float, float, float] = _ORIGIN
    rpy: tuple[float, float, float] = _ORIGIN
    declared: bool = field(default=False, compare=False)

    def foreign(self, frame_id: str) -> bool:
        """True when the vehicle file declares this sensor's frame_id and ``frame_id`` is
        another one."""
        return self.declared and frame_id != self.frame_id

    @cached_property
    def rotation(self) -> FloatArray:
        """R_bs, shape (3, 3): sensor axes (FRD) → body axes (FRD); computed once (the
        online preprocessing asks for it per message)."""
        return matrix_from_euler(np.asarray(self.rpy))

    @cached_property
    def lever(self) -> FloatArray:
        """The position r, shape (3,) (m, FRD)."""
        return np.asarray(self.position, dtype=float)

    @property
    def centred(self) -> bool:
        """True when the sensor sits at the body origin."""
        return self.position == _ORIGIN

    @property
    def aligned(self) -> bool:
        """True when the sensor's axes are the body's."""
        return self.rpy == _ORIGIN

    @classmethod
    def from_dict(cls, name: str, d: Any, angles: bool = True) -> SensorMount:
        """From ``{frame_id, position, rpy}``; ConfigError names ``sensors.<name>.<key>``."""
        where = f"sensors.{name}"
        if d is None:
            d = {}
        if not isinstance(d, Mapping):
            raise ConfigError(where, f"must be a mapping (frame_id, position{', rpy' * angles})"
                                     f", got {d!r}")
        known = {"frame_id", "position"} | ({"rpy"} if angles else set())
        unknown = sorted(set(map(str, d)) - known)
        if unknown:
            raise ConfigError(f"{where}.{unknown[0]}", f"unknown key; known: {sorted(known)}")
        frame_id = d.get("frame_id", DEFAULT_FRAME_IDS[name])
        if not isinstance(frame_id, str) or not frame_id:
            raise ConfigError(f"{where}.frame_id", f"must be a non-empty string, got "
                                                   f"{frame_id!r}")
        return cls(frame_id, _three(f"{where}.position", d.get("position", _ORIGIN)),
                   _three(f"{where}.rpy", d.get("rpy", _ORIGIN)), declared="frame_id" in d)


@dataclass(frozen=True)
class Mounting:
    """The mounting of the IMU, the DVL and the pressure sensor (defaults: all at the origin,
    aligned, the default frame ids)."""

    imu: SensorMount = field(default_factory=lambda: SensorMount(DEFAULT_FRAME_IDS["imu"]))
    dvl: SensorMount = field(default_factory=lambda: SensorMount(DEFAULT_FRAME_IDS["dvl"]))
    pressure: SensorMount = field(
        default_factory=lambda: SensorMount(DEFAULT_FRAME_IDS["pressure"]))

    @classmethod
    def from_dict(cls, d: Any) -> Mounting:
        """From a vehicle file's ``sensors:`` mapping (None: the defaults).

        Raises
        ------
        ConfigError
            Naming the field (``sensors.dvl.position`` …): not a mapping, an unknown key,
            not 3 finite numbers, an empty frame_id.
        """
        if d is None:
            return cls()
        if not isinstance(d, Mapping):
            raise ConfigError("sensors", f"must be a mapping with imu, dvl, pressure, got {d!r}")
        unknown = sorted(set(map(str, d)) - set(DEFAULT_FRAME_IDS))
        if unknown:
            raise ConfigError(f"sensors.{unknown[0]}", "unknown sensor; known: "
                                                       f"{sorted(DEFAULT_FRAME_IDS)}")
        return cls(SensorMount.from_dict("imu", d.get("imu")),
                   SensorMount.from_dict("dvl", d.get("dvl")),
                   SensorMount.from_dict("pressure", d.get("pressure"), angles=False))


# --- kinematics (vectorised over the leading axes) ---------------------------------------------


def lever_velocity(omega: FloatArray, r: FloatArray) -> FloatArray:
    """ω × r: the velocity of a point r relative to the origin (m/s, FRD).

    Parameters
    ----------
    omega : ndarray, shape (..., 3)
        Body rates (rad/s, FRD).
    r : ndarray, shape (3,)
        Point (m, FRD).
    """
    return cross(omega, r)


def lever_acceleration(omega: FloatArray, omega_dot: FloatArray, r: FloatArray) -> FloatArray:
    """ω̇ × r + ω × (ω × r): tangential and centripetal acceleration of a point r relative
    to the origin (m/s², FRD).

    Parameters
    ----------
    omega, omega_dot : ndarray, shape (..., 3)
        Body rates (rad/s) and their derivative (rad/s²), FRD.
    r : ndarray, shape (3,)
    """
    return cross(omega_dot, r) + cross(omega, cross(omega, r))


def rotate(R: FloatArray, v: FloatArray) -> FloatArray:
    """R v for a fixed matrix R (3, 3) and vectors v (..., 3)."""
    return np.asarray(v, dtype=float) @ R.T


def dvl_to_body(mount: SensorMount, v_sensor: FloatArray, omega: FloatArray) -> FloatArray:
    """Body-origin velocity from a DVL's: v = R_bs v_s − ω × r.

    Parameters
    ----------
    mount : SensorMount
    v_sensor : ndarray, shape (..., 3)
        DVL velocity in its axes (m/s, FRD).
    omega : ndarray, shape (..., 3)
        Body rates at the same instants (rad/s, FRD).

    Returns
    -------
    ndarray, shape (..., 3)
        m/s, FRD.
    """
    v = rotate(mount.rotation, v_sensor)
    return v if mount.centred else v - lever_velocity(omega, mount.lever)


def imu_to_body(mount: SensorMount, R_ns: FloatArray, omega_s: FloatArray, f_s: FloatArray
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """An IMU's attitude, rates and specific force turned to the body axes.

    The specific force stays that of the IMU's point; :func:`specific_force_at_origin`
    moves it to the origin once ω̇ is known.

    Parameters
    ----------
    mount : SensorMount
    R_ns : ndarray, shape (..., 3, 3)
        IMU axes (FRD) → NED.
    omega_s, f_s : ndarray, shape (..., 3)
        Gyro (rad/s) and specific force (m/s²) in the IMU's axes (FRD).

    Returns
    -------
    R_nb : ndarray, shape (..., 3, 3)
        Body → NED, R_ns R_bsᵀ.
    omega : ndarray, shape (..., 3)
        R_bs ω_s.
    f_point : ndarray, shape (..., 3)
        R_bs f_s (body axes, at the IMU's point).
    """
    if mount.aligned:
        return R_ns, omega_s, f_s
    R = mount.rotation
    return R_ns @ R.T, rotate(R, omega_s), rotate(R, f_s)


def specific_force_at_origin(mount: SensorMount, f_point: FloatArray, omega: FloatArray,
                             omega_dot: FloatArray) -> FloatArray:
    """Specific force of the origin from that of the IMU's point (both body axes):
    f = f_p − ω̇ × r − ω × (ω × r).

    Parameters
    ----------
    mount : SensorMount
    f_point, omega, omega_dot : ndarray, shape (..., 3)
        m/s², rad/s, rad/s² (FRD).
    """
    if mount.centred:
        return f_point
    return f_point - lever_acceleration(omega, omega_dot, mount.lever)


def depth_offset(mount: SensorMount, R_nb: FloatArray) -> FloatArray:
    """(R_nb r)_z: how much deeper the sensor's point is than the origin (m, NED).

    Parameters
    ----------
    mount : SensorMount
    R_nb : ndarray, shape (..., 3, 3)
        Body → NED.

    Returns
    -------
    ndarray, shape (...)
    """
    # the third row of R_nb dotted with r
    return np.asarray(R_nb[..., 2, :] @ mount.lever, dtype=float)


def frame_id_note(topic: str, count: int, found: str, expected: str) -> str:
    """The one warning line for ``count`` messages of ``topic`` whose frame_id is not the
    configured one."""
    return (f"{topic}: {count} message(s) with header.frame_id {found!r}, expected "
            f"{expected!r} (the sensors: section of the vehicle file); used with the "
            "configured mounting")
