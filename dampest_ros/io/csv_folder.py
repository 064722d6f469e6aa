"""A folder of per-topic CSV files read as one log: the topic → Series mapping of a bag.

Logs often come as one CSV file per topic, written by ``rostopic echo -p TOPIC > FILE.csv``
or by a bag-to-CSV tool (bagpy, the rosbag ``bag2csv`` scripts, ROS 2 bag-to-CSV scripts).
:func:`read_csv_folder` returns what :func:`dampest_ros.io.bag.read_bag` returns for a bag
(``read_bag`` and ``bag_summary`` hand such a folder here), so identification, ``--delay auto``
and ``dampest inspect`` take it the way they take a bag.

**Columns.** One header line, one message per line. A leading ``field.`` (rostopic) is
dropped and ``[i]`` becomes ``i`` (ROS 2 scripts), so ``field.angular_velocity.x`` and
``angular_velocity.x`` are the same column, and arrays are ``field.name0``,
``field.velocity0``, ``covariance[3]``. Units and frames are the message's (ROS, FLU). The
message type follows from the columns (:data:`LAYOUTS`, first match):

==========================================  ==================================================
type                                        columns (each ``.x .y .z``, orientation ``.w`` too)
==========================================  ==================================================
nav_msgs/msg/Odometry                       pose.pose.position, pose.pose.orientation,
                                            twist.twist.linear, twist.twist.angular
sensor_msgs/msg/Imu                         orientation, angular_velocity, linear_acceleration
                                            (covariances from the first line)
geometry_msgs/msg/TwistWithCovarianceStamped  twist.twist.linear, twist.twist.angular
geometry_msgs/msg/TwistStamped              twist.linear, twist.angular
geometry_msgs/msg/WrenchStamped             wrench.force, wrench.torque
geometry_msgs/msg/AccelWithCovarianceStamped  accel.accel.linear, accel.accel.angular
sensor_msgs/msg/FluidPressure               fluid_pressure (variance from the first line)
sensor_msgs/msg/JointState                  name0…, velocity0…, effort0…, position0…
                                            (names from the first line)
==========================================  ==================================================

Only these columns are parsed: others (``header.frame_id``, often empty; ``header.seq``) may
hold anything. ``header.frame_id`` is taken from the first line.

**Time.** Each file is its own clock. The stamp is ``header.stamp`` (one column, or
``header.stamp.sec`` + ``header.stamp.nanosec``, or ``.secs`` + ``.nsecs``) unless it is
missing or zero on every line; then the record time (``%time``, ``bag_time_ns`` or
``time``). The unit of a single column is detected (:mod:`dampest_ros.io.csv_table`) and
converted to seconds. Stamps must increase from line to line.

**Topic of a file.** From the file name without ``.csv`` / ``.csv.gz``: ``_slash_`` is a
``/`` (``_slash_imu_slash_data.csv``), and in a name without one ``-`` is (bagpy's
``imu-data.csv``); leading separators go. A name whose words (split at ``/``, ``-`` and
``_``) are those of a topic of the contract (docs/architecture.md §3), alone or at its end,
is that topic: ``imu_data.csv``, ``_imu_data.csv`` (``rostopic echo -p`` scripts,
``${topic//\\//_}``), ``imu-data.csv``, ``_slash_imu_slash_data.csv`` and
``mybag-_vehicle_imu_data.csv`` are all ``imu/data``. Any topic option (``--imu-topic``…)
may instead name a file of the folder (``--imu-topic my_imu_log.csv``), or a topic whose
words match a file's.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from dampest_ros.core.signals.measurements import (
    TOPIC_TYPES,
    AccelSeries,
    FloatArray,
    ImuSeries,
    JointSeries,
    OdometrySeries,
    PressureSeries,
    Series,
    TwistSeries,
    WrenchSeries,
)
from dampest_ros.io.bag import BagSummary, MissingTopicError, TopicSummary
from dampest_ros.io.csv_table import CsvError, numeric_columns, read_head, seconds

#: What a folder's CSV file names end with.
SUFFIXES = (".csv", ".csv.gz")
#: Record-time columns (normalised, lower case), in order of preference.
RECORD_TIME = ("%time", "bag_time_ns", "time")
#: Header stamps split in two columns: (seconds, nanoseconds) names.
SPLIT_STAMPS = (("header.stamp.sec", "header.stamp.nanosec"),
                ("header.stamp.secs", "header.stamp.nsecs"))


def _vec(prefix: str, axes: str = "xyz") -> tuple[str, ...]:
    return tuple(f"{prefix}.{a}" for a in axes)


@dataclass(frozen=True)
class Layout:
    """The columns of one message type: series field → columns (per line), and the shared
    fields (covariances, variance) → column prefix read from the first line."""

    msgtype: str
    cls: type[Series]
    fields: dict[str, tuple[str, ...]]
    shared: dict[str, tuple[str, int]]


#: Message types by their columns; the first whose per-line columns are all present wins.
LAYOUTS = (
    Layout("nav_msgs/msg/Odometry", OdometrySeries,
           {"position": _vec("pose.pose.position"),
            "orientation": _vec("pose.pose.orientation", "xyzw"),
            "linear": _vec("twist.twist.linear"), "angular": _vec("twist.twist.angular")}, {}),
    Layout("sensor_msgs/msg/Imu", ImuSeries,
           {"orientation": _vec("orientation", "xyzw"),
            "angular_velocity": _vec("angular_velocity"),
            "linear_acceleration": _vec("linear_acceleration")},
           {f"{k}_covariance": (f"{k}_covariance", 9)
            for k in ("orientation", "angular_velocity", "linear_acceleration")}),
    Layout("geometry_msgs/msg/TwistWithCovarianceStamped", TwistSeries,
           {"linear": _vec("twist.twist.linear"), "angular": _vec("twist.twist.angular")},
           {"covariance": ("twist.covariance", 36)}),
    Layout("geometry_msgs/msg/TwistStamped", TwistSeries,
           {"linear": _vec("twist.linear"), "angular": _vec("twist.angular")}, {}),
    Layout("geometry_msgs/msg/WrenchStamped", WrenchSeries,
           {"force": _vec("wrench.force"), "torque": _vec("wrench.torque")}, {}),
    Layout("geometry_msgs/msg/AccelWithCovarianceStamped", AccelSeries,
           {"linear": _vec("accel.accel.linear"), "angular": _vec("accel.accel.angular")},
           {"covariance": ("accel.covariance", 36)}),
    Layout("sensor_msgs/msg/FluidPressure", PressureSeries,
           {"fluid_pressure": ("fluid_pressure",)}, {"variance": ("variance", 0)}),
)
JOINT_STATE = "sensor_msgs/msg/JointState"


def normalise(column: str) -> str:
    """A column name without rostopic's ``field.`` and with ``[i]`` as ``i``."""
    name = column.strip()
    name = name[len("field."):] if name.startswith("field.") else name
    return re.sub(r"\[(\d+)\]", r"\1", name)


def _stem(name: str) -> str:
    low = name.lower()
    return name[:-len(next(s for s in SUFFIXES[::-1] if low.endswith(s)))]


def _words(name: str) -> tuple[str, ...]:
    return tuple(w for w in re.split(r"[/_\-]+", name.lower().replace("_slash_", "/")) if w)


def decoded_topic(file_name: str) -> str:
    """A file's topic by the naming rule of the module docstring, without the contract:
    ``_slash_`` and, in a name without it, ``-`` are ``/``; leading separators dropped."""
    stem = _stem(file_name)
    name = stem.replace("_slash_", "/") if "_slash_" in stem else stem.replace("-", "/")
    return name.strip("/_-") or stem


def _contract_topic(file_name: str) -> str | None:
    """The contract topic whose words the file name's are, exactly or at its end."""
    words = _words(_stem(file_name))
    exact = [t for t in TOPIC_TYPES if _words(t) == words]
    if exact:
        return exact[0]
    tail = [t for t in TOPIC_TYPES if words[-len(_words(t)):] == _words(t)]
    return max(tail, key=lambda t: len(_words(t))) if tail else None


def is_csv_folder(path: str | Path) -> bool:
    """Whether ``path`` is a folder of per-topic CSV files (a directory with a ``.csv`` or
    ``.csv.gz`` file and no rosbag2 metadata or storage file)."""
    p = Path(path)
    if not p.is_dir() or (p / "metadata.yaml").exists():
        return False
    names = [f.name.lower() for f in p.iterdir() if f.is_file()]
    return (any(n.endswith(SUFFIXES) for n in names)
            and not any(n.endswith((".mcap", ".db3")) for n in names))


@dataclass(frozen=True)
class TopicFile:
    """One file of a folder: its topic and type, the columns read (file names), the time
    column(s) and unit, and its messages."""

    file: str
    topic: str
    msgtype: str
    columns: tuple[str, ...]
    clock: str
    unit: str
    series: Series


def _recognise(names: set[str]) -> Layout | None:
    """The layout of a file's normalised column names; JointState built from its arrays."""
    layout = next((lay for lay in LAYOUTS
                   if all(c in names for cols in lay.fields.values() for c in cols)), None)
    if layout is not None or "name0" not in names:
        return layout
    k = sum(1 for n in names if re.fullmatch(r"name\d+", n))
    arrays = {f: tuple(f"{f}{i}" for i in range(k)) for f in ("velocity", "effort", "position")}
    present = {f: cols for f, cols in arrays.items() if all(c in names for c in cols)}
    if "velocity" not in present and "effort" not in present:
        return None
    return Layout(JOINT_STATE, JointSeries, present, {})


def _time(path: Path, col: dict[str, str], header: list[str]
          ) -> tuple[FloatArray, tuple[str, ...], str, str]:
    """Stamps (s) of a file: header stamp unless missing or all zero, else record time.
    Returns the stamps, the file's time columns, their description and the unit."""
    where = str(path)
    for sec, nsec in SPLIT_STAMPS:
        if sec in col and nsec in col:
            d = numeric_columns(path, header, [col[sec], col[nsec]])
            if np.any(d[col[sec]]) or np.any(d[col[nsec]]):
                t, _ = seconds(d[col[sec]] + 1e-9 * d[col[nsec]], where, col[sec], unit="s")
                return t, (col[sec], col[nsec]), f"{col[sec]} + {col[nsec]}", "s + ns"
    if "header.stamp" in col:
        stamp = numeric_columns(path, header, [col["header.stamp"]])[col["header.stamp"]]
        if np.any(stamp):
            t, unit = seconds(stamp, where, col["header.stamp"])
            return t, (col["header.stamp"],), col["header.stamp"], unit
    lower = {k.lower(): v for k, v in col.items()}
    record = next((lower[c] for c in RECORD_TIME if c in lower), None)
    if record is None:
        raise CsvError(f"{path}: no time: no header.stamp (or one that is zero throughout) and "
                       f"no record time column ({', '.join(RECORD_TIME)})")
    t, unit = seconds(numeric_columns(path, header, [record])[record], where, record)
    return t, (record,), record, unit


def _first_line(path: Path, first: list[str], index: dict[str, int], layout: Layout
                ) -> dict[str, object]:
    """The fields a message type shares across lines, from the file's first data line."""
    out: dict[str, object] = {}
    for name, (prefix, count) in layout.shared.items():
        cols = [prefix] if count == 0 else [f"{prefix}{i}" for i in range(count)]
        if not all(c in index for c in cols):
            continue
        try:
            values = np.array([float(first[index[c]] or "nan") for c in cols])
        except ValueError:
            raise CsvError(f"{path}: line 2: {prefix} is not numbers") from None
        out[name] = float(values[0]) if count == 0 else values
    if "header.frame_id" in index:
        out["frame_id"] = first[index["header.frame_id"]].strip()
    if layout.cls is OdometrySeries and "child_frame_id" in index:
        out["child_frame_id"] = first[index["child_frame_id"]].strip()
    if layout.cls is JointSeries:
        k = sum(1 for c in index if re.fullmatch(r"name\d+", c))
        out["names"] = tuple(first[index[f"name{i}"]].strip() for i in range(k))
    return out


def read_topic_file(path: Path, topic: str) -> TopicFile | str:
    """One per-topic CSV file as a series, or why it is not one (unknown columns).

    Raises
    ------
    CsvError
        A header-only file, a cell of a used column that is not a number, time that does
        not increase: naming the file, line and column.
    """
    header, first = read_head(path)
    index = {normalise(h): i for i, h in enumerate(header)}
    col = {n: header[i] for n, i in index.items()}
    layout = _recognise(set(index))
    if layout is None:
        return (f"{path.name}: its columns match no message type identification reads "
                f"({', '.join(list(index)[:5])}…)")
    if first is None:
        raise CsvError(f"{path}: only a header line, no messages; delete the file or export "
                       "the topic again")
    t, time_cols, clock, unit = _time(path, col, header)
    used = [col[c] for cols in layout.fields.values() for c in cols]
    data = numeric_columns(path, header, used)
    kw: dict[str, object] = {
        f: data[col[cols[0]]] if layout.cls is PressureSeries
        else np.stack([data[col[c]] for c in cols], axis=1)
        for f, cols in layout.fields.items()}
    kw.update(_first_line(path, first, index, layout))
    if layout.cls is JointSeries:
        shape = (len(t), len(kw["names"]))  # type: ignore[arg-type]
        kw = {"velocity": np.full(shape, np.nan), "effort": np.full(shape, np.nan), **kw}
    series = layout.cls(stamp=t, **kw)  # type: ignore[arg-type]
    return TopicFile(path.name, topic, layout.msgtype, (*time_cols, *used), clock, unit, series)


@dataclass(frozen=True)
class FolderLog:
    """A folder read: topic → its file, and the files that are no topic (with why)."""

    path: Path
    files: dict[str, TopicFile]
    skipped: tuple[str, ...]


def _csv_files(path: Path) -> list[Path]:
    return sorted(f for f in path.iterdir() if f.is_file() and f.name.lower().endswith(SUFFIXES))


def load_folder(path: str | Path) -> FolderLog:
    """Every file of a folder (read once, then cached until a file changes).

    Raises
    ------
    CsvError
        No file is a topic, two files give one topic, or a file cannot be read.
    """
    p = Path(path)
    signature = tuple((f.name, f.stat().st_mtime_ns, f.stat().st_size) for f in _csv_files(p))
    return _load(p, signature)


@lru_cache(maxsize=2)
def _load(path: Path, signature: tuple[tuple[str, int, int], ...]) -> FolderLog:
    files: dict[str, TopicFile] = {}
    skipped: list[str] = []
    for name, _, _ in signature:
        topic = _contract_topic(name) or decoded_topic(name)
        if topic in files:
            raise CsvError(f"{path}: {files[topic].file} and {name} are both topic {topic}; "
                           f"rename one, or name the file to use with --TOPIC-topic FILE")
        got = read_topic_file(path / name, topic)
        if isinstance(got, str):
            skipped.append(got)
        else:
            files[topic] = got
    if not files:
        raise CsvError(f"{path}: no CSV file here is a topic identification reads "
                       f"({'; '.join(skipped)}); columns are the message's fields as "
                       "`rostopic echo -p` writes them (field.angular_velocity.x, …; see "
                       "README 'Bringing your own log')")
    return FolderLog(path, files, tuple(skipped))


def resolve_topic(path: str | Path, name: str) -> str:
    """The folder's topic that ``name`` designates: a topic, a file of the folder, or a
    topic whose words are a file's (``vehicle/imu`` for ``vehicle_imu.csv``); ``name``
    (without a leading ``/``) when none does."""
    log, rel = load_folder(path), name.lstrip("/")
    by_file = {f.file: t for t, f in log.files.items()}
    words = [t for t in log.files if _words(t) == _words(rel)]
    if rel in log.files:
        return rel
    if rel in by_file:
        return by_file[rel]
    return words[0] if len(words) == 1 else rel


def read_csv_folder(path: str | Path, topics: Sequence[str] | None = None,
                    start: float | None = None, stop: float | None = None
                    ) -> dict[str, Series]:
    """The series of a folder of per-topic CSV files, as :func:`dampest_ros.io.bag.read_bag`
    gives a bag's.

    Parameters
    ----------
    path : str or Path
    topics : sequence of str, optional
        Topics (or file names, :func:`resolve_topic`); default every topic of the folder.
    start, stop : float, optional
        Only messages stamped in [start, stop) (s).

    Returns
    -------
    dict of str to Series
        Keyed by the names asked for (default: the folder's topics); stamps in seconds.

    Raises
    ------
    MissingTopicError
        A requested topic is not in the folder; lists those that are, with their files.
    """
    log = load_folder(path)
    names = list(log.files) if topics is None else list(topics)
    resolved = {n: resolve_topic(path, n) for n in names}
    missing = [n for n, r in resolved.items() if r not in log.files]
    if missing:
        have = ", ".join(f"{t} ({f.file}, {f.msgtype})" for t, f in log.files.items())
        raise MissingTopicError(f"topics {missing} not in CSV folder {path}; it has: {have}")
    out = {}
    for n, r in resolved.items():
        s = log.files[r].series
        lo, hi = np.searchsorted(s.stamp, [-np.inf if start is None else start,
                                           np.inf if stop is None else stop])
        out[n] = s.select(np.arange(int(lo), int(hi)))
    return out


def folder_summary(path: str | Path) -> BagSummary:
    """What :func:`dampest_ros.io.bag.bag_summary` says of a bag, for a folder (storage
    ``csv``; topics with a leading ``/``; the time range of all stamps, s)."""
    log = load_folder(path)
    topics = {f"/{t}": TopicSummary(f"/{t}", f.msgtype, len(f.series))
              for t, f in log.files.items()}
    stamps = [f.series.stamp for f in log.files.values() if len(f.series)]
    return BagSummary(Path(path), "csv", min(float(s[0]) for s in stamps),
                      max(float(s[-1]) for s in stamps), topics)


def folder_notes(path: str | Path) -> list[str]:
    """One line per file: its topic, type and clock with the unit detected; one per file
    that is no topic."""
    log = load_folder(path)
    return [*(f"{f.file} → {t} ({f.msgtype}, {len(f.series)} messages): time from {f.clock} "
              f"in {f.unit}" for t, f in log.files.items()),
            *(f"skipped {s}" for s in log.skipped)]
