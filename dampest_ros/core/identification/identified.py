"""What every reader of an identified model checks, and what the data determined.

The check every reader of a model (:class:`~dampest_ros.core.identification.model.Model`)
shares: :func:`check_model_numbers` (θ, M and the σ of the identified coefficients finite).
A model says per coefficient whether the data determined it (``held``: name → why it stayed
at its prior; :func:`identified_mask`); a model file without its term structure has it
rebuilt from the names (:func:`damping_from_names`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import (
    DOF_NAMES,
    FORCE_NAMES,
    ConfigError,
)
from dampest_ros.core.physics.vehicle import damping_from_spec

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

def damping_from_names(names: Sequence[str]) -> DampingModel:
    """Rebuild a damping model from SNAME names alone (linear ``X_u``, ``Y_r``; quadratic
    ``X_uu`` … ``N_rr``), for model files written without ``model.terms``."""
    linear: dict[str, float] = {}
    quadratic: dict[str, float] = {}
    for n in names:
        force, _, vel = n.partition("_")
        if force in FORCE_NAMES and len(vel) == 2 and vel[0] == vel[1] and vel[0] in DOF_NAMES:
            quadratic[n] = 0.0
        elif force in FORCE_NAMES and vel in DOF_NAMES:
            linear[n] = 0.0
        else:
            raise ConfigError("model.parameter_names",
                              f"{n!r} needs model.terms to be rebuilt (not linear/quadratic)")
    spec: dict[str, dict[str, float]] = {}
    if linear:
        spec["linear"] = linear
    if quadratic:
        spec["quadratic"] = quadratic
    model, _ = damping_from_spec(spec)
    if model.parameter_names != list(names):
        raise ConfigError("model.parameter_names", "order must be linear terms, then quadratic")
    return model


def identified_mask(names: Sequence[str], held: Mapping[str, str]) -> BoolArray:
    """Per coefficient, True when the data determined it (its name is not in ``held``)."""
    return np.array([n not in held for n in names], dtype=bool)


def check_model_numbers(names: Sequence[str], theta: FloatArray, theta_std: FloatArray,
                        M: FloatArray, held: Mapping[str, str] | None = None,
                        where: str = "") -> None:
    """Refuse a model whose numbers no controller or simulator can use.

    θ and every entry of M must be finite; σ must be finite for each identified
    coefficient (one in ``held`` stayed at its prior: its σ may be NaN, not estimated);
    ``held`` names parameters of the model.

    Parameters
    ----------
    names : sequence of str
        Parameter names, θ order.
    theta, theta_std : ndarray, shape (p,)
    M : ndarray, 36 entries
    held : mapping of str to str, optional
        The coefficients held at their prior, with the reason.
    where : str
        Appended to the message (e.g. `` (in model.yaml)``).

    Raises
    ------
    ConfigError
        Naming the entry and its value, e.g. ``model.theta: Z_ww = nan (in m.yaml)``.
    """
    theta = np.asarray(theta, dtype=float)
    std = np.asarray(theta_std, dtype=float)
    M = np.asarray(M, dtype=float).reshape(-1)
    unknown = sorted(set(held or {}) - set(names))
    if unknown:
        raise ConfigError("model.held", f"names no parameter of the model: {unknown}{where}")
    bad = [f"{n} = {v}" for n, v in zip(names, theta, strict=True) if not np.isfinite(v)]
    if bad:
        raise ConfigError("model.theta", f"not finite: {', '.join(bad)}{where}")
    mask = identified_mask(names, held or {})
    bad = [f"{n} = {v}" for n, v, ok in zip(names, std, mask, strict=True)
           if ok and not np.isfinite(v)]
    if bad:
        raise ConfigError("model.theta_std", f"not finite for an identified coefficient: "
                                             f"{', '.join(bad)}{where}")
    bad = [f"M[{FORCE_NAMES[k // 6]},{DOF_NAMES[k % 6]}] = {v}" for k, v in enumerate(M)
           if not np.isfinite(v)]
    if bad:
        raise ConfigError("model.M", f"not finite: {', '.join(bad)}{where}")
