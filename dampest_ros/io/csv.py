"""The seed paper's CSV format of identification data.

One row per sample and a header line naming the columns, in this order::

    time,u,v,w,p,q,r,ax,ay,az,wx,wy,wz,depth,tau_X,tau_Y,tau_Z,tau_K,tau_M,tau_N[,extra...]

==================  ======================================================  ==========
column              meaning                                                 unit
==================  ======================================================  ==========
time                sample time                                             s
u, v, w             body linear velocity relative to the water              m/s
p, q, r             body angular velocity                                   rad/s
ax, ay, az          body linear acceleration u̇, v̇, ẇ (not specific force)  m/s²
wx, wy, wz          body angular acceleration ṗ, q̇, ṙ                       rad/s²
depth               depth below the surface (NED z, positive down)          m
tau_X … tau_N       generalized force on the vehicle (thrusters)            N, N·m
rpm_<name>          optional: rotor speed of a thruster                     rev/min
thrust_<name>       optional: thrust of a thruster                          N
roll, pitch, yaw    optional: ZYX Euler angles of FRD in NED                rad
segment             optional: index of the gap-free stretch                 —
==================  ======================================================  ==========

**Frames.** Every body vector in the CSV (velocities, accelerations, forces) is in Fossen's
FRD body frame (x forward, y starboard, z down), the frame of the core and of
:class:`dampest_ros.core.samples.Samples`, which :func:`samples_to_columns` and
:func:`samples_from_columns` convert to and from.

Numbers are written with ``%.17g``, so a write/read round trip is exact. Files with other
column names are read through a column map (``their name: our name``, see
:func:`load_column_map`).
"""

from __future__ import annotations

import csv as _csv
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from dampest_ros.core.measurements import FloatArray
from dampest_ros.core.samples import Samples

#: Body velocity ν = [u v w p q r] (FRD).
VELOCITY_COLUMNS = ("u", "v", "w", "p", "q", "r")
#: Body acceleration ν̇ (FRD).
ACCELERATION_COLUMNS = ("ax", "ay", "az", "wx", "wy", "wz")
#: Generalized force τ (FRD).
FORCE_COLUMNS = ("tau_X", "tau_Y", "tau_Z", "tau_K", "tau_M", "tau_N")
#: Columns every file must have, in the order they are written.
REQUIRED_COLUMNS = ("time", *VELOCITY_COLUMNS, *ACCELERATION_COLUMNS, "depth", *FORCE_COLUMNS)


def write_csv(path: str | Path, columns: Mapping[str, Any]) -> Path:
    """Write columns as a CSV file: the required columns first, then the others as given.

    Parameters
    ----------
    path : str or Path
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
             required: Sequence[str] = REQUIRED_COLUMNS) -> dict[str, FloatArray]:
    """Read a CSV file into columns.

    Parameters
    ----------
    path : str or Path
    column_map : mapping of str to str, optional
        The file's column name → our name (e.g. from :func:`load_column_map`); names not in
        the map are kept.
    required : sequence of str
        Our names that must be present (default :data:`REQUIRED_COLUMNS`).

    Returns
    -------
    dict of str to ndarray, each shape (N,)
        In file order, under our names.

    Raises
    ------
    ValueError
        Naming the file and the missing required columns, or the first unreadable line.
    """
    path = Path(path)
    with path.open(newline="") as f:
        header = next(_csv.reader(f), None)
    if not header:
        raise ValueError(f"{path}: empty file, expected a header line")
    names = [(column_map or {}).get(h.strip(), h.strip()) for h in header]
    dups = sorted({n for n in names if names.count(n) > 1})
    if dups:
        raise ValueError(f"{path}: columns {dups} appear more than once")
    _check_required(names, required, str(path), mapped=column_map is not None)
    try:
        with warnings.catch_warnings():  # a header-only file is a valid empty table
            warnings.filterwarnings("ignore", "loadtxt: input contained no data")
            data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2, dtype=float)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    if data.size == 0:
        data = np.zeros((0, len(names)))
    if data.shape[1] != len(names):
        raise ValueError(f"{path}: {data.shape[1]} values per row, {len(names)} columns")
    return {n: data[:, i].copy() for i, n in enumerate(names)}


def _check_required(names: Sequence[str], required: Sequence[str], where: str,
                    mapped: bool = False) -> None:
    missing = [c for c in required if c not in names]
    if missing:
        hint = "" if mapped else " (a column map renames other names to these)"
        raise ValueError(f"{where}: missing required columns {missing}{hint}; "
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
    """
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ValueError(f"{path}: not valid YAML: {exc}") from None
    if isinstance(doc, dict) and set(doc) == {"columns"}:
        doc = doc["columns"]
    if not isinstance(doc, dict) or not all(
            isinstance(k, str) and isinstance(v, str) for k, v in doc.items()):
        raise ValueError(f"{path}: a column map is a mapping of column name to column name")
    targets = list(doc.values())
    dups = sorted({t for t in targets if targets.count(t) > 1})
    if dups:
        raise ValueError(f"{path}: several columns map to {dups}")
    return dict(doc)


# --- identification samples ---------------------------------------------------------------

#: Optional columns that :func:`samples_to_columns` writes and :func:`samples_from_columns`
#: reads: attitude (ZYX Euler angles of FRD in NED, rad) and the gap-free segment index.
ATTITUDE_COLUMNS = ("roll", "pitch", "yaw")


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
    if "segment" in columns:
        segment = np.asarray(columns["segment"]).astype(np.int64)
    else:
        segment = np.r_[0, np.cumsum(np.diff(t) > max_gap)].astype(np.int64)
    return Samples(t, _stack(columns, VELOCITY_COLUMNS), _stack(columns, ACCELERATION_COLUMNS),
                   _stack(columns, FORCE_COLUMNS), euler,
                   np.asarray(columns["depth"], dtype=float), segment)
