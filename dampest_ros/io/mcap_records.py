"""The records of a decompressed MCAP chunk, found with numpy over the chunk's bytes.

A chunk's records follow each other: opcode (uint8), body length (uint64, little endian),
body. Where a record starts depends on every record before it, so instead of a Python step
per record every byte that could start one (a known opcode, a body within the chunk) is a
candidate, each candidate points to where its successor would start, and the chain from
byte 0 is followed by pointer doubling: about log2(records) numpy passes over the candidates.
The records found are exactly those a record-by-record parse finds, and it stops where that
parse would. Where the chunk's message indexes already list every record (no schema or
channel record inside it), checking that they chain from the first byte to the last
replaces the search.
"""

from __future__ import annotations

from collections.abc import Collection
from typing import Any

import numpy as np
from numpy.typing import DTypeLike, NDArray

#: Opcode (uint8) and body length (uint64) of every record.
HEADER = 9


def at_every_byte(raw: bytes, dtype: DTypeLike) -> NDArray[Any]:
    """``dtype`` values starting at every byte of ``raw`` (a view, no copy).

    Parameters
    ----------
    raw : bytes
    dtype : dtype
        Of itemsize s ≤ len(raw), e.g. ``'<u8'`` or ``np.dtype((np.void, s))``.

    Returns
    -------
    ndarray, shape (len(raw) - s + 1,)
        Element i is the value of bytes [i, i + s).
    """
    dt = np.dtype(dtype)
    return np.ndarray(shape=(len(raw) - dt.itemsize + 1,), dtype=dt, buffer=raw,
                      strides=(1,))


def _is_chain(raw: bytes, known: NDArray[np.bool_], starts: NDArray[np.int64]) -> bool:
    """Whether ``starts`` are exactly the records of ``raw``, from its first byte to its
    last, each of a known opcode."""
    n = len(raw)
    if not len(starts) or starts[0] != 0 or starts.max() > n - HEADER:
        return False
    length = at_every_byte(raw, "<u8")[starts + 1]
    if not known[np.frombuffer(raw, np.uint8)[starts]].all() or (length > n).any():
        return False
    nxt = starts + HEADER + length.astype(np.int64)
    return bool((nxt[:-1] == starts[1:]).all() and nxt[-1] == n)


def record_starts(raw: bytes, opcodes: Collection[int],
                  hint: NDArray[np.int64] | None = None) -> tuple[NDArray[np.int64], int]:
    """Byte offsets of the records read whole from the start of ``raw``.

    Parameters
    ----------
    raw : bytes
        A chunk's records, decompressed.
    opcodes : collection of int
        The opcodes a record may have.
    hint : ndarray of int64, shape (k,), optional
        Where the records may start, increasing (a chunk's message indexes): taken, without
        looking at the other bytes, when they are exactly the chain of records from the
        first byte to the last; else the chain is found over all bytes.

    Returns
    -------
    starts : ndarray of int64, shape (k,)
        Offset of each record, increasing; record i ends where record i + 1 starts.
    end : int
        ``len(raw)`` when the records fill ``raw`` exactly, else the offset of the first
        record that is cut short, has another opcode, or whose body runs past the end.
    """
    n = len(raw)
    if n < HEADER:
        return np.zeros(0, np.int64), 0
    known = np.zeros(256, dtype=bool)
    known[list(opcodes)] = True
    if hint is not None and _is_chain(raw, known, hint):
        return hint, n
    lo, hi = min(opcodes), max(opcodes)
    first = np.frombuffer(raw, np.uint8, n - HEADER + 1)
    cand = np.flatnonzero(first - np.uint8(lo) <= hi - lo)  # wraps below lo: one pass
    cand = cand[known[first[cand]]]
    length = at_every_byte(raw, "<u8")[cand + 1]
    fits = length <= (n - HEADER - cand).astype(np.uint64)
    cand = cand[fits]
    nxt = cand + HEADER + length[fits].astype(np.int64)
    if not len(cand) or cand[0] != 0:
        return np.zeros(0, np.int64), 0
    k = len(cand)
    idx = np.minimum(np.searchsorted(cand, nxt), k - 1)
    # successor node: a candidate, k (the end of raw) or k + 1 (no record starts there)
    up = np.where(cand[idx] == nxt, idx, np.where(nxt == n, k, k + 1))
    up = np.append(up, [k, k + 1])
    path = np.zeros(1, np.int64)
    while path[-1] < k:  # path: nodes 0 … 2^j - 1 steps from byte 0; up: 2^j steps
        path = np.concatenate([path, up[path]])
        up = up[up]
    starts = cand[path[path < k]]
    end = n if path[-1] == k else int(nxt[path[path < k][-1]])
    return starts, end
