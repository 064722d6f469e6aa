"""6-DOF vehicle simulator: fixed-step RK4 of Fossen's model with thrusters, current,
fluid memory and switchable hidden effects.

Equations (FRD body, NED world, ν_r = ν − ν_c the velocity relative to the water):

    M_RB ν̇ + C_RB(ν)ν + M_A ν̇_r + C_A(ν_r)ν_r + D(ν_r)ν_r + g(η) = τ
    ṗ = R(q) ν_1,   q̇ = ½ q ⊗ (0, ν_2),   ż = −λ z + ν_r[dof],   ṅ = (n_cmd − n)/T_m
"""

from __future__ import annotations

import math
from collections import deque
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.frames import roll_pitch
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.thrusters import lag_toward
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.measurements import Recording
from dampest_ros.core.simulation.control import VelocityPI
from dampest_ros.core.simulation.effects import Effects, true_vehicle
from dampest_ros.core.simulation.excitation import Excitation, ProtocolStream
from dampest_ros.core.simulation.excitation import protocol as make_protocol
from dampest_ros.core.simulation.sensors import SensorBias, SensorConfig, measure
from dampest_ros.core.simulation.trajectory import Trajectory

FloatArray = NDArray[np.float64]


def _cross(a: list[float], b: list[float]) -> list[float]:
    # a × b on Python floats: cheaper than numpy for single 3-vectors
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _coriolis_force(v: list[float], om: list[float], a: list[float]) -> list[float]:
    """C(ν)ν = [ω × a1, v × a1 + ω × a2] for ν = [v, ω] and a = M ν, on Python floats
    (one call for what takes three of :func:`_cross`)."""
    v0, v1, v2 = v
    w0, w1, w2 = om
    a0, a1, a2, a3, a4, a5 = a
    return [w1 * a2 - w2 * a1, w2 * a0 - w0 * a2, w0 * a1 - w1 * a0,
            (v1 * a2 - v2 * a1) + (w1 * a5 - w2 * a4),
            (v2 * a0 - v0 * a2) + (w2 * a3 - w0 * a5),
            (v0 * a1 - v1 * a0) + (w0 * a4 - w1 * a3)]


class Simulator:
    """Fixed-step RK4 integration of the true vehicle, one step at a time.

    Parameters
    ----------
    vehicle : Vehicle
        The nominal vehicle (what a user's model says).
    effects : Effects
        Hidden effects switched on in the physics.
    dt : float
        Integration step (s).
    position : ndarray, shape (3,), optional
        Initial NED position (m); default 5 m deep.
    quaternion : ndarray, shape (4,), optional
        Initial attitude [w, x, y, z] (FRD → NED); default level, heading north.
    record : bool
        Keep the ground truth of every step for :meth:`trajectory`.
    """

    BLOCK = 4096  # steps kept raw before they become log rows (bounds the memory)

    def __init__(self, vehicle: Vehicle, effects: Effects | None = None, dt: float = 0.02,
                 position: FloatArray | None = None, quaternion: FloatArray | None = None,
                 record: bool = True) -> None:
        if not np.isfinite(dt) or dt <= 0:
            raise ConfigError("dt", f"must be > 0, got {dt}")
        self.nominal = vehicle
        self.effects = effects if effects is not None else Effects()
        self.truth = true_vehicle(vehicle, self.effects)
        self.dt = float(dt)
        body = self.truth.body
        self._M_RB = body.M_RB
        self._body = body
        self._M_A = body.added_mass
        self._M_A_dot = body.added_mass if body.added_mass_terms.inertial else None
        self._C_A_all = body.added_mass_terms.all
        self._M_inv = np.linalg.inv(body.M_inertial)
        self._W, self._B = body.weight, body.buoyancy
        self._r_g, self._r_b = body.r_g, body.r_b
        self._model: DampingModel = self.truth.damping
        self._theta = self.truth.theta
        self._theta_changed = self._theta.copy()
        if self._model.term("quadratic") is not None:
            quad = self._model.slice("quadratic")
            self._theta_changed[quad] *= self.effects.damping_change_factor
        self._r_g_l, self._r_b_l = body.r_g.tolist(), body.r_b.tolist()
        self._gain = (self._model.static_gain(self._theta), self._model.memory_gain(self._theta))
        self._gain_changed = (self._model.static_gain(self._theta_changed),
                              self._model.memory_gain(self._theta_changed))
        self._mem_rates = self._model.memory_rates
        self._mem_dofs = self._model.memory_dofs
        self._has_current = bool(np.any(self.effects.current) or self.effects.current_variation)
        self._thr = vehicle.need_thrusters("simulating the vehicle")
        self._thrust_gain = self._thr.gain * (1.0 + self.effects.thrust_gain_error)
        self._deadzone = max(self._thr.deadzone, self.effects.thruster_deadzone)
        tm = self._thr.time_constant
        self._inv_tm = 1.0 / tm if tm > 0 else 0.0
        self._alloc = self._thr.allocation
        self._n_mem = len(self._model.memory_rates)
        self._n_thr = self._thr.count
        self._delay_steps = round(float(self.effects.delay) / self.dt)
        self._cmd_queue: deque[FloatArray] = deque(
            [np.zeros(self._n_thr)] * self._delay_steps)
        self.t = 0.0
        p0 = np.array([0.0, 0.0, 5.0]) if position is None else np.asarray(position, float)
        q0 = np.array([1.0, 0.0, 0.0, 0.0]) if quaternion is None else np.asarray(quaternion,
                                                                                   float)
        # state x = [p (3), q (4), ν (6), z (n_mem), n_physical (n_thr)]
        self.x = np.concatenate([p0, q0 / np.linalg.norm(q0), np.zeros(6),
                                 np.zeros(self._n_mem), np.zeros(self._n_thr)])
        self.rotor = np.zeros(self._n_thr)  # what the vehicle logs (undelayed)
        self._record = record
        self._half_dt = self.dt / 2
        self._decay = np.exp(-self.dt / tm) if tm > 0 else None
        # blocks of log rows, and the raw values of the steps since the last block
        self._log: list[FloatArray] = []
        self._steps: list[tuple[float | FloatArray, ...]] = []

    # --- state access ------------------------------------------------------------------

    @property
    def position(self) -> FloatArray:
        """NED position (m), shape (3,)."""
        return self.x[0:3]

    @property
    def quaternion(self) -> FloatArray:
        """Attitude [w, x, y, z], FRD → NED, shape (4,)."""
        return self.x[3:7]

    @property
    def nu(self) -> FloatArray:
        """Body velocity over ground (FRD), shape (6,)."""
        return self.x[7:13]

    def current_ned(self, t: float) -> FloatArray:
        """Water current in NED at time t (m/s), shape (3,)."""
        return self.effects.current_at(t)

    def _current_rate(self, t: float) -> FloatArray:
        e = self.effects
        if not e.current_variation:
            return np.zeros(3)
        w = 2 * np.pi / e.current_period
        return e.current_variation * w * np.array([np.cos(w * t), -np.sin(w * t), 0.0])

    # --- dynamics ----------------------------------------------------------------------

    def _rhs(self, t: float, x: FloatArray, n_cmd: list[float]) -> tuple[FloatArray, FloatArray]:
        """ẋ at (t, x) and the thruster wrench τ (FRD), both ndarrays.

        The element-wise arithmetic runs on Python floats (numpy's per-call overhead would
        dominate on 3- and 6-vectors); the matrix products stay numpy's, so every number is
        the same as with whole-array numpy arithmetic.
        """
        nm = self._n_mem
        xl = x.tolist()
        w, qx, qy, qz = xl[3:7]
        s = 1.0 / (w * w + qx * qx + qy * qy + qz * qz) ** 0.5
        w, qx, qy, qz = w * s, qx * s, qy * s, qz * s
        R = [[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - w * qz), 2 * (qx * qz + w * qy)],
             [2 * (qx * qy + w * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - w * qx)],
             [2 * (qx * qz - w * qy), 2 * (qy * qz + w * qx), 1 - 2 * (qx * qx + qy * qy)]]
        nu = x[7:13]
        v, om = xl[7:10], xl[10:13]
        nu_r, nu_c_dot = (self._relative(t, R, nu, om) if self._has_current
                          else (nu, None))
        # thrust of the physical rotors (with the hidden gain error and dead-zone)
        n = xl[13 + nm:]
        gain, dz = self._thrust_gain, self._deadzone
        tau = self._alloc @ np.array([0.0 if abs(n_) < dz else gain * n_ * abs(n_)
                                      for n_ in n])
        cor = self._coriolis(nu, v, om, nu_r)
        d = self._damping(t, x, nu_r, v + om if nu_r is nu else nu_r.tolist())
        # g(η) = −[f_g + f_b ; r_g × f_g + r_b × f_b] with f = (W, −B) · Rᵀ e_z
        down = R[2]
        fg, fb = [self._W * d_ for d_ in down], [-self._B * d_ for d_ in down]
        mg, mb = _cross(self._r_g_l, fg), _cross(self._r_b_l, fb)
        g = [fg[0] + fb[0], fg[1] + fb[1], fg[2] + fb[2],
             mg[0] + mb[0], mg[1] + mb[1], mg[2] + mb[2]]
        # (M_RB + M_A) ν̇ = τ − C_RB ν − C_A ν_r − D ν_r − g + M_A ν̇_c   (g enters as −g(η));
        # without the inertial added-mass effect M_RB ν̇ = τ − C_RB ν − C_A ν_r − D ν_r − g
        rhs = np.array([t_ - c_ - d_ + g_ for t_, c_, d_, g_ in
                        zip(tau.tolist(), cor, d, g, strict=True)])
        if nu_c_dot is not None and self._M_A_dot is not None:
            rhs += self._M_A_dot @ nu_c_dot
        nu_dot = (self._M_inv @ rhs).tolist()
        # kinematics: ṗ = R v, q̇ = ½ q ⊗ (0, ω)
        p_dot = [R[i][0] * v[0] + R[i][1] * v[1] + R[i][2] * v[2] for i in range(3)]
        q_dot = [0.5 * (-qx * om[0] - qy * om[1] - qz * om[2]),
                 0.5 * (w * om[0] + qy * om[2] - qz * om[1]),
                 0.5 * (w * om[1] + qz * om[0] - qx * om[2]),
                 0.5 * (w * om[2] + qx * om[1] - qy * om[0])]
        # memory ż = −λ z + ν_r[dof]; motor lag ṅ = (n_cmd − n)/T_m
        z_dot = ((-self._mem_rates * x[13:13 + nm] + nu_r[self._mem_dofs]).tolist() if nm
                 else [])
        inv_tm = self._inv_tm
        n_dot = [(c - n_) * inv_tm for c, n_ in zip(n_cmd, n, strict=True)]
        return np.array(p_dot + q_dot + nu_dot + z_dot + n_dot), tau

    def _relative(self, t: float, R: list[list[float]], nu: FloatArray, om: list[float]
                  ) -> tuple[FloatArray, FloatArray]:
        """ν_r = ν − ν_c and ν̇_c = −ω × v_c + Rᵀ v̇_c (FRD), shape (6,) each, with the
        current's angular part zero."""
        c, c_dot = self.current_ned(t).tolist(), self._current_rate(t).tolist()
        vc = [R[0][i] * c[0] + R[1][i] * c[1] + R[2][i] * c[2] for i in range(3)]
        vc_dot = [R[0][i] * c_dot[0] + R[1][i] * c_dot[1] + R[2][i] * c_dot[2]
                  for i in range(3)]
        wxv = _cross(om, vc)
        return (nu - np.array([*vc, 0.0, 0.0, 0.0]),
                np.array([vc_dot[i] - wxv[i] for i in range(3)] + [0.0, 0.0, 0.0]))

    def _coriolis(self, nu: FloatArray, v: list[float], om: list[float], nu_r: FloatArray
                  ) -> list[float]:
        """C_RB(ν)ν + C_A(ν_r)ν_r (FRD, N and N·m), with C(ν)ν = [ν2 × a1, ν1 × a1 + ν2 × a2],
        a = M ν."""
        cor = _coriolis_force(v, om, (self._M_RB @ nu).tolist())
        if not self._C_A_all:
            # the added-mass switches of the vehicle: only the acting part of C_A(ν_r)ν_r
            return (np.array(cor) + self._body.added_coriolis_force(nu_r)).tolist()
        vr, omr = (v, om) if nu_r is nu else (nu_r[:3].tolist(), nu_r[3:].tolist())
        added = _coriolis_force(vr, omr, (self._M_A @ nu_r).tolist())
        return [c + a_ for c, a_ in zip(cor, added, strict=True)]

    def _damping(self, t: float, x: FloatArray, nu_r: FloatArray, nu_r_list: list[float]
                 ) -> list[float]:
        """D(ν_r)ν_r = (α(ν_r) K) ν_r plus the memory force Σ c_m z_m (FRD, N and N·m);
        ``nu_r_list`` is ν_r on Python floats."""
        e = self.effects
        K, c_mem = (self._gain_changed if 0 <= e.damping_change_time <= t else self._gain)
        d = (self._model.alpha_one(nu_r_list) @ K).reshape(6, 6) @ nu_r
        nm = self._n_mem
        if nm:
            np.add.at(d, self._mem_dofs, c_mem * x[13:13 + nm])
        return list(d.tolist())

    def step(self, rotor_command: FloatArray) -> None:
        """Advance one step ``dt`` with the rotor speed command held (rev/s).

        Parameters
        ----------
        rotor_command : ndarray, shape (n_thrusters,)
        """
        n_max = self._thr.n_max
        # np.clip, on Python floats
        cmd_l = [min(max(c, -n_max), n_max) for c in np.asarray(rotor_command, float).tolist()]
        cmd = np.array(cmd_l)
        if self._delay_steps:
            self._cmd_queue.append(cmd)
            phys_cmd = self._cmd_queue.popleft()
            phys_l = phys_cmd.tolist()
        else:
            phys_cmd, phys_l = cmd, cmd_l
        if self._decay is None:
            # no motor lag: the rotors turn at the command during this whole step, and the
            # logged speed (undelayed) already shows it in this step's record
            self.x[13 + self._n_mem:] = phys_cmd
            self.rotor = cmd
        h, h2, t, x = self.dt, self._half_dt, self.t, self.x
        k1, tau1 = self._rhs(t, x, phys_l)
        k2, tau2 = self._rhs(t + h2, x + h2 * k1, phys_l)
        k3, tau3 = self._rhs(t + h2, x + h2 * k2, phys_l)
        k4, tau4 = self._rhs(t + h, x + h * k3, phys_l)
        # RK4: x_{k+1} = x_k + h/6 (k1 + 2 k2 + 2 k3 + k4); the same weights give the mean τ
        # that the step applied (:meth:`_rows`)
        x_new = x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        quat = x_new[3:7]
        quat /= math.sqrt(quat.dot(quat))  # np.linalg.norm's arithmetic
        self.x = x_new
        n0 = self.rotor
        if self._decay is not None:
            # the logged rotor follows the undelayed command exactly: n(s) = c + (n₀ − c) e^{−s/T}
            self.rotor = lag_toward(n0, cmd, self._decay)
        if self._record:
            self._steps.append((t, x, k1, tau1, tau2, tau3, tau4, n0, cmd))
            if len(self._steps) >= self.BLOCK:
                self._log.append(self._rows())
        self.t = t + h

    def _rows(self) -> FloatArray:
        """The pending steps as log rows, whole arrays at once (the same numbers as step by
        step): [t, p, q, ν, ν̇, mean τ, mean rotor speed, mean thrust, current, memory]."""
        nm = self._n_mem
        t, x, k1, tau1, tau2, tau3, tau4, n0, cmd = (np.array(c) for c in
                                                    zip(*self._steps, strict=True))
        self._steps = []
        tau_mean = (tau1 + 2 * tau2 + 2 * tau3 + tau4) / 6.0
        n_mean, thrust_mean = self._thr.step_means(n0, cmd, self.dt)
        return np.column_stack([t, x[:, :13], k1[:, 7:13], tau_mean, n_mean, thrust_mean,
                                self.effects.current_series(t), x[:, 13:13 + nm]])

    def take_log(self, keep: int = 1) -> Trajectory:
        """The steps recorded so far as a Trajectory, then forget all but the last ``keep``.

        For streaming (the simulator node): the memory of a long run stays bounded, and the
        kept steps let the next chunk interpolate across the boundary.
        """
        traj = self.trajectory()
        self._log = [self._log[0][-keep:]] if keep > 0 and self._log else []
        return traj

    def wrench_to_command(self, tau: FloatArray) -> FloatArray:
        """Rotor speeds (rev/s) that produce τ with the nominal thrusters, saturated."""
        return self._thr.speed_for_thrust(self._thr.allocate(tau))

    def trajectory(self) -> Trajectory:
        """Ground truth of every recorded step."""
        nt, nm = self._n_thr, self._n_mem
        if self._steps:
            self._log.append(self._rows())
        self._log = [np.concatenate(self._log)] if self._log else []
        log = self._log[0] if self._log else np.zeros((0, 26 + 2 * nt + 3 + nm))
        cols = np.cumsum([1, 3, 4, 6, 6, 6, nt, nt, 3])
        t, pos, quat, nu, nu_dot, tau, rotor, thrust, cur, mem = np.split(log, cols, axis=1)
        return Trajectory(t=t[:, 0], position=pos, quaternion=quat, nu=nu, nu_dot=nu_dot,
                          tau=tau, rotor_speed=rotor, thrust=thrust,
                          current=cur, memory=mem, thruster_names=self._thr.names)


#: Plants the vehicle can fly in: our own equations (``native``) or MuJoCo's fluid model.
BACKENDS = ("native", "mujoco")


class Plant(Protocol):
    """What a simulator backend offers the controller loops (run, stream, track)."""

    t: float
    dt: float

    @property
    def position(self) -> FloatArray: ...

    @property
    def quaternion(self) -> FloatArray: ...

    @property
    def nu(self) -> FloatArray: ...

    def current_ned(self, t: float) -> FloatArray: ...

    def step(self, rotor_command: FloatArray) -> None: ...

    def wrench_to_command(self, tau: FloatArray) -> FloatArray: ...

    def take_log(self, keep: int = 1) -> Trajectory: ...

    def trajectory(self) -> Trajectory: ...


def make_plant(vehicle: Vehicle, effects: Effects | None = None, dt: float = 0.02,
               backend: str = "native", position: FloatArray | None = None,
               quaternion: FloatArray | None = None, record: bool = True) -> Plant:
    """A simulator of ``backend`` (:data:`BACKENDS`) for the vehicle.

    ``mujoco`` needs the vehicle's ``geometry:`` block and the ``mujoco`` package.
    """
    if backend == "native":
        return Simulator(vehicle, effects, dt=dt, position=position, quaternion=quaternion,
                         record=record)
    if backend == "mujoco":
        # imported here: MuJoCo loads a native library
        from dampest_ros.core.simulation.mujoco_backend import MujocoSimulator

        return MujocoSimulator(vehicle, effects, dt=dt, position=position,
                               quaternion=quaternion, record=record)
    raise ConfigError("backend", f"unknown backend {backend!r}; use one of {BACKENDS}")


def run(vehicle: Vehicle, excitation: Excitation | ProtocolStream, effects: Effects | None = None,
        dt: float = 0.02, backend: str = "native") -> Trajectory:
    """Fly ``excitation`` with the velocity PI controller and return the ground truth.

    Parameters
    ----------
    vehicle : Vehicle
        Nominal vehicle (the controller and the logs use it).
    excitation : Excitation or ProtocolStream
        Sampled or block-wise protocol; its grid sets the control rate (a multiple of
        ``dt``).
    effects : Effects, optional
        Hidden effects in the physics.
    dt : float
        Integration step (s).
    backend : {'native', 'mujoco'}
        The plant (:func:`make_plant`).

    Returns
    -------
    Trajectory
    """
    sim = make_plant(vehicle, effects, dt=dt, backend=backend,
                     position=np.array([0.0, 0.0, excitation.initial_depth]))
    dt_c = excitation.dt
    sub = max(1, round(dt_c / dt))
    ctrl = VelocityPI.for_vehicle(vehicle, excitation.bandwidth)
    for k in range(excitation.ticks):
        roll, pitch = roll_pitch(sim.quaternion)
        cmd = excitation.command(k, sim.nu, roll, pitch, float(sim.position[2]))
        tau = ctrl(cmd, sim.nu, dt_c) + excitation.feedforward(k)
        rotor = sim.wrench_to_command(tau)
        for _ in range(sub):
            sim.step(rotor)
    return sim.trajectory()


def track(sim: Plant, controller: VelocityPI, nu_ref: FloatArray, dt: float) -> FloatArray:
    """Fly a velocity reference on the simulator with a controller, closed loop.

    Parameters
    ----------
    sim : Plant
        Flown from its current state; advanced by ``len(nu_ref) * dt`` seconds.
    controller : VelocityPI
    nu_ref : ndarray, shape (N, 6)
        Reference ν_ref (FRD, m/s and rad/s) at each control step.
    dt : float
        Control period (s), a multiple of ``sim.dt``.

    Returns
    -------
    ndarray, shape (N, 6)
        ν (FRD, m/s and rad/s) at each control step, measured before the command.
    """
    nu_ref = np.asarray(nu_ref, dtype=float)
    nu = np.empty_like(nu_ref)
    sub = max(1, round(dt / sim.dt))
    for k, ref in enumerate(nu_ref):  # closed loop: each command needs the last state
        nu[k] = sim.nu
        rotor = sim.wrench_to_command(controller(ref, nu[k], dt))
        for _ in range(sub):
            sim.step(rotor)
    return nu


def simulate(vehicle: Vehicle, protocol: str = "B", duration: float = 600.0, seed: int = 1,
             effects: Effects | None = None, sensors: SensorConfig | None = None,
             dt: float = 0.02, backend: str = "native", amplitude: float = 1.0) -> Recording:
    """Fly a protocol and log what the vehicle's sensors measure: ``dampest simulate``
    without the bag (write the result with :func:`dampest_ros.io.bag.write_bag`).

    Parameters
    ----------
    vehicle : Vehicle
    protocol : {'A', 'B', 'C', 'fourier', 'optimal'}
        Excitation (:func:`~dampest_ros.core.simulation.excitation.protocol`).
    duration : float
        Seconds flown.
    seed : int
        Seed of the excitation and of the sensor noise.
    effects : Effects, optional
        Hidden effects in the physics; their sensor biases bias the sensors.
    sensors : SensorConfig, optional
        Rates and noise levels.
    dt : float
        Integration step (s).
    backend : {'native', 'mujoco'}
    amplitude : float
        Scale of the protocol's amplitudes.

    Returns
    -------
    Recording
        Topic → series in ROS frames, as :func:`dampest_ros.io.bag.read_bag` returns a bag.
    """
    fx = effects or Effects()
    excitation = make_protocol(protocol, vehicle, duration, seed=seed, amplitude=amplitude)
    traj = run(vehicle, excitation, fx, dt=dt, backend=backend)
    bias = SensorBias(fx.gyro_bias, fx.accel_bias, fx.dvl_bias)
    return measure(traj, vehicle.body.rho, vehicle.body.gravity, sensors or SensorConfig(),
                   bias, seed=seed, mounting=vehicle.mounting)
