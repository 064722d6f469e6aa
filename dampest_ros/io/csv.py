"""The seed paper's CSV format of identification data, and the flavours logs come in.

One row per sample and a header line naming the columns, in this order::

    time,u,v,w,p,q,r,ax,ay,az,wx,wy,wz,depth,tau_X,tau_Y,tau_Z,tau_K,tau_M,tau_N[,extra...]

==================  ======================================================  ==========
column              meaning                                                 unit
==================  ======================================================  ==========
time                sample time                                             s
u, v, w             body linear velocity over ground (DVL bottom lock)      m/s
p, q, r             body angular velocity                                   rad/s
ax, ay, az          body linear acceleration u̇, v̇, ẇ (not specific force)  m/s²
wx, wy, wz          body angular acceleration ṗ, q̇, ṙ                       rad/s²
depth               depth below the surface (NED z, positive down)          m
tau_X … tau_N       generalized force on the vehicle (thrusters)            N, N·m
rpm_<name>          optional: rotor speed of a thruster                     rev/min
thrust_<name>       optional: thrust of a thruster                          N
roll, pitch, yaw    optional: ZYX Euler angles of FRD in NED                rad
qx, qy, qz, qw      optional, instead: unit quaternion of FRD in NED        —
segment             optional: index of the gap-free stretch                 —
==================  ======================================================  ==========

**Velocity.** u, v, w are over ground, as a DVL in bottom lock measures them and as the bag
path fuses them. Identification and validation assume still water (no current), i.e. they
use them as the velocity through the water too; ``dampest gap``'s ``current`` candidate
instead estimates a constant NED current and applies the damping to ν − ν_c. A log of
velocity through the water (a water-tracking DVL) is read the same way; gap then finds no
current.

**Flavours** (:func:`read_log`). Logs as users have them differ from the table above in
three ways, each detected and read, or refused with one message naming the ambiguity and the
column-map entry that settles it:

- ``ax, ay, az`` as an IMU's specific force f (FRD, m/s²; mean |a| ≈ g) instead of ν̇:
  ν̇_lin = f + g Rᵀe_z − ω × v (IMU at the body origin). The sign follows the data: a log
  with az ≈ −g when level at rest is f itself, one with az ≈ +g is −f. A column map entry
  ``ax: acc_x`` (``ay: acc_y``, ``az: acc_z``) declares specific force, ``ax: ax`` declares
  ν̇;
- ``wx, wy, wz`` as gyro rates equal to p, q, r instead of ṗ, q̇, ṙ: the angular
  acceleration is then the time derivative of p, q, r (central differences per segment).
  ``wx: gyro_x`` … or ``wx: wx`` … declare it;
- no ``tau_*`` columns but ``thrust_<name>`` (N) or ``rpm_<name>`` (rev/min, through the
  vehicle's thrust curve) per thruster: τ = T_alloc f with the vehicle's allocation matrix
  (:class:`dampest_ros.core.physics.thrusters.Thrusters`).

**Frames.** Every body vector in the CSV (velocities, accelerations, forces) is in Fossen's
FRD body frame (x forward, y starboard, z down), the frame of the core and of
:class:`dampest_ros.core.signals.samples.Samples`, which :func:`samples_to_columns` and
:func:`samples_from_columns` convert to and from.

**Bad cells.** Columns the log does not use are not parsed (text there does no harm); a cell
of a used column that is not a number is an error naming the file, line and column. A row
with a non-finite value (``nan``, ``inf``, an empty cell read as nan) in a column the log
uses other than time is dropped by :func:`read_log`, which counts the rows per column in its
notes; the log is split into segments where rows were dropped (filters and derivatives never
run across the hole), and a stretch of one row left between drops goes too.

**Time** (:func:`read_log`). The ``time`` column may count s, ms, µs or ns: the unit is
detected from the stamps' magnitude and steps (the rule of :mod:`dampest_ros.io.csv_table`),
named in the notes unless it is seconds, and converted to seconds. Time must increase from
row to row (the error names the line). Rows need not be evenly spaced: a step over 1.75
median steps is a gap that splits the log, and when the steps inside the gap-free stretches
are uneven (beyond 1 % of the median) every stretch is resampled by linear interpolation
onto one uniform clock whose period is the mean step inside the stretches
(:mod:`dampest_ros.core.signals.resample`); a rate is never read from one step.

Numbers are written with ``%.17g``, so a write/read round trip is exact. A file whose name
ends in ``.csv.gz`` is gzip-compressed and otherwise the same. Files with other column names
are read through a column map (``their name: our name``, see :func:`load_column_map`).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.frames import euler_from_matrix, matrix_from_euler, quat_to_matrix
from dampest_ros.core.physics.thrusters import Thrusters
from dampest_ros.core.signals.measurements import FloatArray
from dampest_ros.core.signals.resample import GAP_PERIODS, resample_uniform
from dampest_ros.core.signals.samples import Samples
from dampest_ros.io.csv_table import CsvError, numeric_columns, read_head, seconds
from dampest_ros.io.schema import load_checked

#: Body velocity ν = [u v w p q r] (FRD).
VELOCITY_COLUMNS = ("u", "v", "w", "p", "q", "r")
#: Body acceleration ν̇ (FRD).
ACCELERATION_COLUMNS = ("ax", "ay", "az", "wx", "wy", "wz")
#: Generalized force τ (FRD).
FORCE_COLUMNS = ("tau_X", "tau_Y", "tau_Z", "tau_K", "tau_M", "tau_N")
#: Columns every file must have, in the order they are written.
REQUIRED_COLUMNS = ("time", *VELOCITY_COLUMNS, *ACCELERATION_COLUMNS, "depth", *FORCE_COLUMNS)
#: Columns every log must have whatever its flavour (:func:`read_log`).
BASE_COLUMNS = ("time", *VELOCITY_COLUMNS, "depth")
#: Our names of an IMU's specific force (FRD, m/s²), for a column map.
SPECIFIC_FORCE_COLUMNS = ("acc_x", "acc_y", "acc_z")
#: How the notes name a time unit.
UNIT_WORDS = {"s": "seconds", "ms": "milliseconds", "µs": "microseconds", "ns": "nanoseconds"}
#: Our names of gyro rates (FRD, rad/s), for a column map.
GYRO_COLUMNS = ("gyro_x", "gyro_y", "gyro_z")


def is_csv(path: str | Path) -> bool:
    """Whether ``path`` names a CSV log (``.csv`` or gzip-compressed ``.csv.gz``)."""
    name = Path(path).name.lower()
    return name.endswith((".csv", ".csv.gz"))


def write_csv(path: str | Path, columns: Mapping[str, Any]) -> Path:
    """Write columns as a CSV file: the required columns first, then the others as given.

    Parameters
    ----------
    path : str or Path
        A name ending in ``.gz`` writes a gzip-compressed file.
    columns : mapping of str to array_like, each shape (N,)
        Must hold every name of :data:`REQUIRED_COLUMNS`; units and frames as in the module
        docstring.

    Returns
    -------
    Path
    """
    path = Path(path)
    _check_required(list(columns), REQUIRED_COLUMNS, str(path))
    names = [*REQUIRED_COLUMNS, *(c for c in columns if c not in REQUIRED_COLUMNS)]
    return write_table(path, {n: columns[n] for n in names})


def write_table(path: str | Path, columns: Mapping[str, Any]) -> Path:
    """Write columns as a CSV file in the order given (``%.17g``, header line; gzip when
    the name ends in ``.gz``).

    Parameters
    ----------
    path : str or Path
    columns : mapping of str to array_like, each shape (N,)

    Returns
    -------
    Path
    """
    path = Path(path)
    names = list(columns)
    bad = [n for n in names if not n or any(ch in n for ch in ',"\n\r') or n != n.strip()]
    if bad:
        raise ValueError(f"column names must be plain words, got {bad}")
    arrays = [np.asarray(columns[n], dtype=float) for n in names]
    lengths = {n: a.shape for n, a in zip(names, arrays, strict=True)}
    if any(len(s) != 1 for s in lengths.values()) or len({s[0] for s in lengths.values()}) > 1:
        raise ValueError(f"columns must be 1-D arrays of one length, got shapes {lengths}")
    np.savetxt(path, np.column_stack(arrays), fmt="%.17g", delimiter=",",
               header=",".join(names), comments="")
    return path


def read_csv(path: str | Path, column_map: Mapping[str, str] | None = None,
             required: Sequence[str] = REQUIRED_COLUMNS,
             keep: Callable[[str], bool] | None = None) -> dict[str, FloatArray]:
    """Read a CSV file into columns.

    Parameters
    ----------
    path : str or Path
        A name ending in ``.gz`` is read through gzip.
    column_map : mapping of str to str, optional
        The file's column name → our name (e.g. from :func:`load_column_map`); names not in
        the map are kept.
    required : sequence of str
        Our names that must be present (default :data:`REQUIRED_COLUMNS`).
    keep : callable, optional
        Whether a column (our name) is read; the others are not parsed (text there does no
        harm). Default: every column.

    Returns
    -------
    dict of str to ndarray, each shape (N,)
        In file order, under our names; time as in the file (see :func:`read_log` for the
        unit).

    Raises
    ------
    CsvError
        Naming the file and the missing required columns, or the line and column of the
        first cell that is not a number.
    """
    path = Path(path)
    header, _ = read_head(path)
    names = [(column_map or {}).get(h, h) for h in header]
    dups = sorted({n for n in names if names.count(n) > 1})
    if dups:
        raise CsvError(f"{path}: columns {dups} appear more than once")
    _check_required(names, required, str(path), mapped=column_map is not None)
    wanted = [(h, n) for h, n in zip(header, names, strict=True) if keep is None or keep(n)]
    data = numeric_columns(path, header, [h for h, _ in wanted])
    return {n: data[h] for h, n in wanted}


def _check_required(names: Sequence[str], required: Sequence[str], where: str,
                    mapped: bool = False) -> None:
    missing = [c for c in required if c not in names]
    if missing:
        hint = "" if mapped else " (a column map renames other names to these)"
        raise CsvError(f"{where}: missing required columns {missing}{hint}; "
                         f"columns present: {list(names)}")


def load_column_map(path: str | Path) -> dict[str, str]:
    """Load a column map: YAML mapping of the file's column names to ours.

    Either at the top level or under a ``columns`` key, e.g.::

        columns:
          t: time
          vel_x: u
          Fx: tau_X

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict of str to str

    Raises
    ------
    InputError
        (a ValueError) naming the file, line and entry: not a mapping, a duplicate key, a
        target that is not one of our column names (the closest one suggested; the schema
        ``dampest_ros/schemas/column_map.schema.json``).
        Several columns mapped to one name too.
    """
    checked = load_checked(path, "column_map")
    nested = set(checked.data) == {"columns"}
    doc = {str(k): v for k, v in (checked.data["columns"] if nested else checked.data).items()}
    targets = list(doc.values())
    dups = sorted({t for t in targets if targets.count(t) > 1})
    if dups:
        last = [k for k, v in doc.items() if v in dups][-1]
        raise checked.error(["columns", last] if nested else [last],
                            f"several columns map to {dups}; keep one")
    return doc


# --- identification samples ---------------------------------------------------------------

#: Optional columns that :func:`samples_to_columns` writes and :func:`samples_from_columns`
#: reads: attitude (ZYX Euler angles of FRD in NED, rad) and the gap-free segment index.
ATTITUDE_COLUMNS = ("roll", "pitch", "yaw")
#: The attitude as a unit quaternion of FRD in NED (x, y, z, w), read when roll, pitch, yaw
#: are absent.
QUATERNION_COLUMNS = ("qx", "qy", "qz", "qw")
#: Largest | |q| − 1 | of a quaternion row read as an attitude.
QUATERNION_TOLERANCE = 0.01


def _stack(columns: Mapping[str, FloatArray], names: Sequence[str]) -> FloatArray:
    return np.stack([np.asarray(columns[n], dtype=float) for n in names], axis=-1)


def samples_to_columns(samples: Samples) -> dict[str, FloatArray]:
    """CSV columns (FRD, the module's table) of identification samples.

    Parameters
    ----------
    samples : Samples

    Returns
    -------
    dict of str to ndarray, each shape (N,)
        :data:`REQUIRED_COLUMNS`, then ``roll``, ``pitch``, ``yaw`` and ``segment``.
    """
    out: dict[str, FloatArray] = {"time": samples.t}
    for names, arr in ((VELOCITY_COLUMNS, samples.nu), (ACCELERATION_COLUMNS, samples.nu_dot),
                       (FORCE_COLUMNS, samples.tau), (ATTITUDE_COLUMNS, samples.euler)):
        out.update({n: arr[:, i] for i, n in enumerate(names)})
    out["depth"] = samples.depth
    out["segment"] = samples.segment.astype(float)
    return {n: out[n] for n in (*REQUIRED_COLUMNS, *ATTITUDE_COLUMNS, "segment")}


def samples_from_columns(columns: Mapping[str, FloatArray], max_gap: float = 1.0) -> Samples:
    """Identification samples from CSV columns.

    Attitude defaults to level (with a warning: restoring forces then assume it); without a
    ``segment`` column, time gaps longer than ``max_gap`` seconds start a new segment.

    Parameters
    ----------
    columns : mapping of str to ndarray, each shape (N,)
    max_gap : float

    Returns
    -------
    Samples
    """
    t = np.asarray(columns["time"], dtype=float)
    if len(t) > 1 and np.any(np.diff(t) <= 0):
        raise ValueError("time must increase strictly from row to row")
    if all(n in columns for n in ATTITUDE_COLUMNS):
        euler = _stack(columns, ATTITUDE_COLUMNS)
    else:
        warnings.warn("no roll, pitch, yaw columns: assuming level attitude for g(η)",
                      stacklevel=2)
        euler = np.zeros((len(t), 3))
    segment = _segment_index(columns, max_gap)
    return Samples(t, _stack(columns, VELOCITY_COLUMNS), _stack(columns, ACCELERATION_COLUMNS),
                   _stack(columns, FORCE_COLUMNS), euler,
                   np.asarray(columns["depth"], dtype=float), segment)


def _segment_index(columns: Mapping[str, FloatArray], max_gap: float) -> NDArray[np.int64]:
    """The ``segment`` column, or a new segment wherever time jumps by more than max_gap."""
    if "segment" in columns:
        return np.asarray(columns["segment"]).astype(np.int64)
    t = np.asarray(columns["time"], dtype=float)
    return np.r_[0, np.cumsum(np.diff(t) > max_gap)].astype(np.int64)


# --- flavours of logs ---------------------------------------------------------------------

#: mean |a| within this share of g: ax, ay, az are a specific force; below NU_DOT_SHARE · g:
#: body acceleration; in between: ambiguous.
SPECIFIC_FORCE_TOLERANCE = 0.2
NU_DOT_SHARE = 0.3
#: RMS(w − ω) / RMS(ω) at most GYRO_MATCH: wx, wy, wz are gyro rates; at least
#: ANGULAR_ACCELERATION_MISMATCH: angular acceleration; in between: ambiguous.
GYRO_MATCH = 0.2
ANGULAR_ACCELERATION_MISMATCH = 0.7


def read_log(path: str | Path, thrusters: Thrusters | None, gravity: float,
             column_map: Mapping[str, str] | None = None, max_gap: float = 1.0
             ) -> tuple[Samples, list[str]]:
    """Identification samples from a CSV log of any flavour of the module docstring.

    Parameters
    ----------
    path : str or Path
        ``.csv`` or ``.csv.gz``.
    thrusters : Thrusters or None
        The vehicle's thrusters: names, allocation and thrust curve, for ``thrust_<name>``
        and ``rpm_<name>`` columns (None: the log must have tau_X…tau_N).
    gravity : float
        g (m/s²), for specific force.
    column_map : mapping of str to str, optional
        The file's column name → our name; an entry naming ``ax`` / ``acc_x`` or ``wx`` /
        ``gyro_x`` declares what those columns are (no detection).
    max_gap : float
        Without a ``segment`` column, time gaps longer than this (s) start a new segment.

    Returns
    -------
    samples : Samples
    notes : list of str
        One line per flavour detected and how it was read (empty for the plain format).

    Raises
    ------
    ValueError
        A missing column or an ambiguous flavour, naming the column-map entry that settles it.
    """
    where = str(path)
    columns = read_csv(path, column_map, required=BASE_COLUMNS, keep=used_column)
    time_name = next((k for k, v in (column_map or {}).items() if v == "time"), "time")
    columns["time"], unit = seconds(columns["time"], where, time_name)
    columns, dropped = drop_nonfinite(columns, max_gap)
    columns, clock = uniform_clock(columns, max_gap)
    declared = set(column_map.values()) if column_map else set()
    standard, notes = interpret_columns(columns, thrusters, gravity, declared, where, max_gap)
    unit_note = [] if unit == "s" else [f"time column {time_name!r} read in "
                                        f"{UNIT_WORDS[unit]} (detected), converted to seconds"]
    return samples_from_columns(standard, max_gap), [*unit_note, *dropped, *clock, *notes]


def uniform_clock(columns: Mapping[str, FloatArray], max_gap: float = 1.0
                  ) -> tuple[dict[str, FloatArray], list[str]]:
    """The rows on one uniform clock, split into segments at gaps
    (:func:`dampest_ros.core.signals.resample.resample_uniform`: a step over 1.75 median
    steps, a ``segment`` change, or a step over ``max_gap`` without a ``segment`` column).

    Parameters
    ----------
    columns : mapping of str to ndarray, each shape (N,)
        Time in seconds, increasing.
    max_gap : float
        Without a ``segment`` column, steps longer than this (s) split the log too.

    Returns
    -------
    columns : dict of str to ndarray, each shape (M,)
        Resampled by linear interpolation when the steps are uneven; with a ``segment``
        column.
    notes : list of str
        One line when the rows were resampled or split.
    """
    t = np.asarray(columns["time"], dtype=float)
    names = [k for k in columns if k not in ("time", "segment")]
    breaks = np.diff(_segment_index(columns, max_gap)) != 0
    x = np.stack([np.asarray(columns[k], dtype=float) for k in names], axis=1) \
        if names else np.zeros((len(t), 0))
    u = resample_uniform(t, x, breaks)
    out = {"time": u.t, **{k: u.x[:, j] for j, k in enumerate(names)},
           "segment": u.segment.astype(float)}
    notes = []
    if u.resampled:
        dt = np.diff(t)
        notes.append(f"time steps uneven ({float(dt.min()):.4g} to {float(dt.max()):.4g} s): "
                     f"resampled by linear interpolation onto a uniform {1 / u.period:.5g} Hz "
                     f"clock (the mean step within the gap-free stretches), {len(t)} rows → "
                     f"{len(u.t)} samples")
    if u.gaps:
        notes.append(f"{u.gaps} gap(s) (steps over {GAP_PERIODS:g} median steps): the log is split "
                     f"there ({int(u.segment.max()) + 1} segments)")
    return out, notes


def used_column(name: str) -> bool:
    """Whether :func:`read_log` reads a column (our name)."""
    return name in (*BASE_COLUMNS, *ACCELERATION_COLUMNS, *FORCE_COLUMNS,
                    *SPECIFIC_FORCE_COLUMNS, *GYRO_COLUMNS, *ATTITUDE_COLUMNS,
                    *QUATERNION_COLUMNS, "segment") \
        or name.startswith(("thrust_", "rpm_"))


def drop_nonfinite(columns: Mapping[str, FloatArray], max_gap: float = 1.0
                   ) -> tuple[dict[str, FloatArray], list[str]]:
    """The rows whose used columns are all finite, the log split where rows went.

    Parameters
    ----------
    columns : mapping of str to ndarray, each shape (N,)
        Under our names; columns :func:`read_log` does not read are not looked at.
    max_gap : float
        Without a ``segment`` column, time gaps longer than this (s) start a new segment.

    Returns
    -------
    columns : dict of str to ndarray
        Without the dropped rows; with a ``segment`` column that starts a new segment after
        every dropped stretch (and drops a one-row segment left between two of them).
    notes : list of str
        One line counting the dropped rows per column (empty when none was dropped).

    Raises
    ------
    ValueError
        When fewer than two rows are left.
    """
    out = {k: np.asarray(v, dtype=float) for k, v in columns.items()}
    n = len(out["time"])
    bad = {k: ~np.isfinite(v) for k, v in out.items() if used_column(k)}
    keep = ~np.logical_or.reduce(list(bad.values())) if bad else np.ones(n, dtype=bool)
    if keep.all():
        return out, []
    # a new segment after each dropped stretch, on top of the log's own segments
    segment = _segment_index(out, max_gap) + np.cumsum(~keep)
    _, segment = np.unique(segment[keep], return_inverse=True)
    sizes = np.bincount(segment)
    alone = sizes[segment] < 2  # a single row between drops: no filter or derivative
    kept = np.flatnonzero(keep)[~alone]
    if kept.size < 2:
        raise ValueError(f"{n - kept.size} of {n} rows have a non-finite value in a column "
                         f"the log uses: fewer than 2 rows are left")
    result = {k: v[kept] for k, v in out.items()}
    result["segment"] = np.unique(segment[~alone], return_inverse=True)[1].astype(float)
    cells = ", ".join(f"{k} {int(b.sum())}" for k, b in bad.items() if b.any())
    note = (f"{n - kept.size} of {n} rows dropped: non-finite values ({cells})"
            + (f", and {int(alone.sum())} row(s) left alone between them" if alone.any()
               else "") + f"; the log is split there ({int(result['segment'].max()) + 1} "
            "segments)")
    return result, [note]


def interpret_columns(columns: Mapping[str, FloatArray], thrusters: Thrusters | None,
                      gravity: float,
                      declared: set[str] | frozenset[str] = frozenset(), where: str = "log",
                      max_gap: float = 1.0) -> tuple[dict[str, FloatArray], list[str]]:
    """Columns of a log of any flavour as the plain format: ν̇ in ax…wz, τ in tau_X…tau_N.

    Parameters
    ----------
    columns : mapping of str to ndarray, each shape (N,)
        Under our names (after the column map); at least :data:`BASE_COLUMNS`.
    thrusters : Thrusters or None
        None when the vehicle has none (then tau_X…tau_N are needed).
    gravity : float
        g (m/s²).
    declared : set of str
        Our names the column map assigned explicitly: ``ax``/``acc_x``, ``wx``/``gyro_x``
        there switch detection off.
    where : str
        Name of the log, for messages.
    max_gap : float
        Gap (s) that splits segments (for the derivative of gyro rates).

    Returns
    -------
    columns : dict of str to ndarray, each shape (N,)
        The input with ax…wz and tau_X…tau_N as the plain format defines them.
    notes : list of str
        How each non-plain flavour was read.
    """
    out = {k: np.asarray(v, dtype=float) for k, v in columns.items()}
    notes: list[str] = []
    _attitude_from_quaternion(out, where, notes)
    nu = _stack(out, VELOCITY_COLUMNS)
    lin = _linear_acceleration(out, nu, gravity, declared, where, notes)
    ang = _angular_acceleration(out, nu, declared, where, max_gap, notes)
    tau = _generalized_force(out, thrusters, where, notes)
    for names, arr in ((ACCELERATION_COLUMNS[:3], lin), (ACCELERATION_COLUMNS[3:], ang),
                       (FORCE_COLUMNS, tau)):
        out.update({n: arr[:, i] for i, n in enumerate(names)})
    return out, notes


def _attitude_from_quaternion(columns: dict[str, FloatArray], where: str,
                              notes: list[str]) -> None:
    """Add roll, pitch, yaw (rad) from ``qx, qy, qz, qw`` when the log has the quaternion
    and not the angles (in place; a note says so).

    Raises
    ------
    ValueError
        A row whose quaternion is not of unit norm (within :data:`QUATERNION_TOLERANCE`):
        the columns are something else, or another convention.
    """
    if any(c in columns for c in ATTITUDE_COLUMNS) or \
            not all(c in columns for c in QUATERNION_COLUMNS):
        return
    xyzw = _stack(columns, QUATERNION_COLUMNS)
    norm = np.linalg.norm(xyzw, axis=1)
    bad = np.flatnonzero(~(np.abs(norm - 1.0) <= QUATERNION_TOLERANCE))
    if bad.size:
        raise ValueError(f"{where}: qx, qy, qz, qw of row {int(bad[0]) + 1} have norm "
                         f"{norm[bad[0]]:.6g}, not 1: give unit quaternions of FRD in NED "
                         "(x, y, z, w), or roll, pitch, yaw columns")
    R = quat_to_matrix(xyzw[:, [3, 0, 1, 2]] / norm[:, None])  # [x, y, z, w] → [w, x, y, z]
    columns.update(zip(ATTITUDE_COLUMNS, euler_from_matrix(R).T, strict=True))
    notes.append(f"{where}: attitude from the quaternion columns qx, qy, qz, qw (FRD in NED)")


def _down(columns: Mapping[str, FloatArray], n: int) -> FloatArray:
    """Rᵀ e_z, NED down in the body frame, from roll/pitch/yaw (level without), (n, 3)."""
    if all(c in columns for c in ATTITUDE_COLUMNS):
        return np.asarray(matrix_from_euler(_stack(columns, ATTITUDE_COLUMNS))[:, 2, :])
    return np.tile([0.0, 0.0, 1.0], (n, 1))


def _which_set(columns: Mapping[str, FloatArray], ours: Sequence[str], theirs: Sequence[str],
               meaning: tuple[str, str], where: str) -> bool:
    """Whether the log carries the sensor's set ``theirs`` rather than our set ``ours`` of
    three columns; ValueError when it has both or neither (``meaning`` describes each set)."""
    have_ours = all(c in columns for c in ours)
    have_theirs = all(c in columns for c in theirs)
    if have_ours and have_theirs:
        raise ValueError(f"{where}: both {', '.join(ours)} and {', '.join(theirs)}; map only "
                         "one set (--columns)")
    if not have_ours and not have_theirs:
        raise ValueError(f"{where}: missing {', '.join(ours)} ({meaning[0]}) or "
                         f"{', '.join(theirs)} ({meaning[1]}); columns present: "
                         f"{list(columns)}")
    return have_theirs


def _linear_acceleration(columns: Mapping[str, FloatArray], nu: FloatArray, gravity: float,
                         declared: set[str] | frozenset[str], where: str, notes: list[str]
                         ) -> FloatArray:
    """u̇, v̇, ẇ (n, 3) from ax…az or from a specific force."""
    have_f = _which_set(columns, ACCELERATION_COLUMNS[:3], SPECIFIC_FORCE_COLUMNS,
                        ("u̇, v̇, ẇ", "IMU specific force"), where)
    have_a = not have_f
    names = SPECIFIC_FORCE_COLUMNS if have_f else ACCELERATION_COLUMNS[:3]
    a = _stack(columns, names)
    if have_a and not declared & set(ACCELERATION_COLUMNS[:3]) and len(a):
        mean_norm = float(np.mean(np.linalg.norm(a, axis=1)))
        if abs(mean_norm - gravity) <= SPECIFIC_FORCE_TOLERANCE * gravity:
            have_f = True
            notes.append(f"ax, ay, az read as an IMU's specific force (mean |a| = "
                         f"{mean_norm:.3g} m/s² ≈ g); --columns 'ax: ax' (ay, az) says they "
                         "are u̇, v̇, ẇ")
        elif mean_norm > NU_DOT_SHARE * gravity:
            raise ValueError(
                f"{where}: columns ax, ay, az are ambiguous: mean |a| = {mean_norm:.3g} m/s² "
                f"is neither small (body acceleration u̇, v̇, ẇ) nor ≈ g = {gravity:g} (IMU "
                "specific force); say which in --columns: 'ax: ax' (and 'ay: ay', 'az: az') "
                "for u̇, v̇, ẇ, or 'ax: acc_x' (and 'ay: acc_y', 'az: acc_z') for specific "
                "force")
    if not have_f:
        return a
    down = _down(columns, len(a))
    # the data's sign: a true specific force points up at rest, f · down ≈ −g
    sign = -1.0 if len(a) and float(np.mean(np.einsum("ni,ni->n", a, down))) > 0 else 1.0
    if sign < 0:
        notes.append("the specific force has az ≈ +g when level at rest: read as −f (the "
                     "sign convention of this log)")
    # v̇ = f + g Rᵀe_z − ω × v
    return np.asarray(sign * a + gravity * down - np.cross(nu[:, 3:], nu[:, :3]))


def _angular_acceleration(columns: Mapping[str, FloatArray], nu: FloatArray,
                          declared: set[str] | frozenset[str], where: str, max_gap: float,
                          notes: list[str]) -> FloatArray:
    """ṗ, q̇, ṙ (n, 3) from wx…wz or, for gyro rates, from the derivative of p, q, r."""
    have_g = _which_set(columns, ACCELERATION_COLUMNS[3:], GYRO_COLUMNS,
                        ("ṗ, q̇, ṙ", "gyro rates"), where)
    have_w = not have_g
    omega = nu[:, 3:]
    if have_w and not declared & set(ACCELERATION_COLUMNS[3:]) and len(omega):
        w = _stack(columns, ACCELERATION_COLUMNS[3:])
        scale = float(np.sqrt(np.mean(omega**2)))
        mismatch = float(np.sqrt(np.mean((w - omega) ** 2))) / scale if scale > 0 else np.inf
        if mismatch <= GYRO_MATCH:
            have_g = True
            notes.append(f"wx, wy, wz read as gyro rates (equal to p, q, r within "
                         f"{mismatch:.1%}): ṗ, q̇, ṙ by differentiating p, q, r; --columns "
                         "'wx: wx' (wy, wz) says they are angular accelerations")
        elif mismatch < ANGULAR_ACCELERATION_MISMATCH:
            raise ValueError(
                f"{where}: columns wx, wy, wz are ambiguous: they differ from p, q, r by "
                f"{mismatch:.0%} RMS, neither equal (gyro rates) nor clearly not (angular "
                "acceleration); say which in --columns: 'wx: wx' (and 'wy: wy', 'wz: wz') "
                "for ṗ, q̇, ṙ, or 'wx: gyro_x' (and 'wy: gyro_y', 'wz: gyro_z') for gyro rates")
    if not have_g:
        return _stack(columns, ACCELERATION_COLUMNS[3:])
    t = np.asarray(columns["time"], dtype=float)
    out = np.zeros_like(omega)
    seg = _segment_index(columns, max_gap)
    edges = np.r_[0, np.flatnonzero(np.diff(seg)) + 1, len(t)]
    for a, b in pairwise(edges.tolist()):  # segments, not samples
        if b - a >= 2:
            out[a:b] = np.gradient(omega[a:b], t[a:b], axis=0)
    return out


def _generalized_force(columns: Mapping[str, FloatArray], thrusters: Thrusters | None,
                       where: str, notes: list[str]) -> FloatArray:
    """τ (n, 6) from tau_X…tau_N or, without them, from per-thruster thrust or rpm."""
    if all(c in columns for c in FORCE_COLUMNS):
        return _stack(columns, FORCE_COLUMNS)
    logged = sorted(c for c in columns if c.startswith(("thrust_", "rpm_")))
    if thrusters is None:
        present = [c for c in FORCE_COLUMNS if c in columns]
        raise ValueError(
            f"{where}: no generalized force: {'only ' + ', '.join(present) if present else 'no'}"
            f" tau_X…tau_N columns, and the vehicle has no thrusters to turn thruster columns "
            f"({logged or 'none'}) into τ; add the tau columns (or map them with --columns) "
            "or a thrusters: section to the vehicle file")
    missing = [n for n in thrusters.names
               if f"thrust_{n}" not in columns and f"rpm_{n}" not in columns]
    if missing:
        present = [c for c in FORCE_COLUMNS if c in columns]
        raise ValueError(
            f"{where}: no generalized force: {'only ' + ', '.join(present) if present else 'no'}"
            f" tau_X…tau_N columns, and no thrust_<name> or rpm_<name> column for thruster(s) "
            f"{missing} of the vehicle (thruster columns present: {logged or 'none'}); "
            "rename them with --columns, e.g. 'T1: thrust_" + missing[0] + "'")
    thrust = np.stack([columns[f"thrust_{n}"] if f"thrust_{n}" in columns
                       else thrusters.thrust(np.asarray(columns[f"rpm_{n}"]) / 60.0)
                       for n in thrusters.names], axis=-1)
    used = ["thrust" if f"thrust_{n}" in columns else "rpm" for n in thrusters.names]
    kinds = " and ".join(sorted(set(used)))
    notes.append(f"no tau columns: τ from the {kinds} of {thrusters.count} thrusters through "
                 "the vehicle's allocation matrix" + (" and thrust curve" if "rpm" in used
                                                      else ""))
    return np.asarray(thrusters.wrench(thrust), dtype=float)
