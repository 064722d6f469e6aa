"""Fixed-layout CDR encoding and decoding of the measurement series, vectorised with numpy.

ROS 2 serialises a message as XCDR1 ("plain CDR"), here little endian: the 4-byte
encapsulation header ``00 01 00 00``, then the fields in declaration order, each primitive
aligned to its own size counted from the first byte after the header. A string is a uint32
length (including the terminating NUL) followed by its bytes and the NUL; a sequence is a
uint32 count followed by its elements (an empty sequence adds no alignment).

Within one series every message has the same frame_id (and child_frame_id, joint names and
counts), so every message has the same byte layout. One numpy structured dtype, built once
per series with explicit padding fields, describes it, and N messages are one array of shape
(N,): encoding fills the array column by column and slices its buffer into N messages;
decoding joins N messages and reads them with ``np.frombuffer``. When the layouts differ
(a frame_id that changes, varying trailing padding, a big-endian message) :func:`decode` falls
back to rosbags' deserialiser, one message at a time.

Stamps are float64 seconds in the series and (int32 sec, uint32 nanosec) in the messages,
rounded to the nearest nanosecond (:func:`stamps_to_ros`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
from numpy.typing import NDArray
from rosbags.typesys import Stores, get_typestore

from dampest_ros.core.signals.measurements import (
    AccelSeries,
    FloatArray,
    ImuSeries,
    JointSeries,
    OdometrySeries,
    PoseSeries,
    PressureSeries,
    Series,
    TwistSeries,
    WrenchSeries,
)

#: Series class → ROS 2 message type it is encoded as.
MESSAGE_TYPES: dict[type[Series], str] = {
    ImuSeries: "sensor_msgs/msg/Imu",
    TwistSeries: "geometry_msgs/msg/TwistWithCovarianceStamped",
    AccelSeries: "geometry_msgs/msg/AccelWithCovarianceStamped",
    PressureSeries: "sensor_msgs/msg/FluidPressure",
    WrenchSeries: "geometry_msgs/msg/WrenchStamped",
    OdometrySeries: "nav_msgs/msg/Odometry",
    JointSeries: "sensor_msgs/msg/JointState",
    PoseSeries: "geometry_msgs/msg/PoseStamped",
}
#: ROS 2 message type → series class it decodes to; a DVL may also send a TwistStamped
#: (decoded to a TwistSeries with a zero covariance: none given).
SERIES_CLASSES: dict[str, type[Series]] = {t: c for c, t in MESSAGE_TYPES.items()}
SERIES_CLASSES["geometry_msgs/msg/TwistStamped"] = TwistSeries

_CDR_LE = b"\x00\x01\x00\x00"
_SEC, _NSEC = "header.stamp.sec", "header.stamp.nanosec"
_NS_PER_S = 1_000_000_000


#: Serialized messages: one bytes-like each, or the rows of a (N,) void array when they
#: are all of one length (as a bag's chunks are read, :mod:`dampest_ros.io.mcap_check`).
Messages = Sequence[bytes | memoryview] | NDArray[np.void]


def join(parts: Sequence[Messages]) -> Messages:
    """Messages of several parts, in order: one void array when all are of one length."""
    arrays = [p for p in parts if isinstance(p, np.ndarray)]
    if len(arrays) == len(parts) and len({p.dtype for p in arrays}) == 1:
        return np.concatenate(arrays)
    return [bytes(m) for p in parts for m in p]


class LayoutError(ValueError):
    """The messages do not share one fixed layout of their message type."""


def message_type(series: Series) -> str:
    """The ROS 2 message type a series is encoded as, e.g. ``sensor_msgs/msg/Imu``."""
    try:
        return MESSAGE_TYPES[type(series)]
    except KeyError:
        raise TypeError(f"no message type for {type(series).__name__}") from None


def series_class(msgtype: str) -> type[Series]:
    """The series class a ROS 2 message type decodes to."""
    try:
        return SERIES_CLASSES[msgtype]
    except KeyError:
        raise TypeError(f"unsupported message type {msgtype!r}; "
                        f"supported: {sorted(SERIES_CLASSES)}") from None


# --- stamps --------------------------------------------------------------------------------


def stamps_to_ros(t: FloatArray) -> tuple[NDArray[np.int32], NDArray[np.uint32]]:
    """Split stamps into builtin_interfaces/Time fields, rounded to the nearest nanosecond.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Stamps (s), finite, within the int32 range of seconds.

    Returns
    -------
    sec : ndarray of int32, shape (N,)
        Whole seconds, floor(t) (or one more when the fraction rounds up to 1 s).
    nanosec : ndarray of uint32, shape (N,)
        Nanoseconds in [0, 1e9).
    """
    t = np.asarray(t, dtype=float)
    if not np.all(np.isfinite(t)):
        raise ValueError("stamps must be finite")
    sec = np.floor(t)
    # t - floor(t) is exact in float64, so the only rounding is that of the product
    ns = np.round((t - sec) * 1e9)
    carry = ns >= 1e9
    sec += carry
    ns[carry] = 0.0
    if sec.size and (sec.min() < -(2**31) or sec.max() >= 2**31):
        raise ValueError("stamps outside the int32 range of builtin_interfaces/Time")
    return sec.astype(np.int32), ns.astype(np.uint32)


def stamps_from_ros(sec: NDArray[np.integer[Any]], nanosec: NDArray[np.integer[Any]]
                    ) -> FloatArray:
    """Stamps (s) from builtin_interfaces/Time fields, the inverse of :func:`stamps_to_ros`.

    Parameters
    ----------
    sec, nanosec : ndarray of int, shape (N,)

    Returns
    -------
    ndarray, shape (N,)
        The float64 nearest to ``sec + nanosec / 1e9`` (exactly so below 2**53 ns, about
        104 days; within one rounding above, where float64 spacing exceeds 1 ns anyway).
    """
    total = np.asarray(sec, dtype=np.int64) * _NS_PER_S + np.asarray(nanosec, dtype=np.int64)
    exact = np.abs(total) < 2**53
    return np.where(exact, total / 1e9, sec + nanosec / 1e9)


def stamps_to_ns(t: FloatArray) -> NDArray[np.int64]:
    """Stamps (s) as int64 nanoseconds, rounded exactly as in the message headers.

    Parameters
    ----------
    t : ndarray, shape (N,)

    Returns
    -------
    ndarray of int64, shape (N,)
    """
    sec, ns = stamps_to_ros(t)
    return sec.astype(np.int64) * _NS_PER_S + ns


# --- layouts -------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Field:
    """A data field of a message layout.

    ``name`` is the ROS field path (also the dtype field name), ``attr`` the series attribute
    ("" when the series does not keep it), ``kind`` one of ``row`` (one value per message),
    ``shared`` (one value per series, taken from the first message), ``unused`` (encoded as
    zeros, ignored when decoding), ``string`` and ``strings`` (constant per layout), and
    ``parts`` the component names of a geometry message (``xyz``, ``xyzw``).
    """

    name: str
    attr: str
    kind: str
    parts: str = ""


class _Builder:
    """Walks a message definition and lays it out as a structured dtype.

    Strings and sequence counts come from ``series`` when encoding, or are read from the
    serialized message ``first`` when decoding.
    """

    def __init__(self, series: Series | None = None, first: bytes | None = None) -> None:
        self.series, self.first = series, first
        self.items: list[tuple[str, str, tuple[int, ...]]] = [("cdr_header", "u1", (4,))]
        self.pos = 0  # offset from the byte after the encapsulation header
        self.fields: list[_Field] = []
        self.consts: dict[str, Any] = {"cdr_header": np.frombuffer(
            _CDR_LE if first is None else first[:4], dtype=np.uint8)}
        self.statics: dict[str, Any] = {}

    def _add(self, name: str, fmt: str, shape: tuple[int, ...], align: int) -> int:
        pad = -self.pos % align
        if pad:
            self.items.append((f"pad{self.pos}", "u1", (pad,)))
            self.pos += pad
        self.items.append((name, fmt, shape))
        start = self.pos
        self.pos += np.dtype(fmt).itemsize * math.prod(shape)
        return start

    def _read(self, start: int, size: int) -> bytes:
        assert self.first is not None
        if 4 + start + size > len(self.first):
            raise LayoutError("message shorter than its layout")
        return self.first[4 + start:4 + start + size]

    def _count(self, name: str, value: int | None) -> int:
        start = self._add(name, "<u4", (), 4)
        if value is None:
            value = int.from_bytes(self._read(start, 4), "little")
        self.consts[name] = np.uint32(value)
        return value

    def _string(self, name: str, value: str | None) -> str:
        raw = None if value is None else value.encode() + b"\0"
        size = self._count(f"{name}.size", None if raw is None else len(raw))
        start = self._add(name, "u1", (size,), 1)
        if raw is None:
            raw = self._read(start, size)
            if not raw.endswith(b"\0"):
                raise LayoutError(f"{name} is not NUL-terminated")
        self.consts[name] = np.frombuffer(raw, dtype=np.uint8)
        return raw[:-1].decode()

    def _given(self, attr: str) -> Any:
        return None if self.series is None else getattr(self.series, attr)

    def stamp(self) -> None:
        """builtin_interfaces/Time of the header."""
        self._add(_SEC, "<i4", (), 4)
        self._add(_NSEC, "<u4", (), 4)

    def string(self, attr: str, name: str) -> None:
        """A string kept in the series as ``attr``."""
        self.statics[attr] = self._string(name, self._given(attr))
        self.fields.append(_Field(name, attr, "string"))

    def strings(self, attr: str, name: str) -> None:
        """A string sequence kept in the series as ``attr`` (a tuple)."""
        given = self._given(attr)
        count = self._count(f"{name}.size", None if given is None else len(given))
        self.statics[attr] = tuple(
            self._string(f"{name}.{i}", None if given is None else str(given[i]))
            for i in range(count))
        self.fields.append(_Field(name, attr, "strings"))

    def floats(self, attr: str, name: str, shape: tuple[int, ...], kind: str = "row",
               parts: str = "") -> None:
        """float64 scalar or fixed array; ``attr`` "" for data the series does not keep."""
        self._add(name, "<f8", shape, 8)
        self.fields.append(_Field(name, attr, kind if attr else "unused", parts))

    def vector(self, attr: str, name: str, parts: str = "xyz") -> None:
        """A geometry_msgs Vector3/Point (``xyz``) or Quaternion (``xyzw``) per message."""
        self.floats(attr, name, (len(parts),), "row", parts)

    def float_seq(self, attr: str, name: str) -> None:
        """float64[] of a constant length; per message (N, n) in the series."""
        given = self._given(attr) if attr else None
        if given is not None and np.ndim(given) != 2:
            raise ValueError(f"{type(self.series).__name__}.{attr}: shape {np.shape(given)}, "
                             "expected (N, n)")
        n = self._count(f"{name}.size", None if self.series is None
                        else (0 if given is None else int(np.shape(given)[1])))
        self._add(name, "<f8", (n,), 8 if n else 1)
        self.fields.append(_Field(name, attr, "row" if attr else "unused"))

    def dtype(self) -> np.dtype[np.void]:
        """The structured dtype; trailing padding of the first message is kept."""
        if self.first is not None:
            extra = len(self.first) - 4 - self.pos
            if not 0 <= extra < 8:
                raise LayoutError(f"message is {len(self.first)} bytes, layout {self.pos + 4}")
            if extra:
                self.items.append(("pad_end", "u1", (extra,)))
        return np.dtype([(n, f, s) if s else (n, f) for n, f, s in self.items])


def _header(b: _Builder) -> None:
    b.stamp()
    b.string("frame_id", "header.frame_id")


def _imu(b: _Builder) -> None:
    _header(b)
    b.vector("orientation", "orientation", "xyzw")
    b.floats("orientation_covariance", "orientation_covariance", (9,), "shared")
    b.vector("angular_velocity", "angular_velocity")
    b.floats("angular_velocity_covariance", "angular_velocity_covariance", (9,), "shared")
    b.vector("linear_acceleration", "linear_acceleration")
    b.floats("linear_acceleration_covariance", "linear_acceleration_covariance", (9,),
             "shared")


def _with_covariance(outer: str) -> Callable[[_Builder], None]:
    def layout(b: _Builder) -> None:
        _header(b)
        b.vector("linear", f"{outer}.{outer}.linear")
        b.vector("angular", f"{outer}.{outer}.angular")
        b.floats("covariance", f"{outer}.covariance", (36,), "shared")
    return layout


def _twist_stamped(b: _Builder) -> None:
    _header(b)
    b.vector("linear", "twist.linear")
    b.vector("angular", "twist.angular")


def _pressure(b: _Builder) -> None:
    _header(b)
    b.floats("fluid_pressure", "fluid_pressure", ())
    b.floats("variance", "variance", (), "shared")


def _wrench(b: _Builder) -> None:
    _header(b)
    b.vector("force", "wrench.force")
    b.vector("torque", "wrench.torque")


def _pose_stamped(b: _Builder) -> None:
    _header(b)
    b.vector("position", "pose.position")
    b.vector("orientation", "pose.orientation", "xyzw")


def _odometry(b: _Builder) -> None:
    _header(b)
    b.string("child_frame_id", "child_frame_id")
    b.vector("position", "pose.pose.position")
    b.vector("orientation", "pose.pose.orientation", "xyzw")
    b.floats("", "pose.covariance", (36,))
    b.vector("linear", "twist.twist.linear")
    b.vector("angular", "twist.twist.angular")
    b.floats("", "twist.covariance", (36,))


def _joint_state(b: _Builder) -> None:
    _header(b)
    b.strings("names", "name")
    b.float_seq("position", "position")
    b.float_seq("velocity", "velocity")
    b.float_seq("effort", "effort")


_LAYOUTS: dict[str, Callable[[_Builder], None]] = {
    "sensor_msgs/msg/Imu": _imu,
    "geometry_msgs/msg/TwistWithCovarianceStamped": _with_covariance("twist"),
    "geometry_msgs/msg/AccelWithCovarianceStamped": _with_covariance("accel"),
    "geometry_msgs/msg/TwistStamped": _twist_stamped,
    "sensor_msgs/msg/FluidPressure": _pressure,
    "geometry_msgs/msg/WrenchStamped": _wrench,
    "nav_msgs/msg/Odometry": _odometry,
    "geometry_msgs/msg/PoseStamped": _pose_stamped,
    "sensor_msgs/msg/JointState": _joint_state,
}


def _layout(msgtype: str, series: Series | None = None, first: bytes | None = None
            ) -> tuple[_Builder, np.dtype[np.void]]:
    series_class(msgtype)
    if first is not None and first[:2] != _CDR_LE[:2]:
        raise LayoutError("not little-endian plain CDR")
    b = _Builder(series, first)
    _LAYOUTS[msgtype](b)
    return b, b.dtype()


# --- encode --------------------------------------------------------------------------------


def encode_array(series: Series) -> NDArray[np.void]:
    """All messages of a series as one structured array (one row per serialized message).

    Parameters
    ----------
    series : Series
        One of the classes in :data:`MESSAGE_TYPES`; body vectors FLU, world ENU, SI units.

    Returns
    -------
    ndarray, shape (N,), structured dtype of itemsize = message length (bytes)
        ``arr[i].tobytes()`` is message i, header included.
    """
    series.validate()
    b, dtype = _layout(message_type(series), series=series)
    n = len(series)
    arr = np.zeros(n, dtype=dtype)
    for name, value in b.consts.items():
        arr[name] = value
    arr[_SEC], arr[_NSEC] = stamps_to_ros(series.stamp)
    for f in b.fields:
        if f.kind not in ("row", "shared"):
            continue
        value = np.asarray(getattr(series, f.attr), dtype=float)
        want = dtype[f.name].shape if f.kind == "shared" else (n, *dtype[f.name].shape)
        if value.shape != want:
            raise ValueError(f"{type(series).__name__}.{f.attr}: shape {value.shape}, "
                             f"expected {want}")
        arr[f.name] = value
    return arr


def encode(series: Series) -> list[bytes]:
    """Serialize every message of a series to CDR.

    Parameters
    ----------
    series : Series
        One of the classes in :data:`MESSAGE_TYPES`.

    Returns
    -------
    list of bytes, length N
        Message i, encapsulation header included, as rosbags' ``serialize_cdr`` writes it.
    """
    arr = encode_array(series)
    buf, size = arr.tobytes(), arr.dtype.itemsize
    return [buf[i:i + size] for i in range(0, len(buf), size)]


# --- decode --------------------------------------------------------------------------------


def decode_fixed(msgtype: str, messages: Messages) -> Series:
    """Decode messages that share one fixed layout with a single ``np.frombuffer``.

    Parameters
    ----------
    msgtype : str
        ROS 2 message type, a key of :data:`SERIES_CLASSES`.
    messages : Messages, length N
        Serialized messages, all of the same length.

    Returns
    -------
    Series
        Arrays of length N on axis 0; shared values (covariances) from the first message.

    Raises
    ------
    LayoutError
        If the messages do not share the layout of the first one.
    """
    cls = series_class(msgtype)
    if len(messages) == 0:
        return cls(stamp=np.zeros(0))
    first = bytes(messages[0])
    if isinstance(messages, np.ndarray):
        b, dtype = _layout(msgtype, first=first)
        arr = np.ascontiguousarray(messages).view(dtype)
    else:
        if len(set(map(len, messages))) != 1:
            raise LayoutError("messages differ in length")
        b, dtype = _layout(msgtype, first=first)
        arr = np.frombuffer(b"".join(messages), dtype=dtype)
    for name, value in b.consts.items():
        if not np.all(arr[name] == value):
            raise LayoutError(f"{name} changes between messages")
    kw: dict[str, Any] = dict(b.statics)
    kw["stamp"] = stamps_from_ros(arr[_SEC], arr[_NSEC])
    for f in b.fields:
        if f.kind == "row":
            kw[f.attr] = np.array(arr[f.name], dtype=float)
        elif f.kind == "shared":
            kw[f.attr] = _shared(arr[f.name][0])
    return cls(**kw)


def decode(msgtype: str, messages: Messages) -> Series:
    """Decode serialized messages into a series: fixed layout if possible, else rosbags.

    Parameters
    ----------
    msgtype : str
        ROS 2 message type, a key of :data:`SERIES_CLASSES`.
    messages : Messages, length N

    Returns
    -------
    Series
        Arrays of length N on axis 0. Values that a series holds once (frame ids, joint
        names, covariances) come from the first message; a warning says when they change.
    """
    try:
        return decode_fixed(msgtype, messages)
    except LayoutError:
        return decode_messages(msgtype, [typestore().deserialize_cdr(bytes(m), msgtype)
                                         for m in messages])


def undecodable(msgtype: str, message: bytes | memoryview) -> str:
    """Why one serialized message does not deserialise as ``msgtype`` (rosbags' CDR
    deserialiser, the ROS 2 Jazzy definitions); empty when it does."""
    try:
        typestore().deserialize_cdr(message, msgtype)
    except Exception as exc:  # any failure of damaged bytes: said, not raised
        return f"{type(exc).__name__}: {exc}"
    return ""


@cache
def typestore() -> Any:
    """The rosbags typestore of ROS 2 Jazzy message definitions (built once)."""
    return get_typestore(Stores.ROS2_JAZZY)


def _get(msg: Any, path: str) -> Any:
    for part in path.split("."):
        msg = getattr(msg, part)
    return msg


def _shared(value: Any) -> Any:
    return float(value) if np.ndim(value) == 0 else np.array(value, dtype=float)


def decode_messages(msgtype: str, msgs: Sequence[Any]) -> Series:
    """Build a series from deserialized message objects (rosbags or rclpy), field by field.

    The slow path for messages of varying layout: one Python step per message and field.

    Parameters
    ----------
    msgtype : str
        ROS 2 message type, a key of :data:`SERIES_CLASSES`.
    msgs : sequence of message objects, length N
        With the attribute structure of the ROS message definition.

    Returns
    -------
    Series
    """
    cls = series_class(msgtype)
    if not msgs:
        return cls(stamp=np.zeros(0))
    # the field list of this message type, laid out from the first message in canonical CDR
    b, _ = _layout(msgtype, first=bytes(typestore().serialize_cdr(msgs[0], msgtype)))
    kw: dict[str, Any] = {"stamp": stamps_from_ros(
        np.array([_get(m, _SEC) for m in msgs]), np.array([_get(m, _NSEC) for m in msgs]))}
    for f in b.fields:
        if f.kind == "unused":
            continue
        values = [_get(m, f.name) for m in msgs]
        if f.parts:
            kw[f.attr] = np.array([[getattr(v, c) for c in f.parts] for v in values], float)
        elif f.kind == "row":
            try:
                kw[f.attr] = np.array(values, dtype=float)
            except ValueError:
                raise ValueError(f"{msgtype}.{f.name} changes length between messages; "
                                 f"a {cls.__name__} needs a constant length") from None
        elif f.kind == "shared":
            kw[f.attr] = _shared(values[0])
        else:
            kept = tuple(values[0]) if f.kind == "strings" else values[0]
            seen = {tuple(v) if f.kind == "strings" else v for v in values}
            if len(seen) > 1:
                warnings.warn(f"{msgtype}.{f.name} changes within the series "
                              f"({len(seen)} values); keeping the first, {kept!r}",
                              stacklevel=2)
            kw[f.attr] = kept
    return cls(**kw)
