"""Bags of measurement series: rosbag2 (MCAP or SQLite3) written and read, ROS 1 read, with
rosbags.

Bags written here are rosbag2 directories (``metadata.yaml`` + storage file) that ``ros2 bag``
on Jazzy, rosbags and the mcap library read; the log time of every message is its header
stamp in nanoseconds. Bags are read by one reader for both generations: a rosbag2 directory,
or a ROS 1 bag (a ``.bag`` file, format 2.0, as most published marine datasets are), whose
messages rosbags converts from the ROS 1 wire format to CDR as they are read (ROS 1 type
names such as ``sensor_msgs/Imu`` become ``sensor_msgs/msg/Imu``). Topic names are stored
fully qualified (``/imu/data``) and returned relative (``imu/data``), as in
:data:`dampest_ros.core.signals.measurements.TOPIC_TYPES`.

Messages are serialized and deserialized with the fixed-layout numpy codec of
:mod:`dampest_ros.io.cdr`. An indexed MCAP bag is read without per-message Python work: each
chunk's records are found, checked and copied out with numpy (:mod:`dampest_ros.io.mcap_check`);
other bags cost the rosbags read call per message (and, for a ROS 1 bag, rosbags' conversion
of the message to CDR); writing costs the rosbags write call per message.
"""

from __future__ import annotations

import shutil
import warnings
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import suppress
from dataclasses import dataclass, fields
from itertools import chain
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray
from rosbags.interfaces import (
    Connection,
    Qos,
)
from rosbags.rosbag1 import Reader as Ros1Reader
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.rosbag2.storage_mcap import McapReader

from dampest_ros.core.signals.measurements import TOPIC_TYPES, Series
from dampest_ros.io import cdr, mcap_check
from dampest_ros.io.bag_metadata import make_qos

#: Topics published with the sensor-data QoS (best effort, volatile, depth 5).
SENSOR_TOPICS = ("imu/data", "dvl/twist", "pressure", "thrusters/state")
#: Topics published transient local with depth 1 (late joiners get the last message).
LATCHED_TOPICS = ("dampest/model",)

#: Messages decoded at once per topic while reading: bounds the raw bytes held in memory
#: (about 2 MB per topic) without slowing the numpy decode down.
READ_CHUNK = 5_000

_STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
#: File name suffix of a ROS 1 bag.
ROS1_SUFFIX = ".bag"


class BagError(RuntimeError):
    """A bag cannot be read (missing metadata, corrupt or truncated storage file)."""


class MissingTopicError(LookupError):
    """A requested topic is not in the bag; the message lists the topics that are."""


class TopicTypeError(BagError):
    """A topic given for an input role of identification carries another message type."""


#: Input roles of identification → the message type each needs: the type of the contract
#: topic that plays the role by default (docs/architecture.md §3).
ROLE_TYPES = {role: TOPIC_TYPES[topic][0] for role, topic in (
    ("imu", "imu/data"), ("dvl", "dvl/twist"), ("pressure", "pressure"),
    ("thrusters", "thrusters/state"), ("wrench", "wrench"))}
#: Other message types a role accepts: a DVL's velocity without covariance; a navigation
#: state's body velocity and attitude (dampest_ros.core.signals.sources).
ROLE_ALTERNATIVES = {"dvl": ("geometry_msgs/msg/TwistStamped", "nav_msgs/msg/Odometry"),
                     "imu": ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped")}


def _relative(topic: str) -> str:
    return topic.lstrip("/")


def _is(topic: str, names: Iterable[str]) -> bool:
    rel = _relative(topic)
    return any(rel == n or rel.endswith("/" + n) for n in names)


def offered_qos(topic: str) -> Qos:
    """QoS offered by the publisher of a topic (stored in the bag metadata).

    Sensor topics (also under a namespace, e.g. ``vehicle/imu/data``): best effort, volatile,
    keep last 5. ``dampest/model``: reliable, transient local, keep last 1. Others: reliable,
    volatile, keep last 10.
    """
    if _is(topic, SENSOR_TOPICS):
        return make_qos(reliable=False, depth=5)
    if _is(topic, LATCHED_TOPICS):
        return make_qos(transient_local=True, depth=1)
    return make_qos()


def _message_type(topic: str, series: Series) -> str:
    msgtype = cdr.message_type(series)
    contract = TOPIC_TYPES.get(_relative(topic))
    if contract is not None and contract[0] != msgtype:
        raise ValueError(f"topic {topic!r} carries {contract[0]} (docs/architecture.md §3), "
                         f"got a {type(series).__name__} ({msgtype})")
    return msgtype


def write_bag(path: str | Path, recording: dict[str, Series], *, storage: str = "mcap"
              ) -> Path:
    """Write a recording as a rosbag2 bag, messages interleaved in stamp order.

    Parameters
    ----------
    path : str or Path
        Bag directory to create; it must not exist.
    recording : dict of str to Series
        Topic name (relative or absolute) → series; the message type follows from the series
        class and must match the topic contract for the topics of ``TOPIC_TYPES``. Stamps
        (s) must be ≥ 0: they become the header stamps and the log times (ns).
    storage : {'mcap', 'sqlite3'}

    Returns
    -------
    Path
        The bag directory.

    Raises
    ------
    FileExistsError
        If ``path`` exists (bags are never overwritten).
    """
    path = Path(path)
    if path.exists():
        raise FileExistsError(f"{path} exists; write_bag never overwrites a bag, "
                              "remove it or choose another path")
    if storage not in _STORAGES:
        raise ValueError(f"storage must be one of {sorted(_STORAGES)}, got {storage!r}")
    topics = ["/" + _relative(t) for t in recording]
    types = [_message_type(t, s) for t, s in zip(topics, recording.values(), strict=True)]
    msgs = [cdr.encode(s) for s in recording.values()]
    stamps = [cdr.stamps_to_ns(s.stamp) for s in recording.values()]
    log_ns = np.concatenate(stamps) if stamps else np.zeros(0, dtype=np.int64)
    if log_ns.size and log_ns.min() < 0:
        raise ValueError("stamps must be >= 0 s to serve as bag log times")
    order = np.argsort(log_ns, kind="stable")
    conn_index = np.repeat(np.arange(len(msgs)), [len(m) for m in msgs])[order].tolist()
    flat = list(chain.from_iterable(msgs))
    writer = Writer(path, version=9, storage_plugin=_STORAGES[storage])
    writer.open()  # creates the directory, refusing an existing one
    try:
        conns = [writer.add_connection(t, m, typestore=cdr.typestore(),
                                       offered_qos_profiles=[offered_qos(t)])
                 for t, m in zip(topics, types, strict=True)]
        for k, i, t in zip(conn_index, order.tolist(), log_ns[order].tolist(), strict=True):
            writer.write(conns[k], t, flat[i])
        writer.close()
    except BaseException:
        with suppress(Exception):
            writer.abort()
        shutil.rmtree(path, ignore_errors=True)  # made by open() above: no half-written bag
        raise
    return path


# --- reading -------------------------------------------------------------------------------


def _files(path: Path) -> str:
    if path.is_dir():
        names = sorted(p.name for p in path.iterdir() if p.suffix in (".mcap", ".db3", ".yaml"))
        return f"{path} ({', '.join(names) or 'no storage files'})"
    return str(path)


def is_ros1_bag(path: str | Path) -> bool:
    """Whether ``path`` names a ROS 1 bag: not a directory, its name ending in ``.bag``."""
    p = Path(path)
    return p.suffix.lower() == ROS1_SUFFIX and not p.is_dir()


def is_bag(path: str | Path) -> bool:
    """Whether ``path`` is a bag to read: a rosbag2 directory or a ROS 1 ``.bag`` file."""
    p = Path(path)
    return p.is_dir() or (p.is_file() and is_ros1_bag(p))


class Bag:
    """A rosbags Reader of either generation (:func:`is_ros1_bag` chooses) whose failures
    become :class:`BagError` naming the files; messages come out as CDR."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise FileNotFoundError(f"no bag at {self.path}")
        self.ros1 = is_ros1_bag(self.path)
        try:
            self.reader: Reader | Ros1Reader = (Ros1Reader if self.ros1 else Reader)(self.path)
            self.reader.open()
        except Exception as exc:
            hint = ""
            if self.ros1:
                hint = ("; it is not a ROS 1 bag (format 2.0), or it is truncated: a recording "
                        "that was interrupted needs 'rosbag reindex' (ROS 1) first")
            elif self.path.is_dir() and any(self.path.glob("*.mcap")):
                hint = (f"; if its recording was interrupted, 'dampest reindex {self.path}' "
                        "rebuilds metadata.yaml and recovers it up to its last complete chunk")
            raise BagError(f"cannot read bag {_files(self.path)}: "
                           f"{exc or type(exc).__name__}{hint}") from exc
        self.checked = self._checked_storages()

    def _checked_storages(self) -> list[McapReader]:
        """The bag's MCAP files when all have chunk indexes (then read through
        :mod:`dampest_ros.io.mcap_check`), their indexes checked and their counts compared
        with ``metadata.yaml``'s; empty for other bags (read by rosbags alone)."""
        inner: Any = getattr(self.reader, "storage", None)  # a directory's or a file's
        storages = [inner] if isinstance(inner, McapReader) else getattr(inner, "storages", [])
        if (not storages or inner.metadata.compression_mode == "message"
                or not all(isinstance(s, McapReader) and s.chunks for s in storages)):
            return []
        try:
            for storage in storages:
                mcap_check.check_index(storage)
        except mcap_check.DamagedFileError as exc:
            self.reader.close()
            raise self._damaged(exc) from None
        stored: Counter[str] = Counter()
        for storage in storages:
            assert storage.statistics is not None
            for c in storage.connections:
                stored[c.topic] += storage.statistics.channel_message_counts.get(c.id, 0)
        listed = {t: int(i.msgcount) for t, i in self.reader.topics.items()}
        if listed != {t: stored.get(t, 0) for t in listed}:
            self.reader.close()
            wrong = ", ".join(f"{t} {n} (the storage holds {stored.get(t, 0)})"
                              for t, n in sorted(listed.items()) if n != stored.get(t, 0))
            raise BagError(f"cannot read bag {_files(self.path)}: metadata.yaml counts other "
                           f"messages than its storage files: {wrong}; 'dampest reindex "
                           f"{self.path}' rebuilds metadata.yaml from the storage files")
        return list(storages)

    def _damaged(self, exc: Exception) -> BagError:
        """The error for a failure while reading messages: a damaged storage file, named,
        with the repair to try."""
        repair = ("'rosbag reindex' (ROS 1) rebuilds its index" if self.ros1 else
                  f"'dampest reindex {self.path}' rebuilds its index from the intact chunks "
                  "and reports what is lost")
        what = (str(exc) if isinstance(exc, mcap_check.DamagedFileError)
                else f"{type(exc).__name__}: {exc}")
        return BagError(f"cannot read bag {_files(self.path)}: a damaged storage file "
                        f"({what}); {repair}")

    def __enter__(self) -> Bag:
        return self

    def __exit__(self, *exc: object) -> None:
        self.reader.close()

    def messages(self, conns: Sequence[Connection], start: int | None = None,
                 stop: int | None = None
                 ) -> Iterator[tuple[Connection, int, bytes | memoryview]]:
        """Connection, log time (ns) and CDR of the messages of ``conns`` in [start, stop)."""
        if not conns:  # rosbags reads every topic for an empty selection
            return
        # a ROS 1 message to CDR by rosbags (the ROS 2 Jazzy definitions; std_msgs/Header
        # loses its seq): the CDR codec then decodes both generations alike
        to_cdr = cdr.typestore().ros1_to_cdr if self.ros1 else None
        source = (self._checked_messages(conns, start, stop) if self.checked else
                  self.reader.messages(connections=conns, start=start, stop=stop))
        try:
            for conn, t, data in source:
                yield conn, t, data if to_cdr is None else to_cdr(data, conn.msgtype)
        except Exception as exc:
            raise self._damaged(exc) from exc

    def batches(self, conns: Sequence[Connection], start: int | None = None,
                stop: int | None = None
                ) -> Iterator[tuple[Connection, NDArray[np.int64], cdr.Messages]]:
        """:meth:`messages` a batch at a time: connection, log times (ns) and CDR of
        consecutive messages of one connection; an indexed MCAP bag's chunk by chunk, with
        numpy, other bags' :data:`READ_CHUNK` messages of a connection at a time."""
        if not self.checked:
            yield from _grouped(self.messages(conns, start, stop))
            return
        try:
            for storage, ours, theirs in self._per_file(conns):
                for group in mcap_check.batches(storage, theirs, start, stop):
                    for b in group:
                        yield ours[b.connection.id], b.log_time, b.data
        except Exception as exc:
            raise self._damaged(exc) from exc

    def _per_file(self, conns: Sequence[Connection]
                  ) -> Iterator[tuple[McapReader, dict[int, Connection], list[Connection]]]:
        """The checked MCAP files, each with its connection ids → the one of ``conns`` of
        the same topic and type, and those connections of its own."""
        for storage in self.checked:
            ours = {x.id: c for x in storage.connections for c in conns
                    if (x.topic, x.msgtype) == (c.topic, c.msgtype)}
            yield storage, ours, [x for x in storage.connections if x.id in ours]

    def _checked_messages(self, conns: Sequence[Connection], start: int | None,
                          stop: int | None) -> Iterator[tuple[Connection, int, bytes]]:
        """:meth:`messages` of an MCAP bag, file by file, each chunk checked as it is read."""
        for storage, ours, theirs in self._per_file(conns):
            for x, t, data in mcap_check.messages(storage, theirs, start, stop):
                yield ours[x.id], t, data

    def decode(self, topic: str, msgtype: str, raw: cdr.Messages,
               log_ns: NDArray[np.int64]) -> Series:
        """The series of ``raw`` (messages of ``topic`` logged at ``log_ns``); messages that
        do not deserialise are damaged bytes, named with their log times and the repair."""
        try:
            return cdr.decode(msgtype, raw)
        except Exception as exc:
            bad = [(t, err) for t, m in zip(log_ns.tolist(), raw, strict=True)
                   if (err := cdr.undecodable(msgtype, bytes(m)))]
            if bad:
                raise self._damaged(mcap_check.DamagedFileError(
                    f"{len(bad)} of {len(raw)} messages of {topic} logged from "
                    f"{log_ns[0] / 1e9:.3f} s to {log_ns[-1] / 1e9:.3f} s do not deserialise "
                    f"as {msgtype}, the first at log time {bad[0][0] / 1e9:.3f} s: "
                    f"{bad[0][1]}")) from exc
            raise BagError(f"cannot decode {topic} ({msgtype}) in bag {_files(self.path)}: "
                           f"{exc}") from exc


def _grouped(messages: Iterable[tuple[Connection, int, bytes | memoryview]]
             ) -> Iterator[tuple[Connection, NDArray[np.int64], list[bytes | memoryview]]]:
    """Messages gathered per connection, :data:`READ_CHUNK` at a time (the rest at the end):
    connection, log times (ns) and messages."""
    held: dict[int, tuple[Connection, list[int], list[bytes | memoryview]]] = {}
    for conn, t, data in messages:
        _, times, raw = held.setdefault(conn.id, (conn, [], []))
        times.append(t)
        raw.append(data)
        if len(raw) == READ_CHUNK:
            yield conn, np.array(times, np.int64), raw
            held[conn.id] = (conn, [], [])
    for conn, times, raw in held.values():
        if raw:
            yield conn, np.array(times, np.int64), raw


class _Assembler:
    """Decoded chunks of one topic copied into arrays preallocated for the announced count,
    so a long topic is held once, not once in chunks plus once joined."""

    def __init__(self, count: int) -> None:
        self.count = count
        self.first: Series | None = None
        self.arrays: dict[str, NDArray[Any]] = {}
        self.n = 0

    def add(self, part: Series) -> None:
        """Append a decoded chunk."""
        if self.first is None:
            self.first = part
            total = max(self.count, len(part))
            self.arrays = {k: np.empty((total, *a.shape[1:]), dtype=a.dtype)
                           for k, a in part.per_message().items()}
        else:
            for f in fields(part):
                value = getattr(part, f.name)
                if not isinstance(value, np.ndarray) and value != getattr(self.first, f.name):
                    warnings.warn(f"{type(part).__name__}.{f.name} changes within the series; "
                                  f"keeping the first, {getattr(self.first, f.name)!r}",
                                  stacklevel=3)
        m = len(part)
        if self.n + m > len(self.arrays["stamp"]):  # more than announced: grow
            for k, a in self.arrays.items():
                grown = np.empty((max(2 * len(a), self.n + m), *a.shape[1:]), a.dtype)
                grown[:self.n] = a[:self.n]
                self.arrays[k] = grown
        for k, a in part.per_message().items():
            self.arrays[k][self.n:self.n + m] = a
        self.n += m

    def result(self) -> Series:
        """The joined series."""
        assert self.first is not None
        kw: dict[str, Any] = {f.name: getattr(self.first, f.name) for f in fields(self.first)}
        kw.update({k: a[:self.n] for k, a in self.arrays.items()})
        return type(self.first)(**kw)


def read_bag(path: str | Path, topics: Sequence[str] | None = None,
             progress: Callable[[int, int], None] | None = None,
             start: float | None = None, stop: float | None = None) -> dict[str, Series]:
    """Read the series of a bag: a rosbag2 bag (MCAP or SQLite3 directory, or a single
    storage file) or a ROS 1 ``.bag`` file.

    Parameters
    ----------
    path : str or Path
    topics : sequence of str, optional
        Topics to read, with or without the leading ``/``. Default: every topic whose type
        is one of :data:`dampest_ros.io.cdr.SERIES_CLASSES` (others are skipped).
    progress : callable, optional
        Called as ``progress(done, total)`` (message counts) every :data:`READ_CHUNK`
        messages and at the end.
    start, stop : float, optional
        Read only messages logged in [start, stop) (s, bag log time); uses the storage's
        index, so a window of a long bag costs only its own messages.

    Returns
    -------
    dict of str to Series
        Keyed by the names asked for (default: bag names without the leading ``/``); rows
        in bag (log time) order. Stamps (s) are the header stamps.

    Raises
    ------
    MissingTopicError
        If a requested topic is not in the bag; lists the topics that are.
    BagError
        If the bag is missing its metadata, corrupt or truncated; names the files.
    """
    from dampest_ros.io import csv_folder  # a folder of per-topic CSV files reads like a bag
    if csv_folder.is_csv_folder(path):
        return csv_folder.read_csv_folder(path, topics, start, stop)
    with Bag(path) as bag:
        return {k: v.series for k, v in _read(bag, topics, progress, _ns(start), _ns(stop)
                                              ).items()}


def _ns(seconds: float | None) -> int | None:
    """A log time (s) in ns."""
    return None if seconds is None else round(seconds * 1e9)


class Logged(NamedTuple):
    """A topic's messages read from a bag: the series and each message's log time (ns)."""

    series: Series
    log_ns: NDArray[np.int64]

    def between(self, start: int | None, stop: int | None) -> Logged:
        """The messages logged in [start, stop) (ns; None: unbounded)."""
        if start is None and stop is None:
            return self
        keep = np.ones(len(self.log_ns), dtype=bool)
        if start is not None:
            keep &= self.log_ns >= start
        if stop is not None:
            keep &= self.log_ns < stop
        return Logged(self.series.select(keep), self.log_ns[keep])

    def then(self, later: Logged) -> Logged:
        """These messages followed by ``later``'s (of the same topic)."""
        if not len(later.log_ns) or not len(self.log_ns):
            return later if not len(self.log_ns) else self
        joined = _Assembler(len(self.log_ns) + len(later.log_ns))
        joined.add(self.series)
        joined.add(later.series)
        return Logged(joined.result(), np.concatenate([self.log_ns, later.log_ns]))


class _Topic:
    """The batches of one topic, decoded :data:`READ_CHUNK` messages at a time (the last
    ones at the end) into an :class:`_Assembler`.

    Parameters
    ----------
    bag : Bag
    topic, msgtype : str
    count : int
        Messages announced (0: unknown).
    """

    def __init__(self, bag: Bag, topic: str, msgtype: str, count: int) -> None:
        self.bag, self.topic, self.msgtype = bag, topic, msgtype
        self.parts = _Assembler(count)
        self.raw: list[cdr.Messages] = []
        self.log_ns: list[NDArray[np.int64]] = []
        self.held = 0
        self.decoded: list[NDArray[np.int64]] = []

    def add(self, log_ns: NDArray[np.int64], raw: cdr.Messages) -> int:
        """Take a batch (log times in ns, messages); the number of messages decoded."""
        self.raw.append(raw)
        self.log_ns.append(log_ns)
        self.held += len(log_ns)
        return self._decode(self.held - self.held % READ_CHUNK) if self.held >= READ_CHUNK else 0

    def _decode(self, k: int) -> int:
        """Decode the first ``k`` messages held, :data:`READ_CHUNK` at a time."""
        if not k:
            return 0
        raw, log_ns = cdr.join(self.raw), np.concatenate(self.log_ns)
        for i in range(0, k, READ_CHUNK):
            self.parts.add(self.bag.decode(self.topic, self.msgtype, raw[i:i + READ_CHUNK],
                                           log_ns[i:i + READ_CHUNK]))
        self.decoded.append(log_ns[:k])
        self.raw, self.log_ns, self.held = [raw[k:]], [log_ns[k:]], len(log_ns) - k
        return k

    def result(self) -> Logged:
        """The whole series (the messages still held decoded) and its log times."""
        self._decode(self.held)
        if self.parts.first is None:  # no message
            self.parts.add(cdr.decode(self.msgtype, []))
        return Logged(self.parts.result(), np.concatenate([np.zeros(0, np.int64),
                                                           *self.decoded]))


def _read(bag: Bag, topics: Sequence[str] | None,
          progress: Callable[[int, int], None] | None, start: int | None,
          stop: int | None) -> dict[str, Logged]:
    """:func:`read_bag` on a bag already open (``start``, ``stop`` in ns), with log times."""
    info = bag.reader.topics
    if topics is None:
        wanted = {_relative(t): t for t, i in info.items() if i.msgtype in cdr.SERIES_CLASSES}
    else:
        by_rel = {_relative(t): t for t in info}
        missing = [t for t in topics if _relative(t) not in by_rel]
        if missing:
            have = ", ".join(f"{t} ({i.msgtype})" for t, i in sorted(info.items()))
            raise MissingTopicError(f"topics {missing} not in bag {bag.path}; it has: {have}")
        wanted = {t: by_rel[_relative(t)] for t in topics}
    key = {name: out for out, name in wanted.items()}
    msgtype = {name: str(info[name].msgtype) for name in key}
    for name, typ in msgtype.items():
        if typ not in cdr.SERIES_CLASSES:
            raise TypeError(f"topic {name} has type {typ}, which has no series class; "
                            f"readable types: {sorted(cdr.SERIES_CLASSES)}")
    window = start is not None or stop is not None
    parts = {name: _Topic(bag, name, msgtype[name],
                          0 if window else int(info[name].msgcount or 0)) for name in key}
    conns = [c for name in key for c in info[name].connections]
    total = sum(int(info[name].msgcount or 0) for name in key)
    done = 0
    for conn, log_ns, raw in bag.batches(conns, start, stop):
        decoded = parts[conn.topic].add(log_ns, raw)
        done += decoded
        if decoded and progress is not None:
            progress(done, total)
    out: dict[str, Logged] = {}
    for name in key:
        logged = parts[name].result()
        if not window and info[name].msgcount and len(logged.series) != info[name].msgcount:
            raise BagError(f"bag {_files(bag.path)} is truncated or corrupt: {name} has "
                           f"{len(logged.series)} of its {info[name].msgcount} messages")
        out[key[name]] = logged
    if progress is not None:
        progress(total, total)
    return out


@dataclass(frozen=True)
class TopicSummary:
    """One topic of a bag: name (as stored), message type and message count."""

    name: str
    msgtype: str
    count: int


@dataclass(frozen=True)
class BagSummary:
    """What a bag holds: storage (``mcap``, ``sqlite3`` or ``ros1``), time range of the log
    times (s) and its topics."""

    path: Path
    storage: str
    start: float
    end: float
    topics: dict[str, TopicSummary]

    @property
    def message_count(self) -> int:
        """Total number of messages."""
        return sum(t.count for t in self.topics.values())

    @property
    def duration(self) -> float:
        """end − start (s)."""
        return self.end - self.start


def bag_summary(path: str | Path) -> BagSummary:
    """Topics, types, counts and time range of a bag, from its metadata or, for a ROS 1 bag,
    its index (no messages read).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    BagSummary
        ``start``/``end``: first and last log time (s); 0 for an empty bag.
    """
    from dampest_ros.io import csv_folder  # a folder of per-topic CSV files reads like a bag
    if csv_folder.is_csv_folder(path):
        return csv_folder.folder_summary(path)
    with Bag(path) as bag:
        return _summary(bag)


def _summary(bag: Bag) -> BagSummary:
    """:func:`bag_summary` of a bag already open."""
    r = bag.reader
    topics = {t: TopicSummary(t, str(i.msgtype), i.msgcount) for t, i in r.topics.items()}
    empty = r.message_count == 0
    start = 0 if empty else r.start_time
    end = 0 if empty else r.end_time - 1  # rosbags: end_time is one past the last
    files = [bag.path] if bag.path.is_file() else list(bag.path.iterdir())
    storage = ("ros1" if bag.ros1 else
               "mcap" if any(f.suffix == ".mcap" for f in files) else "sqlite3")
    return BagSummary(bag.path, storage, start / 1e9, end / 1e9, topics)


def role_type_errors(summary: BagSummary, roles: Mapping[str, str]) -> list[str]:
    """What is wrong with the message types of the topics given for identification's roles.

    Parameters
    ----------
    summary : BagSummary
    roles : mapping of str to str
        Role (a key of :data:`ROLE_TYPES`) → topic, as ``--imu-topic`` etc. give them.

    Returns
    -------
    list of str
        One sentence per role whose topic is in the bag with another type than the role
        needs, naming the topic, the type found, the type needed and the ``--ROLE-topic``
        option that names another topic; empty when all match. Topics absent from the bag
        are not reported here (reading them raises :class:`MissingTopicError`), nor is the
        ``thrusters`` topic when a ``wrench`` topic gives τ instead.
    """
    found = {_relative(name): t.msgtype for name, t in summary.topics.items()}
    errors = []
    for role, topic in roles.items():
        if role == "thrusters" and "wrench" in roles:
            continue
        have, need = found.get(_relative(topic)), ROLE_TYPES[role]
        if have is not None and have != need and have not in ROLE_ALTERNATIVES.get(role, ()):
            carriers = [name for name, msgtype in found.items() if msgtype == need]
            which = carriers[0] if len(carriers) == 1 else "TOPIC"
            errors.append(f"topic {topic} ({role}) carries {have}, not the {need} "
                          f"identification needs; give the {role} topic with "
                          f"--{role}-topic {which}")
    return errors


def check_role_types(summary: BagSummary, roles: Mapping[str, str]) -> None:
    """Refuse a bag whose topics for identification's roles carry other message types.

    Parameters
    ----------
    summary : BagSummary
        The bag's (:func:`bag_summary`; the caller has read it).
    roles : mapping of str to str
        Role → topic (see :func:`role_type_errors`).

    Raises
    ------
    TopicTypeError
        With every mismatch of :func:`role_type_errors`, in one line naming the bag.
    """
    errors = role_type_errors(summary, roles)
    if errors:
        raise TopicTypeError(f"bag {summary.path}: {'; '.join(errors)}")


class BagSource:
    """Time windows of a bag's topics on demand: the
    :class:`dampest_ros.core.signals.preprocess.SeriesSource` that keeps a long log out of memory.

    Parameters
    ----------
    path : str or Path
        rosbag2 directory (MCAP or SQLite3), ROS 1 ``.bag`` file or a folder of per-topic CSV
        files (:mod:`dampest_ros.io.csv_folder`).
    progress : callable, optional
        Called as ``progress(seconds_read, seconds_total)`` as windows are read.
    together : sequence of str
        Topics read in one pass per window (their messages share the bag's chunks, which
        would otherwise be decompressed once per topic). The last two windows read are kept
        (with the messages' log times): the part of a window that one of them holds is not
        read again (the frame checks' first window, the overlap of consecutive stretches).
    whole : sequence of str
        Small topics (DVL, pressure) read whole, in one pass, the first time one of them is
        asked for, and kept: their windows are cut from them.

    The bag stays open until :meth:`close` (or the end of a ``with`` block): opening a ROS 1
    bag reads its whole index, which per window would cost in proportion to the bag.
    """

    def __init__(self, path: str | Path,
                 progress: Callable[[int, int], None] | None = None,
                 together: Sequence[str] = (), whole: Sequence[str] = ()) -> None:
        from dampest_ros.io import csv_folder  # a folder of per-topic CSV files reads like a bag

        self.path = Path(path)
        self._bag: Bag | None = None
        if csv_folder.is_csv_folder(self.path):  # parsed once, cached by csv_folder
            self.summary = csv_folder.folder_summary(self.path)
        else:
            self._bag = Bag(self.path)
            self.summary = _summary(self._bag)
        #: the first log time (ns): no message is logged before it
        self._first = (self._bag.reader.start_time
                       if self._bag is not None and self._bag.reader.message_count else 0)
        self.progress = progress
        self.together = [_relative(t) for t in together]
        have = set(self.topics())
        self.whole = [_relative(t) for t in whole if _relative(t) in have]
        #: windows read of the together topics: [start, stop) (ns) and their messages
        self._windows: list[tuple[int, int, dict[str, Logged]]] = []
        self._whole: dict[str, Logged] | None = None

    def __enter__(self) -> BagSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the bag."""
        if self._bag is not None:
            self._bag.__exit__()

    def _read(self, topics: Sequence[str], start: int | None, stop: int | None
              ) -> dict[str, Logged]:
        assert self._bag is not None
        return _read(self._bag, topics, None, start, stop)

    def topics(self) -> list[str]:
        """Topic names (without the leading ``/``)."""
        return [_relative(t) for t in self.summary.topics]

    def series(self, topic: str, start: float | None = None,
               stop: float | None = None) -> Series:
        """Messages of ``topic`` logged in [start, stop) (s); the whole topic by default."""
        name = _relative(topic)
        if self._bag is None:
            return read_bag(self.path, [topic], start=start, stop=stop)[name]
        a, b = _ns(start), _ns(stop)
        if name in self.whole:
            if self._whole is None:
                self._whole = self._read(self.whole, None, None)
            return self._whole[name].between(a, b).series
        if b is None or name not in self.together:
            return self._read([topic], a, b)[name].series
        out = self._window(self._first if a is None else a, b)[name].series
        if self.progress is not None:
            total = self.summary.end - self.summary.start
            self.progress(round(min(max(b / 1e9 - self.summary.start, 0.0), total)),
                          round(total))
        return out

    def _window(self, a: int, b: int) -> dict[str, Logged]:
        """The together topics logged in [a, b) (ns), read but for what a kept window
        holds; a window that extends a kept one replaces it, another the older one."""
        for i, (c, d, held) in enumerate(self._windows):
            if (c <= a or c <= self._first) and a < d:  # it holds all messages of [a, min(b, d))
                if b <= d:
                    return {t: x.between(a, b) for t, x in held.items()}
                later = self._read(self.together, d, b)
                got = {t: x.between(a, None).then(later[t]) for t, x in held.items()}
                self._windows = [*self._windows[:i], *self._windows[i + 1:], (a, b, got)]
                return got
        got = self._read(self.together, a, b)
        self._windows = [*self._windows[-1:], (a, b, got)]
        return got
