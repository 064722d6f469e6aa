"""A vehicle: rigid body + added mass, damping model with its coefficients, thrusters.

The ``thrusters`` section is optional: a vehicle whose logs carry the generalised force τ
(``tau_*`` CSV columns, a body-wrench topic) needs none. What turns thrust into τ or τ into
thrust (simulation, thruster telemetry, the velocity controller) asks for it with
:meth:`Vehicle.need_thrusters`, which names what is missing in one line.

Built from a preset mapping (``config/vehicles/*.yaml`` loaded by :mod:`dampest_ros.io`).
The ``damping`` section names coefficients by SNAME names, stored positive when dissipative::

    damping:
      linear: {X_u: 13.7, Y_v: 0.0, ...}          # X_u … N_r, off-diagonal like Y_r
      quadratic: {X_uu: 141.0, ...}               # X_{u|u|} …
      cross: [{row: Y, col: v, alpha: "|r|", value: 2.0}]
      freq: [{dof: u, rate: 2.0, c: 5.0}]
      added: {added.N_uv: 0.0}
      residual: {modes: [[...6...], ...], values: [...]}
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.damping import DampingModel, DampingTerm
from dampest_ros.core.physics.geometry import Geometry
from dampest_ros.core.physics.identity import Identity, vehicle_identity
from dampest_ros.core.physics.mounting import Mounting
from dampest_ros.core.physics.point_drag import PointSpec, point_term
from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES, ConfigError, RigidBody
from dampest_ros.core.physics.terms import (
    CrossSpec,
    added_mass_term,
    coriolis_term,
    cross_term,
    linear_term,
    memory_term,
    quadratic_term,
    residual_term,
)
from dampest_ros.core.physics.thrusters import Thrusters

FloatArray = NDArray[np.float64]


def _letters(name: str, section: str) -> tuple[int, int]:
    """(row, col) of an SNAME name like ``X_u``, ``Y_r`` or ``X_uu``."""
    try:
        force, vel = name.split("_", 1)
        return FORCE_NAMES.index(force), DOF_NAMES.index(vel[0])
    except ValueError:
        raise ConfigError(f"damping.{section}", f"bad coefficient name {name!r}") from None


def _values(section: str, d: Any) -> dict[str, float]:
    if not isinstance(d, dict):
        raise ConfigError(f"damping.{section}", "must be a mapping of name: value")
    out = {}
    for k, v in d.items():
        try:
            out[str(k)] = float(v)
        except (TypeError, ValueError):
            raise ConfigError(f"damping.{section}.{k}", f"not a number: {v!r}") from None
        if not np.isfinite(out[str(k)]):
            raise ConfigError(f"damping.{section}.{k}", "is NaN or Inf")
    return out


def damping_from_spec(spec: dict[str, Any]) -> tuple[DampingModel, FloatArray]:
    """Damping model and its θ from a preset's ``damping`` mapping.

    Returns
    -------
    model : DampingModel
    theta : ndarray, shape (p,)
    """
    terms: list[DampingTerm] = []
    values: dict[str, float] = {}
    if "linear" in spec:
        lin = _values("linear", spec["linear"])
        diag: list[tuple[int, int]] = []
        off: list[tuple[int, int]] = []
        for name in lin:
            r, c = _letters(name, "linear")
            (diag if r == c else off).append((r, c))
        terms.append(linear_term([r for r, _ in diag], off))
        values.update(lin)
    if "quadratic" in spec:
        quad = _values("quadratic", spec["quadratic"])
        dofs = []
        for name in quad:
            r, c = _letters(name, "quadratic")
            if r != c or name[2:] != DOF_NAMES[c] * 2:
                raise ConfigError("damping.quadratic", f"{name!r} is not X_uu … N_rr")
            dofs.append(r)
        terms.append(quadratic_term(dofs))
        values.update(quad)
    if spec.get("cross"):
        specs = [CrossSpec.from_dict(c) for c in spec["cross"]]
        terms.append(cross_term(specs))
        values.update({s.label: float(c.get("value", 0.0)) for s, c in zip(specs, spec["cross"],
                                                                              strict=True)})
    if spec.get("freq"):
        rates: dict[str | int, list[float]] = {}
        cs: list[float] = []
        for item in spec["freq"]:
            rates.setdefault(str(item["dof"]), []).append(float(item["rate"]))
        mem = memory_term(rates)
        # order of states follows the dict grouping; match c values by (dof, rate)
        by_key = {(str(i["dof"]), float(i["rate"])): float(i.get("c", 0.0)) for i in spec["freq"]}
        for d, lam in zip(mem.state_dofs, mem.rates, strict=True):
            cs.append(by_key[(DOF_NAMES[int(d)], float(lam))])
        terms.append(mem)
        values.update(dict(zip(mem.parameter_names, cs, strict=True)))
    if "added" in spec:
        terms.append(added_mass_term())
        values.update(_values("added", spec["added"] or {}))
    if "coriolis" in spec:
        cor = _values("coriolis", spec["coriolis"] or {})
        axes = [n.removeprefix("coriolis.m_") for n in cor] or ["u", "v", "w"]
        if any(a not in ("u", "v", "w") for a in axes):
            raise ConfigError("damping.coriolis", f"names are coriolis.m_u, coriolis.m_v, "
                                                  f"coriolis.m_w; got {list(cor)}")
        terms.append(coriolis_term(axes))
        values.update(cor)
    if spec.get("point"):
        points = [PointSpec.from_dict(d, f"damping.point[{k}]")
                  for k, d in enumerate(spec["point"])]
        terms.append(point_term(points))
        values.update({p.label: float(d.get("value", 0.0))
                       for p, d in zip(points, spec["point"], strict=True)})
    if "residual" in spec:
        res = spec["residual"] or {}
        term = residual_term(np.asarray(res["modes"], dtype=float).T if "modes" in res else None)
        terms.append(term)
        vals = list(res.get("values", [0.0] * term.n_params))
        values.update(dict(zip(term.parameter_names, map(float, vals), strict=True)))
    model = DampingModel(terms)
    return model, model.theta_from_dict(values)


@dataclass
class Vehicle:
    """Everything the simulator and the identification need to know about a vehicle.

    Parameters
    ----------
    name : str
    body : RigidBody
        Mass, inertia, added mass, restoring data.
    damping : DampingModel
        The term structure of D(ν).
    theta : ndarray, shape (p,)
        Damping coefficients (truth for a simulator, nominal/prior for identification).
    thrusters : Thrusters or None
        None when the vehicle file has no ``thrusters`` section.
    length : float
        Reference length L (m) for nondimensionalisation.
    extra : dict
        The file's other sections, as read.
    geometry : Geometry or None
        The shape for a fluid model (the MuJoCo backend), from a ``geometry:`` section.
    source : str
        The file the vehicle was read from ("" when built in code), for messages.
    mounting : Mounting
        Where the IMU, DVL and pressure sensor sit, from a ``sensors:`` section
        (:mod:`dampest_ros.core.physics.mounting`; default: at the origin, aligned).
    """

    name: str
    body: RigidBody
    damping: DampingModel
    theta: FloatArray
    thrusters: Thrusters | None
    length: float = 1.0
    extra: dict[str, Any] = field(default_factory=dict)
    geometry: Geometry | None = None
    source: str = ""
    mounting: Mounting = field(default_factory=Mounting)

    @property
    def identity(self) -> Identity:
        """Its name and the hashes of its rigid body, added mass and thrusters
        (:func:`~dampest_ros.core.physics.identity.vehicle_identity`): what every model made
        for it carries."""
        return vehicle_identity(self.name, self.body, self.thrusters)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Vehicle:
        """Build from a preset mapping with sections ``vehicle``, ``damping`` and, optionally,
        ``thrusters``, ``geometry`` and ``sensors``."""
        for key in ("vehicle", "damping"):
            if key not in d:
                raise ConfigError(key, "missing section")
        body = RigidBody.from_dict(d["vehicle"])
        damping, theta = damping_from_spec(d["damping"])
        thrusters = None if d.get("thrusters") is None else \
            Thrusters.from_dict(d["thrusters"], rho=body.rho)
        length = float(d["vehicle"].get("length", 1.0))
        if not np.isfinite(length) or length <= 0:
            raise ConfigError("vehicle.length", f"must be > 0, got {length}")
        geometry = None if d.get("geometry") is None else Geometry.from_dict(d["geometry"])
        return cls(str(d["vehicle"].get("name", "vehicle")), body, damping, theta, thrusters,
                   length, {k: v for k, v in d.items()
                            if k not in ("vehicle", "damping", "thrusters", "geometry",
                                         "sensors")},
                   geometry, mounting=Mounting.from_dict(d.get("sensors")))

    def need_thrusters(self, what: str, instead: str = "") -> Thrusters:
        """The thrusters, or ConfigError naming ``what`` needs them and how to give them
        (``instead``: another way, e.g. ``"give --wrench-topic"``)."""
        if self.thrusters is None:
            raise ConfigError("thrusters", f"{what} needs the vehicle's thrusters, and vehicle "
                              f"{self.name!r} has none: add a thrusters: section (model and "
                              "units) to its file" + (f", or {instead}" if instead else ""))
        return self.thrusters

    def wrench_scale(self, force: FloatArray | None = None) -> FloatArray:
        """The largest generalised force per DOF, shape (6,) (N, N·m): the thrusters'
        :attr:`~dampest_ros.core.physics.thrusters.Thrusters.max_wrench`, or without thrusters
        the largest the data show (:func:`wrench_scale_of` ``force``).

        Parameters
        ----------
        force : ndarray, shape (6,), optional
            The 99th percentile of the measured |τ_i| per DOF (FRD, N and N·m; an
            :class:`~dampest_ros.core.signals.extent.Extent`'s ``force``); needed when the
            vehicle has no thrusters.
        """
        if self.thrusters is not None:
            return np.asarray(self.thrusters.max_wrench, dtype=float)
        if force is None:
            raise ConfigError("thrusters", f"vehicle {self.name!r} has no thrusters and no "
                                           "measured τ was given for the force scale")
        return wrench_scale_of(force)


def measured_wrench_scale(tau: FloatArray, percentile: float = 99.0) -> FloatArray:
    """The largest generalised force per DOF that the data show, shape (6,) (N, N·m):
    :func:`wrench_scale_of` the ``percentile`` of |τ_i| per DOF (robust to single spikes).

    Parameters
    ----------
    tau : ndarray, shape (n, 6)
        Measured τ (FRD, N and N·m); non-finite rows are ignored.
    percentile : float
    """
    tau = np.asarray(tau, dtype=float).reshape(-1, 6)
    tau = tau[np.all(np.isfinite(tau), axis=1)]
    if len(tau) == 0:
        raise ConfigError("tau", "no finite measured generalised force to scale with")
    return wrench_scale_of(np.percentile(np.abs(tau), percentile, axis=0))


def wrench_scale_of(force: FloatArray) -> FloatArray:
    """The force scale per DOF from the largest |τ_i| the data show, shape (6,) → (6,)
    (N, N·m): a DOF the data never push (below 1e-6 of its group's largest, forces X, Y, Z
    or moments K, M, N) takes 1 % of that largest, or 1 when the whole group is zero, so
    that the scale is never zero."""
    s = np.array(force, dtype=float)
    for g in (slice(0, 3), slice(3, 6)):
        top = float(s[g].max())
        s[g] = np.where(s[g] > 1e-6 * top, s[g], 0.01 * top if top > 0 else 1.0)
    return s


def nondim_scales(v_ref: float, L_ref: float, rho: float) -> tuple[FloatArray, FloatArray]:
    """Velocity and force scales of the prime system for reference speed and length.

    Parameters
    ----------
    v_ref : float
        Reference speed (m/s), > 0.
    L_ref : float
        Reference length (m), > 0.
    rho : float
        Water density (kg/m³).

    Returns
    -------
    nu_scale : ndarray, shape (6,)
        [v, v, v, v/L, v/L, v/L].
    force_scale : ndarray, shape (6,)
        [F, F, F, F L, F L, F L] with F = ½ ρ L² v².
    """
    if v_ref <= 0 or L_ref <= 0:
        raise ConfigError("v_ref/L_ref", "must be > 0")
    F = 0.5 * rho * L_ref**2 * v_ref**2
    nu_scale = np.array([v_ref] * 3 + [v_ref / L_ref] * 3)
    force_scale = np.array([F] * 3 + [F * L_ref] * 3)
    return nu_scale, force_scale
