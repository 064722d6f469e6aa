"""Streaming sensor models: the messages of :func:`dampest_ros.core.simulation.sensors.measure`,
produced incrementally as the simulator advances (for the simulator node, where a controller closes
the loop and the trajectory is not known in advance).

Same physics, frames, interpolation (cubic Hermite for ν and position, nlerp for attitude),
noise levels and message layout as :mod:`dampest_ros.core.simulation.sensors` (whose helpers it
uses); the sample grids are global (t0 + k / rate), so chunking does not change the stamps. The
noise streams are spawned from the seed in the same order but drawn sample by sample, so a
stream is statistically, not bitwise, the same as ``measure`` on the whole trajectory.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.frames import (
    body_vec,
    continuous,
    quat_frd_ned_to_flu_enu,
    quat_mul,
    quat_to_matrix,
    roll_pitch,
    small_rotation,
    world_vec,
    wxyz_to_xyzw,
)
from dampest_ros.core.physics.mounting import Mounting
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.measurements import (
    ImuSeries,
    JointSeries,
    OdometrySeries,
    PressureSeries,
    Recording,
    TwistSeries,
)
from dampest_ros.core.simulation.control import VelocityPI
from dampest_ros.core.simulation.effects import Effects
from dampest_ros.core.simulation.excitation import protocol as make_protocol
from dampest_ros.core.simulation.interpolate import hermite, locate, nlerp
from dampest_ros.core.simulation.sensors import (
    FRAME_IDS,
    NOISE_STREAMS,
    UNUSED_VARIANCE,
    SensorBias,
    SensorConfig,
    diag3,
    dvl_reading,
    hydro_series,
    imu_reading,
    sensor_depth,
)
from dampest_ros.core.simulation.simulate import make_plant
from dampest_ros.core.simulation.trajectory import Trajectory

FloatArray = NDArray[np.float64]


class SensorStream:
    """Incremental sensor messages from consecutive trajectory chunks.

    Parameters
    ----------
    rho, gravity : float
        Water density (kg/m³) and g (m/s²).
    config : SensorConfig
    bias : SensorBias
    seed : int
    mounting : Mounting, optional
        Where the IMU, DVL and pressure sensor sit (as
        :func:`~dampest_ros.core.simulation.sensors.measure` models them; default: at the origin,
        aligned).

    Notes
    -----
    Feed :meth:`add` with chunks that overlap by one step (the last step of the previous
    chunk first), as :meth:`dampest_ros.core.simulation.simulate.Simulator.take_log` with ``keep=1``
    gives them. Each call returns the messages whose stamps fall after those already
    returned and up to the chunk's end (thruster windows up to the end of its last step).
    """

    HISTORY = 256  # integration steps of thruster history kept beyond the current chunk

    def __init__(self, rho: float, gravity: float, config: SensorConfig | None = None,
                 bias: SensorBias | None = None, seed: int = 0,
                 mounting: Mounting | None = None) -> None:
        self.rho, self.gravity = float(rho), float(gravity)
        self.mount = mounting or Mounting()
        self.cfg = config or SensorConfig()
        self.bias = bias or SensorBias()
        children = np.random.default_rng(seed).spawn(len(NOISE_STREAMS))
        self.rng = dict(zip(NOISE_STREAMS, children, strict=True))
        self.t0 = math.nan
        # last stamp index emitted per sensor
        self._next: dict[str, int] = {}
        self._gyro_walk = np.zeros(3)
        self._accel_walk = np.zeros(3)
        # DVL bottom lock: alternating locked / lost phases
        self._dvl_locked = True
        self._dvl_switch = math.inf
        # running integral of the thruster step means at step edges
        self._edges: deque[float] = deque(maxlen=self.HISTORY)
        self._int_speed: deque[FloatArray] = deque(maxlen=self.HISTORY)
        self._int_thrust: deque[FloatArray] = deque(maxlen=self.HISTORY)
        self._last_step_t = -math.inf
        self._names: tuple[str, ...] = ()

    def _stamps(self, name: str, rate: float, a: float, b: float) -> FloatArray:
        """Grid stamps t0 + k/rate not yet emitted and ≤ b (a: the first time allowed)."""
        k0 = self._next.get(name, math.ceil((a - self.t0) * rate - 1e-9))
        k1 = math.floor((b - self.t0) * rate + 1e-6)
        if k1 < k0:
            return np.zeros(0)
        self._next[name] = k1 + 1
        return self.t0 + np.arange(k0, k1 + 1, dtype=float) / rate

    def add(self, traj: Trajectory) -> Recording:
        """Messages for a chunk of trajectory (≥ 2 steps, the first one already seen unless
        this is the first chunk). Returns topic → series (possibly empty)."""
        t = np.asarray(traj.t, dtype=float)
        if math.isnan(self.t0):
            self.t0 = float(t[0])
            if self.cfg.dvl_dropout_rate > 0:
                self._dvl_switch = self.t0 + self.rng["dvl_dropout"].exponential(
                    1.0 / self.cfg.dvl_dropout_rate)
            self._edges.append(float(t[0]))
            n = traj.rotor_speed.shape[1]
            self._int_speed.append(np.zeros(n))
            self._int_thrust.append(np.zeros(n))
            self._names = tuple(traj.thruster_names)
        cfg = self.cfg
        q = continuous(np.asarray(traj.quaternion, dtype=float))
        nu = np.asarray(traj.nu, dtype=float)
        nu_dot = np.asarray(traj.nu_dot, dtype=float)
        pos = np.asarray(traj.position, dtype=float)
        p_dot = np.einsum("nij,nj->ni", quat_to_matrix(q), nu[:, :3])
        a, b = float(t[0]), float(t[-1])
        out: Recording = {}
        # --- IMU
        st = self._stamps("imu", cfg.imu_rate, a, b)
        k = locate(t, st)
        v_nu, v_nud = hermite(k, nu, nu_dot)
        qs = nlerp(k, q)
        n = len(st)
        g_body = self.gravity * quat_to_matrix(qs)[:, 2, :]
        sf = v_nud[:, :3] + np.cross(v_nu[:, 3:], v_nu[:, :3]) - g_body
        w_s, sf, qs = imu_reading(self.mount.imu, v_nu[:, 3:], v_nud[:, 3:], sf, qs)
        gyro_walk = self._walk("gyro_walk", n, cfg.gyro_bias_walk, cfg.imu_rate, "_gyro_walk")
        accel_walk = self._walk("accel_walk", n, cfg.accel_bias_walk, cfg.imu_rate,
                                "_accel_walk")
        gyro = (w_s + np.asarray(self.bias.gyro) + gyro_walk
                + self.rng["gyro_noise"].standard_normal((n, 3)) * cfg.gyro_noise)
        accel = (sf + np.asarray(self.bias.accel) + accel_walk
                 + self.rng["accel_noise"].standard_normal((n, 3)) * cfg.accel_noise)
        dtheta = self.rng["orientation"].standard_normal((n, 3)) * cfg.orientation_noise
        q_meas = quat_mul(quat_frd_ned_to_flu_enu(qs), small_rotation(dtheta))
        q_meas *= np.where(q_meas[:, :1] < 0.0, -1.0, 1.0)
        out["imu/data"] = ImuSeries(
            stamp=st, frame_id=self.mount.imu.frame_id, orientation=wxyz_to_xyzw(q_meas),
            angular_velocity=body_vec(gyro), linear_acceleration=body_vec(accel),
            orientation_covariance=diag3(cfg.orientation_noise**2),
            angular_velocity_covariance=diag3(cfg.gyro_noise**2),
            linear_acceleration_covariance=diag3(cfg.accel_noise**2))
        # --- DVL
        st = self._stamps("dvl", cfg.dvl_rate, a, b)
        v_nu, _ = hermite(locate(t, st), nu, nu_dot)
        v = (dvl_reading(self.mount.dvl, v_nu) + np.asarray(self.bias.dvl)
             + self.rng["dvl_noise"].standard_normal((len(st), 3)) * cfg.dvl_noise)
        keep = np.array([self._locked(s) for s in st], dtype=bool)
        cov = np.diag([cfg.dvl_noise**2] * 3 + [UNUSED_VARIANCE] * 3).ravel()
        out["dvl/twist"] = TwistSeries(stamp=st[keep], frame_id=self.mount.dvl.frame_id,
                                       linear=body_vec(v[keep]),
                                       angular=np.zeros((int(keep.sum()), 3)), covariance=cov)
        # --- pressure
        st = self._stamps("pressure", cfg.pressure_rate, a, b)
        k = locate(t, st)
        p_i, _ = hermite(k, pos, p_dot)
        z = sensor_depth(self.mount.pressure, p_i[:, 2], nlerp(k, q))
        pressure = (cfg.atmospheric_pressure + self.rho * self.gravity * z
                    + self.rng["pressure"].standard_normal(len(st)) * cfg.pressure_noise)
        out["pressure"] = PressureSeries(stamp=st, frame_id=self.mount.pressure.frame_id,
                                         fluid_pressure=pressure,
                                         variance=cfg.pressure_noise**2)
        # --- thrusters: window means over [s − w, s] of the step means
        self._integrate_steps(traj)
        w = 1.0 / cfg.thruster_rate
        st = self._stamps("thrusters", cfg.thruster_rate, self.t0 + w, self._edges[-1])
        edges = np.array(self._edges)
        speed = self._window_mean(st, w, edges, np.array(self._int_speed))
        thrust = self._window_mean(st, w, edges, np.array(self._int_thrust))
        out["thrusters/state"] = JointSeries(
            stamp=st, frame_id=FRAME_IDS["thrusters/state"], names=self._names,
            velocity=2.0 * np.pi * speed
            + self.rng["rpm"].standard_normal(speed.shape) * cfg.rpm_noise,
            effort=thrust)
        # --- truth
        st = self._stamps("truth", cfg.truth_rate, a, b)
        k = locate(t, st)
        p_i, _ = hermite(k, pos, p_dot)
        v_nu, _ = hermite(k, nu, nu_dot)
        out["truth/odom"] = OdometrySeries(
            stamp=st, frame_id=FRAME_IDS["truth/odom"], child_frame_id="base_link",
            position=world_vec(p_i),
            orientation=wxyz_to_xyzw(quat_frd_ned_to_flu_enu(nlerp(k, q))),
            linear=body_vec(v_nu[:, :3]), angular=body_vec(v_nu[:, 3:]))
        if traj.hydro is not None:
            # the plant's own fluid wrench (MuJoCo)
            out["truth/hydro_wrench"] = hydro_series(st, t, traj.hydro)
        return out

    def _walk(self, stream: str, n: int, sigma: float, rate: float, attr: str) -> FloatArray:
        """Random-walk bias continued from its last value: b_k = b_{k−1} + σ √Δt ξ_k."""
        steps = self.rng[stream].standard_normal((n, 3)) * (sigma * math.sqrt(1.0 / rate))
        walk = getattr(self, attr) + np.cumsum(steps, axis=0)
        if n:
            setattr(self, attr, walk[-1].copy())
        return np.asarray(walk, dtype=float)

    def _locked(self, s: float) -> bool:
        """Bottom lock at stamp s (advances the renewal process)."""
        cfg = self.cfg
        while s >= self._dvl_switch:
            self._dvl_locked = not self._dvl_locked
            mean = (1.0 / cfg.dvl_dropout_rate) if self._dvl_locked else cfg.dvl_dropout_mean
            self._dvl_switch += self.rng["dvl_dropout"].exponential(mean) if mean > 0 else 0.0
        return self._dvl_locked

    def _integrate_steps(self, traj: Trajectory) -> None:
        t = np.asarray(traj.t, dtype=float)
        dt = float(t[1] - t[0]) if len(t) > 1 else 0.0
        # the history must hold the whole chunk plus the window before it: a long chunk
        # (one advance over many steps) grows it instead of dropping the edges still needed
        needed = len(t) + self.HISTORY
        if needed > (self._edges.maxlen or 0):
            self._edges = deque(self._edges, maxlen=needed)
            self._int_speed = deque(self._int_speed, maxlen=needed)
            self._int_thrust = deque(self._int_thrust, maxlen=needed)
        for k in range(len(t)):
            if t[k] <= self._last_step_t + 1e-12:
                continue  # the overlap step, already integrated
            self._last_step_t = float(t[k])
            edge = float(t[k]) + dt
            self._int_speed.append(self._int_speed[-1] + np.asarray(traj.rotor_speed[k]) * dt)
            self._int_thrust.append(self._int_thrust[-1] + np.asarray(traj.thrust[k]) * dt)
            self._edges.append(edge)

    @staticmethod
    def _window_mean(st: FloatArray, w: float, edges: FloatArray,
                     integral: FloatArray) -> FloatArray:
        if integral.shape[1] == 0 or len(st) == 0:
            return np.zeros((len(st), integral.shape[1]))
        hi = np.stack([np.interp(st, edges, c) for c in integral.T], axis=1)
        lo = np.stack([np.interp(st - w, edges, c) for c in integral.T], axis=1)
        return np.asarray((hi - lo) / w, dtype=float)


class LiveSimulation:
    """The simulator flown step by step with its sensors streamed: the core of the sim node.

    The excitation protocol is tracked by the velocity PI controller of
    :func:`dampest_ros.core.simulation.simulate.run`, unless an external wrench command is in force
    (:meth:`command`), which then replaces the controller's output.

    Parameters
    ----------
    vehicle : Vehicle
    protocol : str
        One of :data:`dampest_ros.core.simulation.excitation.LIVE_PROTOCOLS` (generated block by
        block: memory does not grow with the duration).
    duration : float
        Length of the protocol (s); :attr:`done` after it.
    seed : int
    effects : Effects, optional
    sensors : SensorConfig, optional
    dt : float
        Integration step (s).
    backend : {'native', 'mujoco'}
        The plant (:func:`dampest_ros.core.simulation.simulate.make_plant`).
    """

    def __init__(self, vehicle: Vehicle, protocol: str = "B", duration: float = 300.0,
                 seed: int = 1, effects: Effects | None = None,
                 sensors: SensorConfig | None = None, dt: float = 0.02,
                 backend: str = "native") -> None:
        self.vehicle = vehicle
        self.effects = effects or Effects()
        self.excitation = make_protocol(protocol, vehicle, duration, seed=seed)
        ex = self.excitation
        self.sim = make_plant(vehicle, self.effects, dt=dt, backend=backend,
                              position=np.array([0.0, 0.0, ex.initial_depth]))
        self.dt_control = ex.dt
        self.sub = max(1, round(self.dt_control / dt))
        self.controller = VelocityPI.for_vehicle(vehicle, ex.bandwidth)
        bias = SensorBias(self.effects.gyro_bias, self.effects.accel_bias, self.effects.dvl_bias)
        self.stream = SensorStream(vehicle.body.rho, vehicle.body.gravity, sensors, bias, seed,
                                   vehicle.mounting)
        self.k = 0
        self._cmd: FloatArray | None = None
        self._cmd_until = -math.inf
        self.external_steps = 0
        self._logged = 0

    @property
    def t(self) -> float:
        """Simulation time (s)."""
        return float(self.sim.t)

    @property
    def done(self) -> bool:
        """True when the protocol has been flown to its end."""
        return self.k >= self.excitation.ticks

    def command(self, tau: FloatArray, hold: float) -> None:
        """External wrench τ (FRD, N and N·m) in force for ``hold`` seconds of sim time."""
        self._cmd = np.asarray(tau, dtype=float)
        self._cmd_until = self.t + hold

    def advance(self, until: float) -> Recording:
        """Fly control steps while the time is below ``until``; returns the new messages."""
        ex, sim = self.excitation, self.sim
        while not self.done and self.t + 1e-9 < until:
            if self._cmd is not None and self.t < self._cmd_until:
                tau = self._cmd
                self.external_steps += 1
            else:
                roll, pitch = roll_pitch(sim.quaternion)
                ref = ex.command(self.k, sim.nu, roll, pitch,
                                 float(sim.position[2]))
                tau = self.controller(ref, sim.nu, self.dt_control) + ex.feedforward(self.k)
            rotor = sim.wrench_to_command(tau)
            for _ in range(self.sub):
                sim.step(rotor)
            self._logged += self.sub
            self.k += 1
        if self._logged < 2:
            return {}  # the sensors interpolate between two logged steps
        self._logged = 1
        return self.stream.add(sim.take_log(keep=1))
