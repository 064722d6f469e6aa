"""The shape of a vehicle for a fluid model: ellipsoid geoms (hull, housings, fins).

A vehicle file's optional ``geometry:`` block, read and checked when the vehicle is loaded
(so that a bad value is named with its file); the MuJoCo backend
(:mod:`dampest_ros.core.simulation.mujoco_backend`) turns it into MuJoCo geoms with
``fluidshape="ellipsoid"``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from dampest_ros.core.physics.rigid_body import ConfigError

#: MuJoCo's default ellipsoid fluid coefficients: blunt drag, slender drag, angular drag,
#: Kutta lift, Magnus lift.
DEFAULT_FLUIDCOEF = (0.5, 0.25, 1.5, 1.0, 1.0)
#: Dynamic viscosity of sea water at ~15 °C (Pa·s).
WATER_VISCOSITY = 1.2e-3


@dataclass(frozen=True)
class Geom:
    """One ellipsoid of the vehicle's shape (FRD body frame).

    Attributes
    ----------
    name : str
    size : tuple of 3 float
        Semi-axes (m), > 0.
    position : tuple of 3 float
        Centre in the body frame (m).
    rpy : tuple of 3 float
        Orientation of the geom's axes: roll, pitch, yaw (rad), ZYX.
    fluidcoef : tuple of 5 float
        MuJoCo's blunt drag, slender drag, angular drag, Kutta lift, Magnus lift.
    """

    name: str
    size: tuple[float, ...]
    position: tuple[float, ...] = (0.0, 0.0, 0.0)
    rpy: tuple[float, ...] = (0.0, 0.0, 0.0)
    fluidcoef: tuple[float, ...] = DEFAULT_FLUIDCOEF


@dataclass(frozen=True)
class Geometry:
    """The vehicle's shape for the fluid model: ellipsoid geoms and the water's viscosity.

    Built from a vehicle's ``geometry:`` block::

        geometry:
          viscosity: 1.2e-3                      # Pa·s (density is vehicle.rho)
          fluidcoef: [0.5, 0.25, 1.5, 1.0, 1.0]  # default of every geom
          geoms:
            - {name: hull, size: [0.23, 0.29, 0.13]}
            - {name: fin, size: [0.06, 0.08, 0.006], position: [-0.7, 0.17, 0], rpy: [0, 0, 0]}
    """

    geoms: tuple[Geom, ...]
    viscosity: float = WATER_VISCOSITY

    @classmethod
    def from_dict(cls, d: Any) -> Geometry:
        """From a ``geometry:`` mapping; every bad value raises ConfigError naming it."""
        if not isinstance(d, dict):
            raise ConfigError("geometry", "must be a mapping with a geoms: list")
        unknown = set(d) - {"viscosity", "fluidcoef", "geoms"}
        if unknown:
            raise ConfigError("geometry", f"unknown key(s) {sorted(unknown)}; known: "
                              "viscosity, fluidcoef, geoms")
        viscosity = _number("geometry.viscosity", d.get("viscosity", WATER_VISCOSITY))
        if viscosity < 0:
            raise ConfigError("geometry.viscosity", f"must be ≥ 0 (Pa·s), got {viscosity}")
        coef = _numbers("geometry.fluidcoef", d.get("fluidcoef", DEFAULT_FLUIDCOEF), 5)
        items = d.get("geoms")
        if not isinstance(items, list) or not items:
            raise ConfigError("geometry.geoms", "must be a non-empty list of ellipsoids")
        geoms = []
        for k, g in enumerate(items):
            where = f"geometry.geoms[{k}]"
            if not isinstance(g, dict):
                raise ConfigError(where, "must be a mapping {name, size, position, rpy}")
            bad = set(g) - {"name", "size", "position", "rpy", "fluidcoef"}
            if bad:
                raise ConfigError(where, f"unknown key(s) {sorted(bad)}; known: name, size, "
                                  "position, rpy, fluidcoef")
            if "size" not in g:
                raise ConfigError(f"{where}.size", "missing (three semi-axes in m)")
            size = _numbers(f"{where}.size", g["size"], 3)
            if min(size) <= 0:
                raise ConfigError(f"{where}.size", f"semi-axes must be > 0, got {list(size)}")
            gc = _numbers(f"{where}.fluidcoef", g.get("fluidcoef", coef), 5)
            if min(gc) < 0:
                raise ConfigError(f"{where}.fluidcoef", f"must be ≥ 0, got {list(gc)}")
            geoms.append(Geom(str(g.get("name", f"geom{k}")), size,
                              _numbers(f"{where}.position", g.get("position", (0, 0, 0)), 3),
                              _numbers(f"{where}.rpy", g.get("rpy", (0, 0, 0)), 3), gc))
        names = [g.name for g in geoms]
        if len(set(names)) != len(names):
            raise ConfigError("geometry.geoms", f"geom names must be unique, got {names}")
        return cls(tuple(geoms), viscosity)


def _number(where: str, v: Any) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise ConfigError(where, f"not a number: {v!r}") from None
    if not np.isfinite(x):
        raise ConfigError(where, "is NaN or Inf")
    return x


def _numbers(where: str, v: Any, n: int) -> tuple[float, ...]:
    if not isinstance(v, (list, tuple)) or len(v) != n:
        raise ConfigError(where, f"must be a list of {n} numbers, got {v!r}")
    return tuple(_number(f"{where}[{i}]", x) for i, x in enumerate(v))
