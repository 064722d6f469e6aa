"""The MuJoCo backend: the vehicle as a free body in MuJoCo's ellipsoid fluid model.

This is the outside plant every estimation feature is tested against: its hydrodynamics are
MuJoCo's, not our equations. The vehicle's ``geometry:`` block gives one or more ellipsoid
geoms (hull, thruster housings, fins) with ``fluidshape="ellipsoid"``; MuJoCo computes the
fluid wrench on each from its own velocity relative to the water (``wind`` = the current).

MuJoCo's world here is NED (gravity along +z) and the body frame is FRD, so the state needs
no frame conversion: the free joint's ``qpos`` is the NED position of the body origin and
the FRD → NED quaternion [w, x, y, z]; ``qvel`` is [NED velocity of the body origin, FRD
angular velocity]; generalised forces are [NED force at the origin, FRD moment about it].

What the pinned MuJoCo (4.0.0) applies, measured (``test/core/simulation/test_mujoco_backend.py``)
----------------------------------------------------------------------------------------
- Added mass: only its velocity terms. Each geom carries a diagonal virtual mass and
  inertia (from its ellipsoid, times the fluid density); the force −C_A(ν)ν, Coriolis and
  Munk moments included, acts on it, with the geom's own velocity. Summed over geoms this is
  exactly Fossen's C_A(ν)ν of the composite added mass M_A = Σ Hᵀ(r) R M_g Rᵀ H(r)
  (:func:`plant_added_mass`). The inertial force −M_A ν̇ is **not** applied: a step force
  accelerates the body as if M = M_RB. The faithful vehicle description is therefore
  ``added_mass: M_A``, ``added_mass_terms: {inertial: false, coriolis: true, munk: true}``
  (:func:`plant_vehicle`).
- Drag on the Euclidean speed: linear drag is −(3π D_eq μ + ρ‖v‖(A_proj C_blunt +
  C_slender(A_max − A_proj))) v, with A_proj the ellipsoid's area projected along v; so a
  sway velocity raises the surge drag (‖v‖, not |u|). Angular drag is −(π D_eq³ μ +
  ρ‖c ⊙ ω‖) ω, again a magnitude over all three rates.
- Kutta lift ∝ ((n(v) × v) × v) and Magnus force ∝ ω × v (bilinear in the velocities);
  a geom off the origin turns its force into moments and sees ω × r in its velocity.
- Nothing else: no buoyancy (applied here at r_b), no fluid memory, no free surface.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.frames import quat_to_matrix
from dampest_ros.core.physics.geometry import Geometry
from dampest_ros.core.physics.rigid_body import AddedMassTerms, ConfigError, RigidBody, skew
from dampest_ros.core.physics.thrusters import lag_toward
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.simulation.effects import Effects
from dampest_ros.core.simulation.trajectory import Trajectory

FloatArray = NDArray[np.float64]

#: Longest MuJoCo (RK4) step (s): a slender AUV's fluid damping is stiff (a roll rate decays
#: at ~600 /s while it pitches at 0.7 rad/s), which 5 ms steps do not survive.
MAX_STEP = 0.002
#: Effects the MuJoCo plant can hide in its data; the others are properties of the fluid
#: model (added mass, cross coupling, memory, damping) and are refused.
SUPPORTED_EFFECTS = ("current", "current_variation", "current_period", "thruster_deadzone",
                     "thrust_gain_error", "buoyancy_offset", "cg_offset", "gyro_bias",
                     "accel_bias", "dvl_bias", "delay")


def geometry_of(vehicle: Vehicle) -> Geometry:
    """The vehicle's geometry, or ConfigError saying how to add one."""
    if vehicle.geometry is None:
        raise ConfigError("geometry", f"vehicle {vehicle.name!r} has no geometry: block, "
                          "which the mujoco backend needs (ellipsoid geoms; see "
                          "config/vehicles/bluerov2_heavy_mujoco.yaml)")
    return vehicle.geometry


def _quat_rpy(rpy: tuple[float, ...]) -> FloatArray:
    """[w, x, y, z] of the ZYX rotation roll, pitch, yaw."""
    cr, sr = np.cos(rpy[0] / 2), np.sin(rpy[0] / 2)
    cp, sp = np.cos(rpy[1] / 2), np.sin(rpy[1] / 2)
    cy, sy = np.cos(rpy[2] / 2), np.sin(rpy[2] / 2)
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


def _vec(v: Any) -> str:
    return " ".join(f"{float(x):.17g}" for x in np.ravel(v))


def mjcf(body: RigidBody, geometry: Geometry, timestep: float) -> str:
    """The MJCF model of the vehicle: a free body in water, NED world (gravity +z).

    Parameters
    ----------
    body : RigidBody
        Mass, inertia about the CG and r_g; ``rho`` is the fluid density.
    geometry : Geometry
    timestep : float
        MuJoCo's integration step (s).

    Returns
    -------
    str
        The XML text. Geoms have no contacts and no mass (the ``inertial`` element sets it);
        ``ctrl`` is the applied body wrench [X, Y, Z, K, M, N] (FRD, about the origin).
    """
    J = body.inertia
    lines = [
        '<mujoco model="dampest_vehicle">',
        f'  <option timestep="{timestep:.17g}" integrator="RK4" density="{body.rho:.17g}" '
        f'viscosity="{geometry.viscosity:.17g}" gravity="0 0 {body.gravity:.17g}"/>',
        "  <worldbody>",
        '    <body name="vehicle">',
        "      <freejoint/>",
        f'      <inertial pos="{_vec(body.r_g)}" mass="{body.mass:.17g}" '
        f'fullinertia="{_vec([J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2]])}"/>',
    ]
    for g in geometry.geoms:
        lines.append(
            f'      <geom name="{g.name}" type="ellipsoid" size="{_vec(g.size)}" '
            f'pos="{_vec(g.position)}" quat="{_vec(_quat_rpy(g.rpy))}" mass="0" '
            f'contype="0" conaffinity="0" fluidshape="ellipsoid" '
            f'fluidcoef="{_vec(g.fluidcoef)}"/>')
    # the thrusters' body wrench: six actuators on a site at the origin, one per axis of
    # [force, moment] in the body frame (MuJoCo turns them with the body within its steps)
    lines += ['      <site name="origin"/>', "    </body>", "  </worldbody>", "  <actuator>"]
    lines += [f'    <general name="tau_{k}" site="origin" gear="{_vec(np.eye(6)[k])}"/>'
              for k in range(6)]
    lines += ["  </actuator>", "</mujoco>"]
    return "\n".join(lines)


def compile_model(body: RigidBody, geometry: Geometry, timestep: float, source: str = ""
                  ) -> Any:
    """``mujoco.MjModel`` of the vehicle; MuJoCo's own complaint becomes a ConfigError
    naming the vehicle file ``source``."""
    import mujoco

    try:
        return mujoco.MjModel.from_xml_string(mjcf(body, geometry, timestep))
    except ValueError as exc:
        where = f" (vehicle file {source})" if source else ""
        text = " ".join(str(exc).split())
        raise ConfigError("geometry", f"MuJoCo rejects the vehicle{where}: {text}") from None


def plant_added_mass(model: Any, rho: float) -> FloatArray:
    """The added mass whose velocity terms MuJoCo applies, about the body origin (FRD).

    Each geom's virtual mass m_g and inertia I_g (``geom_fluid``, per unit density) make a
    diagonal M_g = ρ diag(m_g, I_g) in the geom's axes; rotated into the body axes
    (R M_g Rᵀ per 3×3 block) and moved to the origin with H(r) = [[I, S(r)ᵀ], [0, I]]
    (Fossen 2011, eq. 3.42): M_A = Σ_g Hᵀ(r_g) M_g H(r_g).

    Parameters
    ----------
    model : mujoco.MjModel
        A model built by :func:`compile_model` (one body).
    rho : float
        Fluid density (kg/m³).

    Returns
    -------
    ndarray, shape (6, 6)
    """
    M_A = np.zeros((6, 6))
    for k in range(model.ngeom):
        coef = np.asarray(model.geom_fluid[k], dtype=float)
        R = quat_to_matrix(np.asarray(model.geom_quat[k], dtype=float))
        # M_g in body axes: R diag(·) Rᵀ for the translational and the rotational block
        Mg = np.zeros((6, 6))
        Mg[:3, :3] = rho * R @ np.diag(coef[6:9]) @ R.T
        Mg[3:, 3:] = rho * R @ np.diag(coef[9:12]) @ R.T
        H = np.eye(6)
        H[:3, 3:] = skew(np.asarray(model.geom_pos[k], dtype=float)).T
        # M_A += Hᵀ M_g H
        M_A += H.T @ Mg @ H
    return 0.5 * (M_A + M_A.T)


def plant_vehicle(vehicle: Vehicle) -> Vehicle:
    """The vehicle as MuJoCo's fluid model makes it: its geometry's added mass, applied
    through the velocity terms only (``added_mass_terms: {inertial: false}``).

    The damping stays the vehicle's nominal one (a prior: MuJoCo's drag is not of that form).
    """
    body = vehicle.body
    model = compile_model(body, geometry_of(vehicle), 0.01, vehicle.source)
    plant = replace(body, added_mass=plant_added_mass(model, body.rho),
                    added_mass_terms=AddedMassTerms(inertial=False, coriolis=True, munk=True))
    return replace(vehicle, body=plant)


class PlantDivergedError(ValueError):
    """MuJoCo's integration went unstable (NaN, Inf or huge state); the message says when."""


#: MuJoCo's warnings of this process, collected instead of printed and written to
#: MUJOCO_LOG.TXT in the working directory (MuJoCo's default); :meth:`MujocoSimulator.step`
#: turns an instability warning into :class:`PlantDivergedError`.
_WARNINGS: list[str] = []


def _collect_warning(text: str) -> None:
    _WARNINGS.append(str(text))


class MujocoSimulator:
    """The vehicle in MuJoCo, one control step at a time (same interface as
    :class:`dampest_ros.core.simulation.simulate.Simulator`).

    Thrusters and the hidden thruster effects are computed here and applied as one body
    wrench (six actuators), held over the control step; buoyancy acts up at r_b; MuJoCo
    integrates the rigid body with its fluid forces (RK4, ``substeps`` per control step).

    Parameters
    ----------
    vehicle : Vehicle
        Needs a ``geometry:`` block.
    effects : Effects, optional
        Only :data:`SUPPORTED_EFFECTS`; the others raise ConfigError.
    dt : float
        Control and logging step (s).
    position, quaternion : ndarray, optional
        Initial NED position (default 5 m deep) and FRD → NED attitude [w, x, y, z].
    record : bool
        Keep the ground truth of every step for :meth:`trajectory`.
    substeps : int, optional
        MuJoCo steps per control step (default: steps of at most :data:`MAX_STEP`).
    """

    BLOCK = 4096  # steps kept as rows of values before they become log rows

    def __init__(self, vehicle: Vehicle, effects: Effects | None = None, dt: float = 0.02,
                 position: FloatArray | None = None, quaternion: FloatArray | None = None,
                 record: bool = True, substeps: int | None = None) -> None:
        import mujoco

        if not np.isfinite(dt) or dt <= 0:
            raise ConfigError("dt", f"must be > 0, got {dt}")
        # MuJoCo steps of at most MAX_STEP: its RK4 must stay stable under the stiffest
        # fluid damping (a slender body's roll damping grows with the pitch rate: ‖c ⊙ ω‖)
        substeps = max(1, math.ceil(dt / MAX_STEP - 1e-9)) if substeps is None else substeps
        if substeps < 1:
            raise ConfigError("substeps", f"must be ≥ 1, got {substeps}")
        self.nominal = vehicle
        self.effects = effects if effects is not None else Effects()
        refused = sorted(set(self.effects.as_dict()) - set(SUPPORTED_EFFECTS))
        if refused:
            raise ConfigError("effects", f"{', '.join(refused)}: not available on the mujoco "
                              "backend (its fluid model sets the hydrodynamics); supported: "
                              f"{', '.join(SUPPORTED_EFFECTS)}")
        self._mj = mujoco
        mujoco.set_mju_user_warning(_collect_warning)
        b = vehicle.body
        e = self.effects
        body = replace(b, r_g=b.r_g + np.asarray(e.cg_offset),
                       volume=b.volume + e.buoyancy_offset / (b.rho * b.gravity))
        self.body = body
        self.dt = float(dt)
        self.substeps = int(substeps)
        self.model = compile_model(body, geometry_of(vehicle), self.dt / self.substeps,
                                   vehicle.source)
        self.data = mujoco.MjData(self.model)
        self._B = body.buoyancy
        self._r_bg = (body.r_b - body.r_g).tolist()
        self.plant = plant_vehicle(vehicle)
        self._thr = vehicle.need_thrusters("simulating the vehicle")
        self._deadzone = max(self._thr.deadzone, e.thruster_deadzone)
        self._delay_steps = round(float(e.delay) / self.dt)
        self._cmd_queue: deque[FloatArray] = deque(
            [np.zeros(self._thr.count)] * self._delay_steps)
        self._has_current = bool(np.any(e.current) or e.current_variation)
        p0 = np.array([0.0, 0.0, 5.0]) if position is None else np.asarray(position, float)
        q0 = np.array([1.0, 0.0, 0.0, 0.0]) if quaternion is None else np.asarray(quaternion,
                                                                                   float)
        self.data.qpos[:3] = p0
        self.data.qpos[3:7] = q0 / np.linalg.norm(q0)
        mujoco.mj_kinematics(self.model, self.data)
        self.t = 0.0
        self.rotor = np.zeros(self._thr.count)  # what the vehicle logs (undelayed)
        self._rotor_phys = np.zeros(self._thr.count)
        self._record = record
        tm = self._thr.time_constant
        # the lag's decay over half a step and over a step (none without a lag)
        self._decay = ((np.exp(-self.dt / (2 * tm)), np.exp(-self.dt / tm)) if tm > 0
                       else ())
        self._nu: FloatArray | None = None
        # blocks of log rows, and the values of the steps since the last block
        self._log: list[FloatArray] = []
        self._steps: list[tuple[list[float], FloatArray, FloatArray]] = []

    # --- state access (the Simulator interface) ----------------------------------------

    @property
    def position(self) -> FloatArray:
        """NED position of the body origin (m), shape (3,)."""
        return np.array(self.data.qpos[:3])

    @property
    def quaternion(self) -> FloatArray:
        """Attitude [w, x, y, z], FRD → NED, shape (4,)."""
        return np.array(self.data.qpos[3:7])

    @property
    def nu(self) -> FloatArray:
        """Body velocity over ground (FRD), shape (6,)."""
        if self._nu is None:  # once per step: the controller asks more than once
            R = quat_to_matrix(self.quaternion)
            self._nu = np.concatenate([R.T @ self.data.qvel[:3], self.data.qvel[3:6]])
        return self._nu.copy()

    def current_ned(self, t: float) -> FloatArray:
        """Water current in NED at time t (m/s), shape (3,)."""
        return self.effects.current_at(t)

    def wrench_to_command(self, tau: FloatArray) -> FloatArray:
        """Rotor speeds (rev/s) that produce τ with the nominal thrusters, saturated."""
        return self._thr.speed_for_thrust(self._thr.allocate(tau))

    # --- dynamics ----------------------------------------------------------------------

    def _buoy(self, d: Any) -> None:
        """Buoyancy B up (−z NED) at r_b, as MuJoCo's Cartesian force on the body: the force
        at the CG plus the moment (R (r_b − r_g)) × [0, 0, −B], with R at the start of the
        MuJoCo step (held over it, as MuJoCo holds every applied force); ``d.xmat`` must be
        current (:func:`mujoco.mj_kinematics` after each step)."""
        xm = d.xmat[1]
        a0, a1, a2 = self._r_bg
        # world components x, y of R (r_b − r_g); (a × [0, 0, −B]) = [−B a_y, B a_x, 0]
        ax = xm[0] * a0 + xm[1] * a1 + xm[2] * a2
        ay = xm[3] * a0 + xm[4] * a1 + xm[5] * a2
        B = self._B
        d.xfrc_applied[1, 2] = -B
        d.xfrc_applied[1, 3] = -B * ay
        d.xfrc_applied[1, 4] = B * ax

    def step(self, rotor_command: FloatArray) -> None:
        """Advance one control step ``dt`` with the rotor speed command held (rev/s)."""
        mj, m, d = self._mj, self.model, self.data
        e = self.effects
        thr = self._thr
        cmd = np.clip(np.asarray(rotor_command, dtype=float), -thr.n_max, thr.n_max)
        if self._delay_steps:
            self._cmd_queue.append(cmd)
            phys_cmd = self._cmd_queue.popleft()
        else:
            phys_cmd = cmd
        h = self.dt
        # rotor speeds over the step (first-order lag, exact) and the mean thrust (Simpson)
        n0, n_end = self.rotor, self._lag_end(self.rotor, cmd)
        p0, p_mid, p_end = ((self._rotor_phys, lag_toward(self._rotor_phys, phys_cmd,
                                                          self._decay[0]),
                             self._lag_end(self._rotor_phys, phys_cmd))
                            if self._decay else (phys_cmd, phys_cmd, phys_cmd))
        tau_thr = thr.wrench(thr.step_thrust(p0, p_mid, p_end, e.thrust_gain_error,
                                             self._deadzone))
        t = self.t
        if self._has_current:
            # the current is MuJoCo's wind (NED), held over the step at its midpoint value
            m.opt.wind[:] = self.current_ned(t + 0.5 * h)
        d.ctrl[:] = tau_thr
        self._buoy(d)
        if self._record:
            mj.mj_forward(m, d)
            self._steps.append((self._state_row(t, tau_thr), n0, cmd))
            if len(self._steps) >= self.BLOCK:
                self._log.append(self._rows())
        for k in range(self.substeps):
            if k:
                self._buoy(d)
            mj.mj_step(m, d)
            mj.mj_kinematics(m, d)
        if _WARNINGS or not np.all(np.isfinite(d.qvel)):
            text = _WARNINGS[-1] if _WARNINGS else "non-finite velocity"
            _WARNINGS.clear()
            raise PlantDivergedError(f"MuJoCo's integration became unstable at t = {t:.2f} s "
                                f"({text.strip()}); try a shorter --dt or gentler excitation")
        self.rotor = n_end
        self._rotor_phys = p_end
        self._nu = None
        self.t = t + h

    def _lag_end(self, n0: FloatArray, command: FloatArray) -> FloatArray:
        """Rotor speeds at the end of a step from n₀ with the command held (rev/s)."""
        return lag_toward(n0, command, self._decay[1]) if self._decay else command

    def _state_row(self, t: float, tau_thr: FloatArray) -> list[float]:
        """[t, qpos (7), ν, ν̇, τ_thr, fluid wrench] of the state ``mj_forward`` left in
        ``data`` (FRD body), on Python floats."""
        d = self.data
        Rt = d.xmat[1].reshape(3, 3).T
        v = (Rt @ d.qvel[:3]).tolist()
        w = d.qvel[3:6].tolist()
        # ν̇ = [Rᵀ a − ω × v, ω̇] from the NED acceleration of the origin
        a = (Rt @ d.qacc[:3]).tolist()
        wxv = [w[1] * v[2] - w[2] * v[1], w[2] * v[0] - w[0] * v[2], w[0] * v[1] - w[1] * v[0]]
        return [t, *d.qpos[:7].tolist(), *v, *w, *(a_ - c for a_, c in zip(a, wxv, strict=True)),
                *d.qacc[3:6].tolist(), *tau_thr.tolist(), *(Rt @ d.qfrc_fluid[:3]).tolist(),
                *d.qfrc_fluid[3:6].tolist()]

    def _rows(self) -> FloatArray:
        """The pending steps as log rows: [t, qpos, ν, ν̇, τ_thr, mean rotor speed, mean
        thrust, current, fluid wrench], the step means computed for the whole block."""
        state, n0, cmd = (np.array(c) for c in zip(*self._steps, strict=True))
        self._steps = []
        n_mean, thrust_mean = self._thr.step_means(n0, cmd, self.dt)
        return np.column_stack([state[:, :26], n_mean, thrust_mean,
                                self.effects.current_series(state[:, 0]), state[:, 26:]])

    def take_log(self, keep: int = 1) -> Trajectory:
        """The steps recorded so far, then forget all but the last ``keep`` (streaming)."""
        traj = self.trajectory()
        self._log = [self._log[0][-keep:]] if keep > 0 and self._log else []
        return traj

    def trajectory(self) -> Trajectory:
        """Ground truth of every recorded step, with MuJoCo's fluid wrench as ``hydro``."""
        nt = self._thr.count
        if self._steps:
            self._log.append(self._rows())
        self._log = [np.concatenate(self._log)] if self._log else []
        log = self._log[0] if self._log else np.zeros((0, 26 + 2 * nt + 3 + 6))
        cols = np.cumsum([1, 3, 4, 6, 6, 6, nt, nt, 3])
        t, pos, quat, nu, nu_dot, tau, rotor, thrust, cur, hydro = np.split(log, cols, axis=1)
        return Trajectory(t=t[:, 0], position=pos, quaternion=quat, nu=nu, nu_dot=nu_dot,
                          tau=tau, rotor_speed=rotor, thrust=thrust, current=cur,
                          memory=np.zeros((len(t), 0)), thruster_names=self._thr.names,
                          hydro=hydro)
