"""Recovery of a bag whose recording was killed: :func:`reindex` rebuilds ``metadata.yaml``
from the storage files, checking every chunk. A file without a valid footer (the recording was
killed) or with damaged chunks is scanned record by record with the mcap stream reader; the
messages of every intact chunk, up to the first unreadable record outside a chunk, are written
to a new, well-formed file that replaces it, and the damaged original is kept beside it as
``<file>.damaged``. What could not be read is reported in bytes and, where the indexes count
them, in messages. The messages of a journal whose chunk never reached the file
(:mod:`dampest_ros.io.recorder`) are added.
"""

from __future__ import annotations

import itertools
import os
import re
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Footer, Message, MessageIndex, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.rosbag2.metadata import parse_qos

from dampest_ros.io import cdr
from dampest_ros.io.bag_metadata import (
    FileRecord,
    TopicRecord,
    write_metadata,
)
from dampest_ros.io.mcap_check import verify_file
from dampest_ros.io.recorder import (
    DEFAULT_CHUNK_SIZE,
    JOURNAL_HEADER,
    LIBRARY,
    PROFILE,
    TEMP_PATTERNS,
    BagBusyError,
    BagLock,
    journal_path,
)


@dataclass
class FileReport:
    """What :func:`reindex` found in one storage file."""

    name: str
    messages: int
    complete: bool
    recovered: bool = False
    lost_bytes: int = 0
    lost_messages: int = 0
    error: str = ""
    journal: int = 0  # messages of the chunk in progress, recovered from the journal
    unverified: str = ""  # why the file as indexed does not read back whole (empty: it does)


@dataclass
class ReindexReport:
    """What :func:`reindex` did: one entry per storage file, and the total."""

    path: Path
    files: list[FileReport]
    removed: list[str] = field(default_factory=list)  # partial files found and removed

    @property
    def messages(self) -> int:
        """Messages indexed in the new metadata."""
        return sum(f.messages for f in self.files)

    @property
    def lost_bytes(self) -> int:
        """Bytes of the storage files that could not be read."""
        return sum(f.lost_bytes for f in self.files)

    @property
    def verified(self) -> bool:
        """Every file as indexed reads back whole (every chunk and message checked)."""
        return not any(f.unverified for f in self.files)

    @property
    def lost_messages(self) -> int:
        """Messages known to be unreadable (counted by the indexes of damaged chunks or the
        file's summary; a chunk cut off by a killed recording has no index to count)."""
        return sum(f.lost_messages for f in self.files)


def _natural(p: Path) -> tuple[Any, ...]:
    return tuple(int(s) if s.isdigit() else s for s in re.split(r"(\d+)", p.name))


def _has_summary(path: Path) -> bool:
    """True when the file ends in a valid footer and summary rosbags can index."""
    try:
        with path.open("rb") as f:
            summary = make_reader(f).get_summary()
    except Exception:  # any failure to parse the file end: not indexable as it is
        return False
    return summary is not None and summary.statistics is not None


@dataclass
class _Scan:
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    complete: bool = False
    end: int = 0           # byte offset after the last complete record
    error: str = ""
    compression: str = ""
    damaged_bytes: int = 0      # bytes of chunks skipped as damaged
    damaged_messages: int = 0   # messages in them, by their message indexes
    untyped: int = 0            # messages of a channel whose record was lost
    undecodable: int = 0        # messages whose bytes do not deserialise as their type
    chunks: int = 0             # chunk records met (intact or not)
    journal: int = 0            # messages taken from the journal

    @property
    def damaged(self) -> bool:
        """Some bytes of the file could not be read."""
        return bool(self.error or self.damaged_bytes or self.untyped or self.undecodable
                    or not self.complete)


def _chunk_records(chunk: Chunk, scan: _Scan) -> list[Any] | None:
    """The records of a chunk, or None when it is damaged (CRC, compression, framing)."""
    try:
        return list(breakup_chunk(chunk, validate_crc=True))  # all or nothing
    except Exception as exc:  # any failure to unpack damaged bytes: the chunk is skipped
        scan.error = scan.error or f"damaged chunk ({type(exc).__name__}: {exc})"
        return None


def _records(path: Path, scan: _Scan) -> Iterator[Message]:
    """Messages of a file in file order, skipping damaged chunks (counted in ``scan`` with
    the messages their indexes list), up to its first incomplete or corrupt record outside
    a chunk; fills ``scan`` with schemas, channels, the readable extent and why it stopped."""
    size = path.stat().st_size
    with path.open("rb") as f:
        reader = StreamReader(f, emit_chunks=True, validate_crcs=False,
                              record_size_limit=max(size, 1))
        skipped = False  # the message indexes after a damaged chunk count its messages
        try:
            for record in reader.records:
                inner: list[Any] | None = [record]
                if isinstance(record, Chunk):
                    scan.chunks += 1
                    scan.compression = record.compression
                    inner = _chunk_records(record, scan)
                    skipped = inner is None
                    if skipped:
                        scan.damaged_bytes += f.tell() - scan.end
                elif isinstance(record, MessageIndex) and skipped:
                    scan.damaged_messages += len(record.records)
                for r in inner or ():
                    if isinstance(r, Schema):
                        scan.schemas[r.id] = r
                    elif isinstance(r, Channel):
                        scan.channels[r.id] = r
                    elif isinstance(r, Message):
                        yield r
                    elif isinstance(r, Footer):
                        scan.complete = True
                scan.end = f.tell()
        except (McapError, ValueError, EOFError, OSError) as exc:
            scan.error = f"{type(exc).__name__}: {exc}".rstrip(": ")
        except struct.error:
            scan.error = "truncated record"
        except Exception as exc:  # any other parse failure of damaged bytes stops the scan
            scan.error = f"{type(exc).__name__}: {exc}"


def _journal_records(path: Path, scan: _Scan) -> Iterator[Message]:
    """The messages of the journal of storage file ``path`` when its chunk is not in the
    file (its index is not below the chunks ``scan`` met), up to its first incomplete
    record; its schemas and channels join ``scan``'s."""
    journal = journal_path(path)
    if not journal.exists():
        return
    with journal.open("rb") as f:
        reader = StreamReader(f, skip_magic=True, validate_crcs=False,
                              record_size_limit=max(journal.stat().st_size, 1))
        try:
            for r in reader.records:
                if isinstance(r, Metadata) and r.name == JOURNAL_HEADER:
                    if int(r.metadata["chunk"]) < scan.chunks:
                        return  # its chunk reached the file
                elif isinstance(r, Schema):
                    scan.schemas.setdefault(r.id, r)
                elif isinstance(r, Channel):
                    scan.channels.setdefault(r.id, r)
                elif isinstance(r, Message):
                    scan.journal += 1
                    yield r
        except (McapError, ValueError, EOFError, struct.error):
            return  # the record being appended when the recorder was killed


@dataclass
class _Tally:
    counts: dict[int, int] = field(default_factory=dict)
    start: int = 2**63 - 1
    end: int = 0

    def add(self, m: Message) -> None:
        self.counts[m.channel_id] = self.counts.get(m.channel_id, 0) + 1
        self.start = min(self.start, m.log_time)
        self.end = max(self.end, m.log_time)


def _recover(path: Path, chunk_size: int, known: _Scan) -> tuple[_Scan, _Tally]:
    """Copy the readable messages of a damaged file into a well-formed one in its place
    (``known``: schemas and channels of its summary, for those lost in damaged chunks)."""
    scan, tally = _Scan(schemas=dict(known.schemas), channels=dict(known.channels)), _Tally()
    tmp = path.with_name(path.name + ".recovering")
    tmp.unlink(missing_ok=True)
    try:
        writer = _copy_readable(path, tmp, chunk_size, scan, tally)
    except BaseException:
        tmp.unlink(missing_ok=True)  # never a partial file left behind
        raise
    if writer is None:  # not even a channel is readable: leave the file as it is
        tmp.unlink()
        return scan, tally
    path.replace(path.with_name(path.name + ".damaged"))
    tmp.replace(path)
    return scan, tally


def _undecodable(scan: _Scan, m: Message) -> bool:
    """Whether message ``m`` of a known channel is of a type the ROS 2 Jazzy definitions
    know and does not deserialise as it."""
    schema = scan.schemas.get(scan.channels[m.channel_id].schema_id)
    msgtype = schema.name if schema is not None else ""
    return msgtype in cdr.typestore().fielddefs and bool(cdr.undecodable(msgtype, m.data))


def _copy_readable(path: Path, tmp: Path, chunk_size: int, scan: _Scan, tally: _Tally
                   ) -> Any:
    """Write the readable messages of ``path`` to ``tmp``; the writer, or None when no
    channel is readable."""
    with tmp.open("xb") as out:
        writer: Any = None  # McapWriter once the first channel is known
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}

        def channel(cid: int) -> int:
            nonlocal writer
            if writer is None:
                comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}.get(
                    scan.compression, CompressionType.NONE)
                writer = McapWriter(out, chunk_size=chunk_size, compression=comp)
                writer.start(PROFILE, LIBRARY + ", recovered by reindex")
            if cid not in channel_ids:
                ch = scan.channels[cid]
                if ch.schema_id and ch.schema_id not in schema_ids:
                    s = scan.schemas[ch.schema_id]
                    schema_ids[ch.schema_id] = writer.register_schema(s.name, s.encoding, s.data)
                channel_ids[cid] = writer.register_channel(
                    ch.topic, ch.message_encoding, schema_ids.get(ch.schema_id, 0), ch.metadata)
            return channel_ids[cid]

        for m in itertools.chain(_records(path, scan), _journal_records(path, scan)):
            if m.channel_id not in scan.channels:
                scan.untyped += 1  # a message whose channel record was lost cannot be typed
                continue
            if _undecodable(scan, m):
                scan.undecodable += 1
                continue
            cid = channel(m.channel_id)
            assert writer is not None
            writer.add_message(cid, m.log_time, m.data, m.publish_time, m.sequence)
            tally.add(m)
        for cid in scan.channels:  # topics without a readable message keep their channel
            channel(cid)
        if writer is not None:
            writer.finish()
            out.flush()
            os.fsync(out.fileno())
    return writer


def _summarised(path: Path) -> tuple[_Scan, _Tally]:
    """Schemas, channels and counts of a complete file, from its summary."""
    scan, tally = _Scan(complete=True), _Tally()
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    scan.schemas = dict(summary.schemas)
    scan.channels = dict(summary.channels)
    st = summary.statistics
    tally.counts = {int(k): int(v) for k, v in st.channel_message_counts.items() if v}
    if st.message_count:
        tally.start, tally.end = st.message_start_time, st.message_end_time
    scan.end = path.stat().st_size
    return scan, tally


def _metadata_value(channel: Channel, key: str) -> str:
    return str(channel.metadata.get(key, ""))


def _index(mcap_path: Path, chunk_size: int) -> tuple[_Scan, _Tally, FileReport]:
    """Schemas, channels, counts and the report of one storage file; a file that is not
    complete and intact (no summary, or a damaged chunk) is rewritten with its readable
    messages (:func:`_recover`)."""
    size = mcap_path.stat().st_size
    known, counted = (_summarised(mcap_path) if _has_summary(mcap_path)
                      else (_Scan(), _Tally()))
    if known.complete:  # the summary is there: are the chunks it indexes intact too?
        check = _Scan(schemas=dict(known.schemas), channels=dict(known.channels))
        for _ in _records(mcap_path, check):
            pass
        if not check.damaged and not verify_file(mcap_path)[1]:  # read as io.bag reads it
            return known, counted, FileReport(mcap_path.name, sum(counted.counts.values()),
                                              complete=True)
    scan, tally = _recover(mcap_path, chunk_size, known)
    readable = sum(tally.counts.values())
    lost = max(scan.damaged_messages + scan.untyped + scan.undecodable,
               sum(counted.counts.values()) - readable)
    # a cut-off last chunk whose messages the journal held loses no message
    tail = 0 if scan.complete or scan.journal else size - scan.end
    error = scan.error or (f"{scan.undecodable} messages that do not deserialise"
                           if scan.undecodable else "")
    return scan, tally, FileReport(mcap_path.name, readable, complete=False, recovered=True,
                                   lost_bytes=scan.damaged_bytes + tail, lost_messages=lost,
                                   error=error, journal=scan.journal,
                                   unverified=_read_back(mcap_path, scan, tally))


def _read_back(mcap_path: Path, scan: _Scan, tally: _Tally) -> str:
    """Why the rewritten file does not read back whole with the counts indexed (empty when
    it does)."""
    if not scan.channels:  # nothing readable: the file is left out of the metadata
        return ""
    counts, why = verify_file(mcap_path)
    indexed = {ch.topic: 0 for ch in scan.channels.values()}
    for cid, n in tally.counts.items():
        indexed[scan.channels[cid].topic] += n
    if why or {t: counts.get(t, 0) for t in indexed} != indexed:
        return (f"{sum(counts.values())} of its {sum(indexed.values())} messages read back"
                f"{': ' + why if why else ''}")
    return ""


def reindex(path: str | Path, *, chunk_size: int = DEFAULT_CHUNK_SIZE) -> ReindexReport:
    """Rebuild ``metadata.yaml`` of an MCAP bag from its storage files.

    Every file is read through, its chunks checked against their CRCs. A complete, intact
    file is indexed from its summary. Any other (the recording was killed, or bytes of a
    chunk are damaged) is read record by record, damaged chunks skipped and counted, up to
    its first unreadable record outside a chunk; the readable messages are written to a new
    file under the same name and the original is kept as ``<file>.damaged``. Partial files
    a killed recorder or reindex left (:data:`TEMP_PATTERNS`) are removed first; an existing
    ``metadata.yaml`` is replaced. The bag is locked meanwhile (:class:`BagLock`).

    Parameters
    ----------
    path : str or Path
        The bag directory.
    chunk_size : int
        Chunk size of rewritten files (bytes).

    Returns
    -------
    ReindexReport

    Raises
    ------
    FileNotFoundError
        If ``path`` is not a directory holding ``.mcap`` files.
    BagBusyError
        If a recorder is still writing the bag.
    """
    path = Path(path)
    if not path.is_dir():
        raise FileNotFoundError(f"{path} is not a bag directory")
    try:
        lock = BagLock(path, "dampest reindex")
    except BagBusyError as exc:
        raise BagBusyError(f"{exc}: reindex would rewrite the file being written; stop the "
                           "recorder first (Ctrl-C or SIGTERM close the bag and write its "
                           "metadata.yaml, no reindex needed)") from None
    try:
        removed = sorted(p.name for pattern in TEMP_PATTERNS for p in path.glob(pattern))
        for name in removed:
            (path / name).unlink()
        report = _reindex(path, chunk_size)
    finally:
        lock.release()
    report.removed = removed
    return report


def _reindex(path: Path, chunk_size: int) -> ReindexReport:
    """:func:`reindex` of a locked bag directory."""
    mcaps = sorted(path.glob("*.mcap"), key=_natural)
    if not mcaps:
        kinds = sorted({p.suffix for p in path.iterdir()})
        raise FileNotFoundError(f"no .mcap storage file in {path} (found {kinds}); "
                                "reindex supports MCAP bags only")
    topics: dict[tuple[str, str], TopicRecord] = {}
    files: list[FileRecord] = []
    reports: list[FileReport] = []
    for mcap_path in mcaps:
        scan, tally, report = _index(mcap_path, chunk_size)
        journal_path(mcap_path).unlink(missing_ok=True)  # used, or its chunk is in the file
        reports.append(report)
        if not scan.channels:
            continue  # nothing readable: left out of the metadata, kept on disk
        record = FileRecord(mcap_path.name, report.messages, tally.start, tally.end)
        files.append(record)
        for cid, ch in scan.channels.items():
            schema = scan.schemas.get(ch.schema_id)
            msgtype = schema.name if schema is not None else ""
            key = (ch.topic, msgtype)
            t = topics.get(key)
            if t is None:
                qos_text = _metadata_value(ch, "offered_qos_profiles")
                qos = parse_qos(qos_text) if qos_text else []
                t = TopicRecord(len(topics) + 1, ch.topic, msgtype, qos,
                                schema.data.decode() if schema is not None else "",
                                _metadata_value(ch, "topic_type_hash"))
                topics[key] = t
            t.count += tally.counts.get(cid, 0)
    write_metadata(path, list(topics.values()), files)
    return ReindexReport(path, reports)
