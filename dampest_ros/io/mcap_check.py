"""Checked reading of an indexed MCAP storage file: every chunk read is checked as it is
read, so a damaged chunk is never taken for a whole one.

rosbags' MCAP reader trusts the summary: a chunk whose index lies about its times or channels
is silently left out of a time window, a record whose opcode was flipped is skipped, and the
chunk CRC of rosbags' own writer is 0 ("not checked" in MCAP). Here, for each file:

- once when opened (:func:`check_index`), every chunk record's header is compared with its
  index entry (opcode, length, times, sizes, compression), and the per-channel counts of the
  chunk indexes with the file's statistics: one small read per chunk, no message read;
- as each chunk is read (:func:`messages`), it is decompressed (size and, when not 0, CRC
  checked), every record in it is parsed to its end (a known opcode, a length within the
  chunk, log times within the chunk's) and its messages are counted per channel against the
  chunk's message indexes.

A failure raises :class:`DamagedChunkError`, naming the file, the chunk's byte offset and log
time, and how many messages it holds. The bytes of a chunk are read once, as rosbags reads
them; memory holds one chunk per chunk being merged.
"""

from __future__ import annotations

import heapq
import struct
from collections import Counter
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import NamedTuple

from rosbags.interfaces import Connection
from rosbags.rosbag2.storage_mcap import ChunkInfo, McapReader, decompress

from dampest_ros.io import cdr

#: Opcodes of the records a chunk may hold: schema, channel, message.
_IN_CHUNK = frozenset({0x03, 0x04, 0x05})
_OP_CHUNK, _OP_MESSAGE = 0x06, 0x05
#: Chunk record: opcode, record length, start and end time, uncompressed size, CRC.
_HEAD = struct.Struct("<BQQQQI")
_U32, _U64 = struct.Struct("<I"), struct.Struct("<Q")
#: Message record after opcode and length: channel id, sequence, log and publish time.
_MESSAGE = struct.Struct("<HIQQ")


class DamagedFileError(ValueError):
    """Bytes of a storage file that cannot be read whole (its message says which)."""


class DamagedChunkError(DamagedFileError):
    """A chunk of an MCAP file that cannot be read whole.

    Parameters
    ----------
    file : str
        Name of the storage file.
    chunk : ChunkInfo
        Its index entry (offset, log times, message counts per channel).
    reason : str
        What is wrong, in a few words.
    """

    def __init__(self, file: str, chunk: ChunkInfo, reason: str) -> None:
        self.file = file
        self.offset = chunk.chunk_start_offset
        self.start = chunk.message_start_time / 1e9
        self.messages = sum(chunk.channel_count.values())
        super().__init__(f"{file}, chunk at byte {self.offset} (log time {self.start:.3f} s, "
                         f"{self.messages} messages unreadable): {reason}")


def _name(storage: McapReader) -> str:
    return str(getattr(storage.path, "name", storage.path))


def _read_at(storage: McapReader, offset: int, size: int) -> bytes:
    bio = storage.bio
    assert bio is not None
    bio.seek(offset)
    return bio.read(size)


def _check_header(storage: McapReader, chunk: ChunkInfo) -> None:
    """The chunk record at the indexed offset agrees with its index entry."""
    comp = chunk.compression.encode()
    size = _HEAD.size + 4 + len(comp) + 8
    raw = _read_at(storage, chunk.chunk_start_offset, size)
    if len(raw) != size:
        raise DamagedChunkError(_name(storage), chunk, "the file ends inside the chunk")
    op, length, start, end, usize, _ = _HEAD.unpack_from(raw)
    (clen,) = _U32.unpack_from(raw, _HEAD.size)
    (csize,) = _U64.unpack_from(raw, _HEAD.size + 4 + len(comp))
    found = (op, length + 9, start, end, usize, raw[_HEAD.size + 4:-8], csize, clen)
    indexed = (_OP_CHUNK, chunk.chunk_length, chunk.message_start_time,
               chunk.message_end_time, chunk.uncompressed_size, comp, chunk.compressed_size,
               len(comp))
    if found != indexed:
        raise DamagedChunkError(_name(storage), chunk, "the chunk record and its index disagree")


def check_index(storage: McapReader) -> None:
    """Check an opened file's chunk index against its chunks' headers and its statistics.

    Parameters
    ----------
    storage : McapReader
        rosbags' reader of one MCAP file, opened.

    Raises
    ------
    DamagedChunkError
        If a chunk record does not match its index entry.
    DamagedFileError
        If the chunk indexes count other messages per channel than the statistics.
    """
    for chunk in storage.chunks:
        _check_header(storage, chunk)
    stats = storage.statistics
    if stats is None or not storage.chunks:
        return
    indexed: Counter[int] = Counter()
    for chunk in storage.chunks:
        indexed.update(chunk.channel_count)
    counted = stats.channel_message_counts
    wrong = [f"{ch.topic} {indexed[cid]} (its statistics {counted.get(cid, 0)})"
             for cid, ch in sorted(storage.channels.items())
             if indexed[cid] != counted.get(cid, 0)]
    if wrong or len(storage.chunks) != stats.chunk_count:
        raise DamagedFileError(f"{_name(storage)}: its summary is inconsistent: its "
                               f"{len(storage.chunks)} chunk indexes (its statistics "
                               f"{stats.chunk_count}) count {', '.join(wrong) or 'as counted'}")


def _records(storage: McapReader, chunk: ChunkInfo) -> bytes:
    """The decompressed records of a chunk (size and CRC checked)."""
    head = chunk.chunk_start_offset + _HEAD.size
    (crc,) = _U32.unpack(_read_at(storage, head - 4, 4))
    data = _read_at(storage, head + 4 + len(chunk.compression) + 8, chunk.compressed_size)
    try:
        return decompress(data, chunk.compression, chunk.uncompressed_size, crc)
    except Exception as exc:  # any failure to decompress damaged bytes
        raise DamagedChunkError(_name(storage), chunk, f"{type(exc).__name__}: {exc}") from None


class _Msg(NamedTuple):
    log_time: int
    offset: int      # 0 for the sentinel that opens a chunk in the merge
    connection: Connection | None
    data: bytes


def _parse(storage: McapReader, chunk: ChunkInfo, cmap: dict[int, Connection],
           start: int, stop: int) -> list[_Msg]:
    """Every record of a chunk parsed to its end, its messages counted per channel against
    its message indexes; the messages of ``cmap``'s channels in [start, stop), in log-time
    order."""
    raw = _records(storage, chunk)
    view, pos, size = memoryview(raw), 0, len(raw)
    first, last, offset = chunk.message_start_time, chunk.message_end_time, chunk.chunk_start_offset
    u64, message, head = _U64.unpack_from, _MESSAGE.unpack_from, _MESSAGE.size
    counts: dict[int, int] = {}
    out: list[_Msg] = []
    while pos < size:
        if pos + 9 > size:
            raise DamagedChunkError(_name(storage), chunk, f"a record cut short at byte {pos}")
        op, (length,) = raw[pos], u64(raw, pos + 1)
        body, pos = pos + 9, pos + 9 + length
        if op not in _IN_CHUNK or pos > size or (op == _OP_MESSAGE and length < head):
            raise DamagedChunkError(_name(storage), chunk, f"a damaged record at byte "
                                    f"{body - 9} (opcode {op:#04x}, length {length})")
        if op != _OP_MESSAGE:
            continue
        cid, _, log_time, _ = message(raw, body)
        if not first <= log_time <= last:
            raise DamagedChunkError(_name(storage), chunk, f"a message at byte {body - 9} "
                                    "logged outside the chunk's time range")
        counts[cid] = counts.get(cid, 0) + 1
        if cid in cmap and start <= log_time < stop:
            out.append(_Msg(log_time, offset, cmap[cid], bytes(view[body + head:pos])))
    if counts != {k: v for k, v in chunk.channel_count.items() if v}:
        raise DamagedChunkError(_name(storage), chunk, f"it holds {sum(counts.values())} messages, "
                           f"its message indexes {sum(chunk.channel_count.values())}")
    out.sort(key=lambda m: m.log_time)
    return out


def _chunk(storage: McapReader, chunk: ChunkInfo, cmap: dict[int, Connection],
           start: int, stop: int) -> Iterator[_Msg]:
    yield _Msg(chunk.message_start_time, 0, None, b"")  # read only when the merge gets here
    yield from _parse(storage, chunk, cmap, start, stop)


def messages(storage: McapReader, connections: Collection[Connection],
             start: int | None = None, stop: int | None = None
             ) -> Iterator[tuple[Connection, int, bytes]]:
    """Messages of an indexed MCAP file in log-time order, each chunk checked as it is read.

    Parameters
    ----------
    storage : McapReader
        rosbags' reader of one MCAP file, opened, with chunk indexes (``storage.chunks``).
    connections : collection of Connection
        The file's connections to read.
    start, stop : int, optional
        Log-time window [start, stop) (ns).

    Yields
    ------
    (Connection, int, bytes)
        Connection, log time (ns) and serialized message.

    Raises
    ------
    DamagedChunkError
        At the first chunk that cannot be read whole.
    """
    cmap = {c.id: c for c in connections}
    lo, hi = -1 if start is None else start, 2**63 if stop is None else stop
    chunks = [_chunk(storage, c, cmap, lo, hi) for c in storage.chunks
              if lo <= c.message_end_time and c.message_start_time < hi
              and any(c.channel_count.get(cid, 0) for cid in cmap)]
    for m in heapq.merge(*chunks):
        if m.offset:
            assert m.connection is not None
            yield m.connection, m.log_time, m.data


def verify_file(path: Path) -> tuple[Counter[str], str]:
    """Read an MCAP storage file whole, as :mod:`dampest_ros.io.bag` reads it: its index
    checked, every chunk checked and every message deserialised (types the ROS 2 Jazzy
    definitions know).

    Parameters
    ----------
    path : Path
        The ``.mcap`` file.

    Returns
    -------
    counts : Counter of str to int
        Messages read per topic (as stored, ``/imu/data``), up to the first failure.
    error : str
        The first failure (empty when the file was read whole).
    """
    counts: Counter[str] = Counter()
    known = cdr.typestore().fielddefs
    try:
        storage = McapReader(path)
        storage.open()
    except Exception as exc:  # any failure to open damaged bytes: said, not raised
        return counts, f"{type(exc).__name__}: {exc}"
    try:
        check_index(storage)
        source = (messages(storage, storage.connections) if storage.chunks else
                  storage.messages(storage.connections))
        for conn, t, data in source:
            if conn.msgtype in known and (why := cdr.undecodable(conn.msgtype, data)):
                return counts, (f"a message of {conn.topic} at log time {t / 1e9:.3f} s does "
                                f"not deserialise as {conn.msgtype}: {why}")
            counts[conn.topic] += 1
    except Exception as exc:  # any failure of damaged bytes: said, not raised
        return counts, str(exc) if isinstance(exc, DamagedFileError) else (
            f"{type(exc).__name__}: {exc}")
    finally:
        storage.close()
    return counts, ""
