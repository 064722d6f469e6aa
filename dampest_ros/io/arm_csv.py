"""An arm's joint log as one CSV file: what a logger writes when there is no bag.

One row per sample, a header line naming the columns (our names; a column map renames the
file's, ``their name: our name``, :func:`dampest_ros.io.csv.load_column_map`):

==============  ===========================================================  ======
column          meaning                                                      unit
==============  ===========================================================  ======
time            sample time (s, ms, µs or ns: detected, :mod:`.csv_table`)   s
<joint>.q       joint position, one column per joint of the arm              rad
<joint>.qd      optional, for all joints or none: joint velocity             rad/s
<joint>.tau     joint effort                                                 N m
==============  ===========================================================  ======

Joints are matched by name (any column order; other columns are not parsed).
Identification takes q̇ and q̈ from the filtered q whatever the source (a bag's velocity
is not used either), so a log without ``<joint>.qd`` identifies the same. The joint columns
are named as the parameters are (``elbow_joint.Fc``), so that no name of an arm's log is one
of a vehicle log's (``tau_X``) and one column map schema serves both. A missing column is one
line naming the file, the file's column that is closest (or the column map entry that
names a column the file lacks) and the valid name; a cell that is not a number, or empty,
names its line and column.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from dampest_ros.io.arm import JointData
from dampest_ros.io.csv_table import CsvError, numeric_columns, read_head, seconds

#: What each joint column holds, by prefix, for messages.
MEANING = {"q": "position in rad", "qd": "velocity in rad/s", "tau": "effort in N m"}


def joint_column_names(prefix: str, joints: Sequence[str]) -> list[str]:
    """Our names of one quantity's columns: ``<joint>.<prefix>`` per joint."""
    return [f"{j}.{prefix}" for j in joints]


def read_joint_csv(path: str | Path, joints: Sequence[str],
                   column_map: Mapping[str, str] | None = None) -> JointData:
    """Read an arm's joint log from a CSV file, in the model's joint order.

    Parameters
    ----------
    path : str or Path
        ``.csv`` or ``.csv.gz``.
    joints : sequence of str
        The model's joint names.
    column_map : mapping of str to str, optional
        The file's column name → ours.

    Returns
    -------
    JointData
        t (N,) s; position, velocity (NaN without ``.qd`` columns), effort (N, n);
        ``topic`` is the file.

    Raises
    ------
    CsvError
        One line naming the file: a missing column (with the closest name, see the module
        docstring), a column given twice, a bad cell (line and column), time that does not
        increase.
    """
    path = Path(path)
    cmap = dict(column_map or {})
    header, _ = read_head(path)
    ours = [cmap.get(h, h) for h in header]
    dups = sorted({n for n in ours if ours.count(n) > 1})
    if dups:
        raise CsvError(f"{path}: columns {dups} appear more than once; keep one of each")
    wanted = ["time", *joint_column_names("q", joints), *joint_column_names("tau", joints)]
    if any(n.endswith(".qd") for n in ours):
        wanted += joint_column_names("qd", joints)
    missing = [n for n in wanted if n not in ours]
    if missing:
        raise CsvError(_missing(path, missing[0], wanted, ours, header, cmap))
    theirs = {n: header[ours.index(n)] for n in wanted}
    data = numeric_columns(path, header, list(theirs.values()))
    t, _ = seconds(data[theirs["time"]], str(path), theirs["time"])

    def stack(prefix: str) -> np.ndarray:
        names = joint_column_names(prefix, joints)
        for n in names:
            bad = np.flatnonzero(~np.isfinite(data[theirs[n]]))
            if bad.size:
                raise CsvError(f"{path}: line {bad[0] + 2}, column {theirs[n]!r}: not a "
                               "number (empty, nan or inf); fix or delete that line")
        return np.column_stack([data[theirs[n]] for n in names])

    velocity = (stack("qd") if f"{joints[0]}.qd" in theirs
                else np.full((len(t), len(joints)), np.nan))
    return JointData(t, stack("q"), velocity, stack("tau"), str(path))


def _missing(path: Path, name: str, wanted: list[str], ours: list[str], header: list[str],
             cmap: dict[str, str]) -> str:
    """The message for our column ``name`` missing from the file: a column map entry naming
    a column the file lacks, else the file's closest column of those not ``wanted`` (``ours``:
    the file's columns under our names, ``header``: as the file names them), else what is
    there."""
    joint, _, prefix = name.rpartition(".")
    what = "the sample time" if name == "time" else f"joint {joint}'s {MEANING[prefix]}"
    fix = f"rename the column to {name!r} or map it in the column map (--columns)"
    lost = [k for k, v in cmap.items() if v == name and k not in header]
    if lost:
        close = difflib.get_close_matches(lost[0], header, n=1)
        return (f"{path}: the column map maps {lost[0]!r} to {name!r} ({what}), but the file "
                f"has no column {lost[0]!r}"
                + (f"; closest column: {close[0]!r}" if close else
                   f"; columns: {', '.join(header)}"))
    spare = [n for n in ours if n not in wanted]
    close = difflib.get_close_matches(name, spare, n=1, cutoff=0.6)
    if close:
        col = header[ours.index(close[0])]
        mapped = f" (mapped to {close[0]!r} by the column map)" if col != close[0] else ""
        return (f"{path}: column {col!r}{mapped} is no column of this arm; the closest valid "
                f"name is {name!r} ({what}): {fix}")
    return f"{path}: no column {name!r} ({what}); columns: {', '.join(header)}: {fix}"

