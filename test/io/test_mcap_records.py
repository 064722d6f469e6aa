"""Records of an MCAP chunk found with numpy: the offsets a record-by-record parse finds, and
where it stops on damaged bytes."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from dampest_ros.io.mcap_records import HEADER, at_every_byte, record_starts

OPCODES = (0x03, 0x04, 0x05)


def record(op: int, body: bytes) -> bytes:
    return struct.pack("<BQ", op, len(body)) + body


def chunk(n: int, seed: int = 0) -> tuple[bytes, list[int]]:
    """``n`` records of random opcode and random bodies (full of bytes 3, 4 and 5, so that
    most candidates are false), and their offsets."""
    rng = np.random.default_rng(seed)
    raw, starts = b"", []
    for _ in range(n):
        starts.append(len(raw))
        body = rng.choice(np.array([3, 4, 5, 0, 9], np.uint8), int(rng.integers(0, 60)))
        raw += record(int(rng.choice(OPCODES)), body.tobytes())
    return raw, starts


def test_at_every_byte_reads_unaligned_values() -> None:
    raw = bytes(range(12))
    u64 = at_every_byte(raw, "<u8")
    assert u64.shape == (5,)
    assert u64[3] == struct.unpack_from("<Q", raw, 3)[0] == 0x0A09080706050403
    rows = at_every_byte(raw, np.dtype((np.void, 3)))[np.array([0, 7])]
    assert [bytes(r) for r in rows] == [b"\x00\x01\x02", b"\x07\x08\x09"]


@pytest.mark.parametrize("n", [1, 2, 3, 700])
def test_a_whole_chunk_gives_every_record(n: int) -> None:
    raw, starts = chunk(n, seed=n)
    found, end = record_starts(raw, OPCODES)
    assert found.tolist() == starts
    assert end == len(raw)


def test_an_empty_chunk_is_whole() -> None:
    found, end = record_starts(b"", OPCODES)
    assert (found.size, end) == (0, 0)


def test_reading_stops_at_the_first_damaged_record() -> None:
    raw, starts = chunk(300, seed=7)
    at = starts[120]
    flipped = raw[:at] + b"\x07" + raw[at + 1:]  # an unknown opcode
    found, end = record_starts(flipped, OPCODES)
    assert found.tolist() == starts[:120] and end == at
    longer = raw[:at + 1] + struct.pack("<Q", len(raw)) + raw[at + HEADER:]  # past the end
    found, end = record_starts(longer, OPCODES)
    assert found.tolist() == starts[:120] and end == at
    cut = raw[:starts[-1] + 4]  # the last record's header cut short
    found, end = record_starts(cut, OPCODES)
    assert found.tolist() == starts[:-1] and end == starts[-1]
    found, end = record_starts(b"\x05\x00\x00", OPCODES)
    assert (found.size, end) == (0, 0)


def test_a_hint_is_taken_only_when_it_is_the_chain() -> None:
    """The message indexes' offsets replace the search when they chain from the first byte
    to the last; one missing, one extra or one on a damaged record: the search, which finds
    the same records or stops at the same byte as without a hint."""
    raw, starts = chunk(300, seed=3)
    hint = np.array(starts, np.int64)
    found, end = record_starts(raw, OPCODES, hint)
    assert found is hint and end == len(raw)
    for wrong in (np.delete(hint, 150), np.insert(hint, 150, hint[150] + 1), hint[1:]):
        found, end = record_starts(raw, OPCODES, wrong)
        assert found.tolist() == starts and end == len(raw)
    at = starts[200]
    flipped = raw[:at] + b"\x07" + raw[at + 1:]
    found, end = record_starts(flipped, OPCODES, hint)
    assert found.tolist() == starts[:200] and end == at
