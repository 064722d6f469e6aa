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
==================  ======================================================  ==========

**Frames.** Every body vector in the CSV (velocities, accelerations, forces) is in Fossen's
FRD body frame (x forward, y starboard, z down), the frame of the core; the ROS topics use
FLU (REP-103). :func:`to_recording` and :func:`from_recording` convert between the two with
:func:`dampest_ros.core.frames.body_twist`.

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
import yaml  # type: ignore[import-untyped]  # no types-PyYAML in the lock

from dampest_ros.core import frames
from dampest_ros.core.measurements import (
    AccelSeries,
    FloatArray,
    Series,
    TwistSeries,
    WrenchSeries,
)

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


# --- conversion to and from the estimator topics -------------------------------------------


def _stack(columns: Mapping[str, FloatArray], names: Sequence[str]) -> FloatArray:
    return np.stack([np.asarray(columns[n], dtype=float) for n in names], axis=-1)


def to_recording(columns: Mapping[str, FloatArray], frame_id: str = "base_link"
                 ) -> dict[str, Series]:
    """The estimator input topics from CSV columns, converted from FRD to FLU.

    Parameters
    ----------
    columns : mapping of str to ndarray, each shape (N,)
        At least ``time``, the velocity, acceleration and force columns.
    frame_id : str
        Body frame of the ROS messages.

    Returns
    -------
    dict of str to Series
        ``dampest/velocity`` (TwistSeries), ``dampest/acceleration`` (AccelSeries) and
        ``dampest/wrench`` (WrenchSeries), stamps = ``time`` (s), body vectors FLU.
    """
    t = np.asarray(columns["time"], dtype=float)
    nu = frames.body_twist(_stack(columns, VELOCITY_COLUMNS))
    nu_dot = frames.body_twist(_stack(columns, ACCELERATION_COLUMNS))
    tau = frames.body_twist(_stack(columns, FORCE_COLUMNS))
    return {
        "dampest/velocity": TwistSeries(t.copy(), frame_id, nu[:, :3], nu[:, 3:]),
        "dampest/acceleration": AccelSeries(t.copy(), frame_id, nu_dot[:, :3], nu_dot[:, 3:]),
        "dampest/wrench": WrenchSeries(t.copy(), frame_id, tau[:, :3], tau[:, 3:]),
    }


def from_recording(recording: Mapping[str, Series], depth: FloatArray) -> dict[str, FloatArray]:
    """CSV columns from the estimator input topics, converted from FLU to FRD.

    Parameters
    ----------
    recording : mapping of str to Series
        ``dampest/velocity``, ``dampest/acceleration`` and ``dampest/wrench`` with identical
        stamps (as the preprocessing publishes them).
    depth : ndarray, shape (N,)
        Depth (m, positive down) at those stamps.

    Returns
    -------
    dict of str to ndarray, each shape (N,)
        The :data:`REQUIRED_COLUMNS`.
    """
    vel, acc, wre = (recording[k] for k in
                     ("dampest/velocity", "dampest/acceleration", "dampest/wrench"))
    if not isinstance(vel, TwistSeries) or not isinstance(acc, AccelSeries) \
            or not isinstance(wre, WrenchSeries):
        raise TypeError("need a TwistSeries, an AccelSeries and a WrenchSeries")
    if not (np.array_equal(vel.stamp, acc.stamp) and np.array_equal(vel.stamp, wre.stamp)):
        raise ValueError("dampest/velocity, dampest/acceleration and dampest/wrench must "
                         "have identical stamps")
    out: dict[str, FloatArray] = {"time": vel.stamp.copy()}
    for names, (a, b) in ((VELOCITY_COLUMNS, (vel.linear, vel.angular)),
                          (ACCELERATION_COLUMNS, (acc.linear, acc.angular)),
                          (FORCE_COLUMNS, (wre.force, wre.torque))):
        six = frames.body_twist(np.hstack([a, b]))
        out.update({n: six[:, i].copy() for i, n in enumerate(names)})
    out["depth"] = np.asarray(depth, dtype=float).copy()
    return {n: out[n] for n in REQUIRED_COLUMNS}
