"""Directions in the body frame: the axes element forces act along (:mod:`.point_drag`,
:mod:`.point_lift`).

A direction is a body axis 0, 1, 2 (x, y, z: velocity letters u, v, w) or any other unit vector
e, the axis of an element the vehicle file rotates (MuJoCo's fluid forces on a geom act along
the geom's own axes, the columns of its rotation). Off the body axes it is kept to
:data:`DIGITS` decimals, so that its name (``e(0.8008,0.491,0.3429)``) is the direction
itself; an element's forces do not change with the sign of e (each is even in e), so the sign
is fixed: the largest component positive.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.frames import matrix_from_euler

#: A direction in the body frame: a body axis 0, 1, 2 (x, y, z: velocity letters u, v, w) or
#: another unit vector (e_x, e_y, e_z), as :func:`direction` gives it.
Direction = int | tuple[float, float, float]
#: An element's three axes in the body frame.
Axes = tuple[Direction, Direction, Direction]
#: The body axes: an element's axes unless its geom is rotated.
BODY_AXES: Axes = (0, 1, 2)
#: The decimals a direction off the body axes is kept to (its name's digits; an angle of
#: 1e-4 rad at most).
DIGITS = 4


def direction(e: Sequence[float] | NDArray[np.float64]) -> Direction:
    """The direction along ``e`` (3 numbers, not all zero, either sign) as a
    :data:`Direction`: its components to :data:`DIGITS` decimals, the largest positive, as
    given when ``e`` is already so (a unit vector to that precision: a name read back);
    the body axis a when that rounds to e_a.

    Parameters
    ----------
    e : sequence of 3 float or ndarray, shape (3,)
        A non-zero vector in the body frame (finite).

    Returns
    -------
    int or tuple of 3 float
        0, 1, 2 or the unit vector's rounded components.
    """
    v = np.asarray(e, dtype=float)
    scale = float(np.linalg.norm(v))
    # as given when it is a unit vector to DIGITS decimals, else the unit vector rounded
    unit = (v if abs(scale - 1.0) <= 0.5 * np.sqrt(3.0) * 10.0 ** -DIGITS
            and np.array_equal(np.round(v, DIGITS), v) else np.round(v / scale, DIGITS))
    # the sign that makes the largest component positive (0.0 for −0.0)
    unit = unit * np.sign(unit[int(np.argmax(np.abs(unit)))]) + 0.0
    for a in range(3):
        if np.array_equal(unit, np.eye(3)[a]):
            return a
    return (float(unit[0]), float(unit[1]), float(unit[2]))


def geom_axes(rpy: Sequence[float]) -> Axes:
    """A geom's x, y, z axes in the body frame, the columns of its rotation R(rpy) (ZYX
    angles, rad) as :data:`Direction` (:data:`BODY_AXES` for rpy = 0)."""
    R = matrix_from_euler(np.asarray(rpy, dtype=float))
    return direction(R[:, 0]), direction(R[:, 1]), direction(R[:, 2])
