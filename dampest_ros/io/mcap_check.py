"""Checked reading of an indexed MCAP storage file: every chunk read is checked as it is
read, so a damaged chunk is never taken for a whole one.

rosbags' MCAP reader trusts the summary: a chunk whose index lies about its times or channels
is silently left out of a time window, a record whose opcode was flipped is skipped, and the
chunk CRC of rosbags' own writer is 0 ("not checked" in MCAP). Here, for each file:

- once when opened (:func:`check_index`), every chunk record's header is compared with its
  index entry (opcode, length, times, sizes, compression), and the per-channel counts of the
  chunk indexes with the file's statistics: one small read per chunk, no message read;
- as each chunk is read (:func:`batches`, :func:`messages`), it is decompressed (size and,
  when not 0, CRC checked), every record in it is parsed to its end (a known opcode, a length
  within the chunk, log times within the chunk's; with numpy over the chunk's bytes,
  :mod:`dampest_ros.io.mcap_records`) and its messages are counted per channel against the
  chunk's message indexes; the messages asked for are copied out a channel at a time.

A failure raises :class:`DamagedChunkError`, naming the file, the chunk's byte offset and log
time, and how many messages it holds. The bytes of a chunk are read once, as rosbags reads
them; memory holds one chunk and the messages asked for of the chunks whose log times
overlap.
"""

from __future__ import annotations

import struct
from collections import Counter
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray
from rosbags.interfaces import Connection
from rosbags.rosbag2.storage_mcap import ChunkInfo, McapReader, decompress

from dampest_ros.io import cdr, mcap_records

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


class Batch(NamedTuple):
    """Messages of one connection in log-time order.

    ``chunk`` and ``position`` (byte offset of the chunk in the file, of the record in the
    chunk) order messages of equal log time as rosbags does.
    """

    connection: Connection
    log_time: NDArray[np.int64]   # (n,) ns
    chunk: NDArray[np.int64]      # (n,)
    position: NDArray[np.int64]   # (n,)
    data: cdr.Messages            # (n,) serialized messages


def _rows(raw: bytes, offsets: NDArray[np.int64], sizes: NDArray[np.int64]) -> cdr.Messages:
    """Bytes [offsets, offsets + sizes) of ``raw``: one void array when the sizes agree."""
    if len(sizes) and sizes.min() == sizes.max() > 0:
        return mcap_records.at_every_byte(raw, np.dtype((np.void, int(sizes[0]))))[offsets]
    return [raw[o:o + n] for o, n in zip(offsets.tolist(), sizes.tolist(), strict=True)]


def _indexed(storage: McapReader, chunk: ChunkInfo) -> NDArray[np.int64] | None:
    """Where the chunk's message indexes say its messages start (offsets in its records),
    sorted; None when the indexes lie outside the bytes after the chunk."""
    base = chunk.chunk_start_offset + chunk.chunk_length
    raw = _read_at(storage, base, chunk.message_index_length)
    parts = [np.zeros(0, np.uint64)]
    for cid, offset in chunk.message_index_offsets.items():
        # a message index record: opcode, length, channel id (u16), byte length (u32),
        # then (log time, offset) uint64 pairs
        at, count = offset - base + 15, chunk.channel_count.get(cid, 0)
        if at < 15 or at + 16 * count > len(raw):
            return None
        parts.append(np.frombuffer(raw, "<u8", 2 * count, at)[1::2])
    starts = np.sort(np.concatenate(parts))
    return None if len(starts) and starts[-1] >= 2**62 else starts.astype(np.int64)


def _field(raw: bytes, dtype: str, offsets: NDArray[np.int64]) -> NDArray[Any]:
    """The ``dtype`` values at byte ``offsets`` of ``raw``."""
    if not len(offsets):
        return np.zeros(0, dtype)
    return mcap_records.at_every_byte(raw, dtype)[offsets]


def _damaged_record(pos: int, op: int, length: int) -> str:
    return f"a damaged record at byte {pos} (opcode {op:#04x}, length {length})"


def _broken_at(raw: bytes, end: int) -> str:
    """Why the record at ``end`` ends the chunk's records early."""
    if end + mcap_records.HEADER > len(raw):
        return f"a record cut short at byte {end}"
    return _damaged_record(end, raw[end], _U64.unpack_from(raw, end + 1)[0])


def _parse(storage: McapReader, chunk: ChunkInfo, cmap: dict[int, Connection],
           start: int, stop: int) -> list[Batch]:
    """Every record of a chunk parsed to its end, its messages counted per channel against
    its message indexes; the messages of ``cmap``'s channels in [start, stop), one batch
    per channel."""
    raw = _records(storage, chunk)
    starts, end = mcap_records.record_starts(raw, _IN_CHUNK, _indexed(storage, chunk))
    is_msg = np.frombuffer(raw, np.uint8)[starts] == _OP_MESSAGE
    msg, size = starts[is_msg], _field(raw, "<u8", starts[is_msg] + 1).astype(np.int64)
    body = msg + mcap_records.HEADER
    short = size < _MESSAGE.size
    log_time = _field(raw, "<u8", np.where(short, 0, body + 6))  # channel u16, sequence u32
    outside = ~short & ((log_time < chunk.message_start_time)
                        | (log_time > chunk.message_end_time))
    if (short | outside).any():
        i = int(np.argmax(short | outside))
        raise DamagedChunkError(_name(storage), chunk, _damaged_record(
            int(msg[i]), _OP_MESSAGE, int(size[i])) if short[i] else (
            f"a message at byte {msg[i]} logged outside the chunk's time range"))
    if end < len(raw):
        raise DamagedChunkError(_name(storage), chunk, _broken_at(raw, end))
    cid = _field(raw, "<u2", body)
    ids, counts = np.unique(cid, return_counts=True)
    if dict(zip(ids.tolist(), counts.tolist(), strict=True)) != {
            k: v for k, v in chunk.channel_count.items() if v}:
        raise DamagedChunkError(_name(storage), chunk, f"it holds {len(cid)} messages, its "
                                f"message indexes {sum(chunk.channel_count.values())}")
    log_time = log_time.astype(np.int64)
    out = []
    for c, conn in cmap.items():
        (sel,) = np.nonzero((cid == c) & (log_time >= start) & (log_time < stop))
        sel = sel[np.argsort(log_time[sel], kind="stable")]
        if len(sel):
            data = _rows(raw, body[sel] + _MESSAGE.size, size[sel] - _MESSAGE.size)
            out.append(Batch(conn, log_time[sel], np.full(len(sel), chunk.chunk_start_offset),
                             msg[sel], data))
    return out


def _take(batch: Batch, index: NDArray[np.int64]) -> Batch:
    data = batch.data
    rows = data[index] if isinstance(data, np.ndarray) else [data[i] for i in index.tolist()]
    return Batch(batch.connection, batch.log_time[index], batch.chunk[index],
                 batch.position[index], rows)


def _joined(parts: list[Batch]) -> Batch:
    """One connection's batches as one, in (log time, chunk, position) order."""
    if len(parts) == 1:
        return parts[0]
    whole = Batch(parts[0].connection, np.concatenate([p.log_time for p in parts]),
                  np.concatenate([p.chunk for p in parts]),
                  np.concatenate([p.position for p in parts]), cdr.join([p.data for p in parts]))
    return _take(whole, np.lexsort((whole.position, whole.chunk, whole.log_time)))


def _split(pending: list[Batch], before: int) -> tuple[list[Batch], list[Batch]]:
    """The messages of ``pending`` logged before ``before`` (ns) and the others, one batch
    per connection each."""
    ready, rest = [], []
    for cid in dict.fromkeys(b.connection.id for b in pending):
        whole = _joined([b for b in pending if b.connection.id == cid])
        k = int(np.searchsorted(whole.log_time, before))
        if k:
            ready.append(_take(whole, np.arange(k)) if k < len(whole.log_time) else whole)
        if k < len(whole.log_time):
            rest.append(_take(whole, np.arange(k, len(whole.log_time))))
    return ready, rest


def batches(storage: McapReader, connections: Collection[Connection],
            start: int | None = None, stop: int | None = None) -> Iterator[list[Batch]]:
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
    list of Batch
        At most one per connection; every message of a list is logged no later than those
        of the lists after it (ties: as rosbags orders them, by chunk and position).

    Raises
    ------
    DamagedChunkError
        At the first chunk that cannot be read whole.
    """
    cmap = {c.id: c for c in connections}
    lo, hi = -1 if start is None else start, 2**63 if stop is None else stop
    chunks = sorted((c for c in storage.chunks
                     if lo <= c.message_end_time and c.message_start_time < hi
                     and any(c.channel_count.get(cid, 0) for cid in cmap)),
                    key=lambda c: (c.message_start_time, c.chunk_start_offset))
    pending: list[Batch] = []
    for chunk in chunks:
        ready, pending = _split(pending, chunk.message_start_time)
        if ready:
            yield ready
        pending += _parse(storage, chunk, cmap, lo, hi)
    if pending:
        yield _split(pending, 2**63)[0]


def messages(storage: McapReader, connections: Collection[Connection],
             start: int | None = None, stop: int | None = None
             ) -> Iterator[tuple[Connection, int, bytes]]:
    """:func:`batches` one message at a time, all connections merged in log-time order.

    Yields
    ------
    (Connection, int, bytes)
        Connection, log time (ns) and serialized message.
    """
    for group in batches(storage, connections, start, stop):
        which = np.concatenate([np.full(len(b.log_time), i) for i, b in enumerate(group)])
        index = np.concatenate([np.arange(len(b.log_time)) for b in group])
        keys = [np.concatenate([getattr(b, k) for b in group])
                for k in ("position", "chunk", "log_time")]
        for i in np.lexsort(keys).tolist():
            b, j = group[which[i]], int(index[i])
            yield b.connection, int(b.log_time[j]), bytes(b.data[j])


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
