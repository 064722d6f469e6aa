"""Reading CSV tables as logs come: numeric columns taken by name, cells that are not used
left alone, time in any unit.

Shared by the single-file log (:mod:`dampest_ros.io.csv`) and the folder of per-topic files
(:mod:`dampest_ros.io.csv_folder`). Every error is a :class:`CsvError`, one line naming the
file, and where it applies the line of the file (1 = the header) and the column.

**Time units.** A time column may count seconds, milliseconds, microseconds or nanoseconds
(``rostopic echo -p`` and most bag-to-CSV tools write integer nanoseconds).
:func:`time_unit` decides from the values alone:

1. *A date*: when the first stamp read in one of the units is a Unix time between 1973 and
   2286 (10⁸ … 10¹⁰ s) and the median step in that unit is at most 10 s, that unit (the
   units are a factor 1000 apart, so at most one fits);
2. *Time from some start* (simulation, a logger's own clock): the largest unit in which the
   median step is at most 1 s, i.e. the streams are taken to run at 1 Hz or faster.

The unit found is named on stderr by the commands (for a single CSV when it is not seconds),
so a wrong guess is seen.

**Size.** A file is size-checked before anything of it is read: over :func:`max_bytes`
(:data:`MAX_MB` MB, or ``DAMPEST_MAX_CSV_MB``) it is refused, naming its size, the limit and
what to do, since reading a table takes several times its size in memory (a 2 GB file took
8–16 GB). The header line is read up to :data:`MAX_HEADER` characters.
"""

from __future__ import annotations

import csv as _csv
import gzip
import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dampest_ros.core.signals.measurements import FloatArray


class CsvError(ValueError):
    """A CSV log cannot be read as asked; the message names the file and where."""


#: Largest CSV file read (MB, 10⁶ bytes) unless ``DAMPEST_MAX_CSV_MB`` says otherwise.
MAX_MB = 1000.0
#: Longest header line read (characters).
MAX_HEADER = 1 << 16


def max_bytes() -> int:
    """The largest CSV file read, in bytes: ``DAMPEST_MAX_CSV_MB`` (MB) or :data:`MAX_MB`."""
    given = os.environ.get("DAMPEST_MAX_CSV_MB", "")
    try:
        mb = float(given) if given.strip() else MAX_MB
    except ValueError:
        raise CsvError(f"DAMPEST_MAX_CSV_MB must be a number of MB, got {given!r}") from None
    return int(mb * 1e6)


def check_size(path: Path) -> None:
    """CsvError when the file at ``path`` is larger than :func:`max_bytes` (a missing file
    passes: its reader names it)."""
    try:
        size = path.stat().st_size
    except OSError:
        return
    limit = max_bytes()
    if size > limit:
        raise CsvError(f"{path}: {size / 1e6:.0f} MB, over the {limit / 1e6:.0f} MB limit for "
                       "a CSV log (reading takes several times its size in memory); split it "
                       "into shorter logs, or convert it to a bag, or raise the limit with "
                       "DAMPEST_MAX_CSV_MB=N if the memory is there")


#: Time units: name → seconds per unit, largest first.
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "µs": 1e-6, "ns": 1e-9}
#: A first stamp in this range (s) is a Unix date (1973 … 2286).
EPOCH_RANGE = (1e8, 1e10)
#: Largest median step (s) of a dated stream; of a stream timed from its start.
DATED_MAX_STEP, RELATIVE_MAX_STEP = 10.0, 1.0


def open_text(path: Path) -> Any:
    """``path`` opened for reading text, through gzip when its name ends in ``.gz``."""
    if path.name.lower().endswith(".gz"):
        return gzip.open(path, "rt", newline="")
    return path.open(newline="")


def read_head(path: Path) -> tuple[list[str], list[str] | None]:
    """The header (names stripped) and the first data row of a CSV file (None when it has
    no data row).

    Raises
    ------
    CsvError
        An unreadable, empty or too large file (:func:`check_size`), or a first line over
        :data:`MAX_HEADER` characters.
    """
    check_size(path)
    try:
        with open_text(path) as f:
            lines = [f.readline(MAX_HEADER + 1), f.readline(MAX_HEADER + 1)]
    except (OSError, EOFError, UnicodeDecodeError) as exc:  # e.g. a corrupt .gz
        raise CsvError(f"{path}: cannot read: {exc}") from None
    if len(lines[0]) > MAX_HEADER:
        raise CsvError(f"{path}: the first line is over {MAX_HEADER} characters: not a CSV "
                       "header (a binary file, or one without line ends?)")
    try:
        rows = list(_csv.reader(line for line in lines if line))
    except _csv.Error as exc:
        raise CsvError(f"{path}: cannot read: {exc}") from None
    header = rows[0] if rows else None
    first = rows[1] if len(rows) > 1 else None
    if not header:
        raise CsvError(f"{path}: empty file, expected a header line")
    return [h.strip() for h in header], first


def numeric_columns(path: Path, header: Sequence[str], names: Sequence[str]
                    ) -> dict[str, FloatArray]:
    """The columns ``names`` of a CSV file as float64; other columns are not parsed, so text
    or empty cells there do no harm. An empty cell in a used column is nan.

    Parameters
    ----------
    path : Path
    header : sequence of str
        The file's column names, in order (:func:`read_head`).
    names : sequence of str
        Columns to read.

    Returns
    -------
    dict of str to ndarray, each shape (N,)

    Raises
    ------
    CsvError
        Naming the file, the line and the column of the first cell that is not a number.
    """
    index = [list(header).index(n) for n in names]
    if not index:
        return {}
    check_size(path)
    try:
        with warnings.catch_warnings():  # a header-only file is a valid empty table
            warnings.filterwarnings("ignore", "loadtxt: input contained no data")
            cells = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2, dtype=str,
                               usecols=index, quotechar='"')
    except (ValueError, OSError, EOFError) as exc:
        raise CsvError(f"{path}: {exc}") from None
    cells = np.char.strip(cells)
    cells = np.where(cells == "", "nan", cells)
    out: dict[str, FloatArray] = {}
    for j, name in enumerate(names):
        out[name] = _floats(cells[:, j], path, name)
    return out


def _floats(cells: Any, path: Path, name: str) -> FloatArray:
    """One column of text cells as float64, or CsvError at its first bad cell (found by
    bisection over vectorised conversions)."""
    try:
        return np.asarray(cells.astype(float), dtype=float)
    except ValueError:
        pass
    lo, hi = 0, len(cells)  # cells[:lo] convert, cells[:hi] do not
    while hi - lo > 1:
        mid = (lo + hi) // 2
        try:
            cells[lo:mid].astype(float)
            lo = mid
        except ValueError:
            hi = mid
    raise CsvError(f"{path}: line {hi + 1}, column {name!r}: {str(cells[hi - 1])!r} is not a "
                   "number; fix or delete that line")


def time_unit(t: FloatArray) -> str:
    """The unit of a time column (a key of :data:`TIME_UNITS`), by the module's rule.

    Parameters
    ----------
    t : ndarray, shape (N,), N ≥ 2
        Stamps in the file's unit, increasing.

    Returns
    -------
    str
    """
    step = float(np.median(np.diff(t)))
    for unit, factor in TIME_UNITS.items():
        if (EPOCH_RANGE[0] <= abs(float(t[0])) * factor <= EPOCH_RANGE[1]
                and step * factor <= DATED_MAX_STEP):
            return unit
    return next((u for u, f in TIME_UNITS.items() if step * f <= RELATIVE_MAX_STEP), "ns")


def seconds(t: FloatArray, where: str, column: str, unit: str | None = None
            ) -> tuple[FloatArray, str]:
    """A time column in seconds, after checking that it increases.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Stamps in the file's unit.
    where : str
        The file, for messages.
    column : str
        The column's name, for messages.
    unit : str, optional
        Known unit (a key of :data:`TIME_UNITS`); default :func:`time_unit`.

    Returns
    -------
    t : ndarray, shape (N,)
        Seconds.
    unit : str

    Raises
    ------
    CsvError
        Fewer than two rows, a non-finite stamp, or a stamp not after the one before,
        naming the line of the file.
    """
    if len(t) < 2:
        raise CsvError(f"{where}: {len(t)} data line(s); a log needs at least two (is the "
                       "file only a header?)")
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise CsvError(f"{where}: line {bad[0] + 2}, column {column!r}: no time; every row "
                       "needs one")
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise CsvError(f"{where}: line {i + 2}, column {column!r}: time {t[i]:.17g} does not "
                       f"increase (line {i + 1} has {t[i - 1]:.17g}); sort the rows by time "
                       "or delete the repeated one")
    unit = unit or time_unit(t)
    return t * TIME_UNITS[unit], unit
