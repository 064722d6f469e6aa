"""Physical effects that can be hidden in simulated data (current, thrust errors, body
offsets, extra cross-coupling, fluid memory, sensor biases, delay, a damping change), and the
vehicle as the physics then sees it (:func:`true_vehicle`). The simulators
(:mod:`dampest_ros.core.simulation.simulate`, :mod:`dampest_ros.core.simulation.mujoco_backend`)
apply them.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import DOF_NAMES, ConfigError, RigidBody
from dampest_ros.core.physics.terms import CrossSpec, cross_term, memory_term
from dampest_ros.core.physics.vehicle import Vehicle

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Effects:
    """Physical effects that can be hidden in simulated data; all off by default.

    Attributes
    ----------
    current : tuple of 3 float
        Ocean current in NED (m/s), constant in the world frame.
    current_variation : float
        Amplitude (m/s) of a slow horizontal rotation of the current vector.
    current_period : float
        Period of that variation (s).
    thruster_deadzone : float
        Rotor speeds below this (rev/s) give no thrust; the logged thrust does not know it.
    thrust_gain_error : float
        Actual thrust = (1 + error) × the nominal curve that the logs use.
    buoyancy_offset : float
        Extra buoyancy (N), positive = lighter in water than the nominal model.
    cg_offset : tuple of 3 float
        Centre of gravity shift (m, FRD) from the nominal model.
    added_mass_error : float
        True M_A = (1 + error) × nominal M_A.
    extra_cross : tuple of dict
        Extra cross-coupling coefficients, each ``{row, col, alpha, value}`` (see CrossSpec).
    memory : tuple of dict
        Fluid memory states, each ``{dof, rate, c}`` (K(t) = c e^{−rate t}).
    gyro_bias, accel_bias, dvl_bias : tuple of 3 float
        Constant sensor biases (FRD), applied by the sensor models.
    delay : float
        Transport delay (s) between the logged thruster state and the force on the vehicle.
    damping_change_time : float
        Time (s) at which the quadratic damping is multiplied by ``damping_change_factor``
        (negative: never).
    damping_change_factor : float
    """

    current: tuple[float, float, float] = (0.0, 0.0, 0.0)
    current_variation: float = 0.0
    current_period: float = 600.0
    thruster_deadzone: float = 0.0
    thrust_gain_error: float = 0.0
    buoyancy_offset: float = 0.0
    cg_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    added_mass_error: float = 0.0
    extra_cross: tuple[dict[str, Any], ...] = ()
    memory: tuple[dict[str, Any], ...] = ()
    gyro_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    accel_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    dvl_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    delay: float = 0.0
    damping_change_time: float = -1.0
    damping_change_factor: float = 1.0

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Effects:
        """From a mapping; unknown keys raise ConfigError naming them."""
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ConfigError("effects", f"unknown effect(s) {sorted(unknown)}; known: "
                              f"{sorted(known)}")
        kw: dict[str, Any] = {}
        for k, v in d.items():
            if k in ("extra_cross", "memory"):
                kw[k] = tuple(dict(x) for x in v)
            elif isinstance(v, (list, tuple)):
                kw[k] = tuple(float(x) for x in v)
            else:
                kw[k] = float(v)
        return cls(**kw)

    def current_at(self, t: float) -> FloatArray:
        """Water current in NED at time t (m/s), shape (3,): the constant current plus its
        slow horizontal rotation."""
        c = np.asarray(self.current, dtype=float)
        if self.current_variation:
            w = 2 * np.pi / self.current_period
            c = c + self.current_variation * np.array([np.sin(w * t), np.cos(w * t), 0.0])
        return c

    def current_series(self, t: FloatArray) -> FloatArray:
        """:meth:`current_at` at each time of ``t`` (s, shape (N,)), shape (N, 3) (m/s)."""
        if not self.current_variation:
            return np.tile(self.current_at(0.0), (len(t), 1))
        return np.array([self.current_at(s) for s in np.asarray(t, dtype=float).tolist()])

    def as_dict(self) -> dict[str, Any]:
        """The effects that differ from the defaults."""
        default = Effects()
        return {f.name: getattr(self, f.name) for f in fields(self)
                if getattr(self, f.name) != getattr(default, f.name)}


def true_vehicle(vehicle: Vehicle, effects: Effects) -> Vehicle:
    """The vehicle as the physics sees it: nominal model plus the hidden effects.

    Body effects (CG offset, buoyancy offset, added-mass error) change the rigid body;
    extra cross-coupling and fluid memory add damping terms (merged into existing terms of
    the same kind).
    """
    b = vehicle.body
    body = RigidBody(
        mass=b.mass,
        inertia=b.inertia,
        r_g=b.r_g + np.asarray(effects.cg_offset),
        r_b=b.r_b,
        volume=b.volume + effects.buoyancy_offset / (b.rho * b.gravity),
        added_mass=b.added_mass * (1.0 + effects.added_mass_error),
        rho=b.rho,
        gravity=b.gravity,
        added_mass_terms=b.added_mass_terms,
    )
    values = dict(zip(vehicle.damping.parameter_names, vehicle.theta, strict=True))
    terms = {t.kind: t for t in vehicle.damping.terms}
    if effects.extra_cross:
        specs = [CrossSpec.from_dict(c) for c in effects.extra_cross]
        extra = cross_term(specs)
        old = terms.get("cross")
        terms["cross"] = replace(extra, bases=(old.bases if old else []) + extra.bases)
        values.update({s.label: float(c.get("value", 0.0))
                       for s, c in zip(specs, effects.extra_cross, strict=True)})
    if effects.memory:
        if "freq" in terms:
            raise ConfigError("effects.memory", "the nominal model already has a memory term")
        rates: dict[str | int, list[float]] = {}
        for m in effects.memory:
            rates.setdefault(str(m["dof"]), []).append(float(m["rate"]))
        mem = memory_term(rates)
        cs = {(str(m["dof"]), float(m["rate"])): float(m["c"]) for m in effects.memory}
        terms["freq"] = mem
        values.update({n: cs[(DOF_NAMES[int(d)], float(r))] for n, d, r in
                       zip(mem.parameter_names, mem.state_dofs, mem.rates, strict=True)})
    model = DampingModel(list(terms.values()))
    return replace(vehicle, body=body, damping=model, theta=model.theta_from_dict(values))
