"""What a rosbag2 bag says besides its messages: message definitions and type hashes, QoS
profiles, the topic and file records and ``metadata.yaml`` (version 9, as rosbag2 writes it on
Jazzy). The recorder (:mod:`dampest_ros.io.recorder`) and reindex
(:mod:`dampest_ros.io.reindex`) write bags with them.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import yaml
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2.metadata import dump_qos_v9
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

#: rosbag2's "infinite" duration in QoS profiles (RMW_DURATION_INFINITE).
INFINITE = QosTime(9223372036, 854775807)


@cache
def _store() -> Any:
    """A typestore of the ROS 2 Jazzy types, extended by :func:`message_definition`."""
    return get_typestore(Stores.ROS2_JAZZY)


def _find_msg_file(msgtype: str, prefixes: Sequence[str]) -> Path | None:
    pkg, _, name = msgtype.partition("/msg/")
    for prefix in prefixes:
        path = Path(prefix) / "share" / pkg / "msg" / f"{name}.msg"
        if path.is_file():
            return path
    return None


def message_definition(msgtype: str, prefixes: Sequence[str] | None = None
                       ) -> tuple[str, str]:
    """The rosbag2 message definition text and RIHS01 type hash of a message type.

    Types of ROS 2 Jazzy come from the rosbags typestore; other types (a vehicle's own
    messages) are loaded from ``share/<package>/msg/<Type>.msg`` under the ament prefixes,
    their dependencies too.

    Parameters
    ----------
    msgtype : str
        e.g. ``sensor_msgs/msg/Imu``.
    prefixes : sequence of str, optional
        Install prefixes to search; default: ``$AMENT_PREFIX_PATH``.

    Returns
    -------
    (msgdef, rihs01)

    Raises
    ------
    KeyError
        If the type (or one it uses) is neither known nor found as a ``.msg`` file.
    """
    store = _store()
    if prefixes is None:
        prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for _ in range(64):  # each round loads one missing type
        try:
            msgdef, _ = store.generate_msgdef(msgtype, ros_version=2)
            return str(msgdef), str(store.hash_rihs01(msgtype))
        except KeyError as exc:
            missing = str(exc.args[0]) if exc.args else msgtype
            if "/msg/" not in missing:
                missing = msgtype
            path = _find_msg_file(missing, prefixes)
            if path is None or missing in store.fielddefs:
                raise KeyError(f"no message definition for {missing!r} (not a ROS 2 Jazzy "
                               f"type and no .msg file under {list(prefixes)})") from None
            store.register(get_types_from_msg(path.read_text(), missing))
    raise KeyError(f"cannot resolve the definition of {msgtype!r}")


def make_qos(*, reliable: bool = True, transient_local: bool = False, depth: int = 10,
             history: QosHistory = QosHistory.KEEP_LAST) -> Qos:
    """A QoS profile as stored in bag metadata (infinite deadline, lifespan and lease)."""
    return Qos(history, depth,
               QosReliability.RELIABLE if reliable else QosReliability.BEST_EFFORT,
               QosDurability.TRANSIENT_LOCAL if transient_local else QosDurability.VOLATILE,
               INFINITE, INFINITE, QosLiveliness.AUTOMATIC, INFINITE, False)


def qos_time(ns: int) -> QosTime:
    """A QoS duration from nanoseconds; 0 (the rmw default) and ≥ 2**63 − 1 stay as rosbag2
    writes them (0 as 0, the maximum as :data:`INFINITE`)."""
    if ns >= 2**63 - 1:
        return INFINITE
    sec, nsec = divmod(int(ns), 1_000_000_000)
    return QosTime(sec, nsec)


def qos_yaml(profiles: Sequence[Qos]) -> str:
    return str(yaml.safe_dump(dump_qos_v9(list(profiles)), default_flow_style=False,
                              sort_keys=False)).strip()



@dataclass
class TopicRecord:
    """A topic of the bag: name, type, offered QoS, definition and message count."""

    id: int
    topic: str
    msgtype: str
    qos: list[Qos]
    msgdef: str
    type_hash: str
    count: int = 0


@dataclass
class FileRecord:
    """A storage file of the bag: name, message count and log-time range (ns)."""

    name: str
    count: int = 0
    start: int = 2**63 - 1
    end: int = 0
    counts: dict[int, int] = field(default_factory=dict)


def write_metadata(path: Path, topics: Sequence[TopicRecord], files: Sequence[FileRecord]
                   ) -> None:
    """Write ``metadata.yaml`` (rosbag2 version 9) atomically.

    Chunk compression inside MCAP files is not bag-level compression: rosbag2 leaves
    ``compression_format``/``compression_mode`` empty for it, and so does this.
    """
    counted = [f for f in files if f.count]
    start = min((f.start for f in counted), default=0)
    end = max((f.end for f in counted), default=0)

    def nanoseconds(n: int) -> dict[str, int]:
        return {"nanoseconds": int(n)}

    info = {
        "version": 9,
        "storage_identifier": "mcap",
        "duration": nanoseconds(end - start),
        "starting_time": {"nanoseconds_since_epoch": int(start)},
        "message_count": sum(f.count for f in files),
        "topics_with_message_count": [
            {"topic_metadata": {"name": t.topic, "type": t.msgtype,
                                "serialization_format": "cdr",
                                "offered_qos_profiles": dump_qos_v9(list(t.qos)),
                                "type_description_hash": t.type_hash},
             "message_count": t.count}
            for t in topics],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [f.name for f in files],
        "files": [{"path": f.name,
                   "starting_time": {"nanoseconds_since_epoch": int(f.start if f.count else 0)},
                   "duration": nanoseconds(f.end - f.start if f.count else 0),
                   "message_count": f.count} for f in files],
        "custom_data": None,
        "ros_distro": "jazzy",
    }
    tmp = path / "metadata.yaml.tmp"
    try:
        tmp.write_text(yaml.safe_dump({"rosbag2_bagfile_information": info},
                                      default_flow_style=False, sort_keys=False))
        tmp.replace(path / "metadata.yaml")
    finally:
        tmp.unlink(missing_ok=True)  # never a partial metadata file left behind
