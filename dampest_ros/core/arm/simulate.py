"""MuJoCo data of an arm tracking a trajectory: computed-torque control on the nominal
model, exact truth, and what an arm's sensors report (quantised encoders, a noisy torque
sensor with an offset)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.arm.ffs import FourierTrajectory
from dampest_ros.core.arm.mjinverse import body_parameters, set_body_parameters
from dampest_ros.core.arm.model import ArmModel, JointDynamics

FloatArray = NDArray[np.float64]

#: rad: a joint this far off its trajectory (or a non-finite state) means the run diverged.
DIVERGED = np.pi


@dataclass(frozen=True)
class ArmSensors:
    """What the arm's sensors add.

    Attributes
    ----------
    encoder_counts : int
        Encoder counts per revolution; positions are rounded to 2π / counts (0: exact).
    torque_sigma : ndarray, shape (n,) or float
        Standard deviation of white torque-sensor noise per joint (N m).
    torque_offset : ndarray, shape (n,) or float
        Constant torque-sensor offset per joint (N m).
    """

    encoder_counts: int = 0
    torque_sigma: FloatArray | float = 0.0
    torque_offset: FloatArray | float = 0.0


#: A UR5-class arm's sensors: 20-bit encoders, torque noise of a current-based estimate.
REALISTIC = ArmSensors(encoder_counts=2 ** 20,
                       torque_sigma=np.array([0.4, 0.4, 0.3, 0.1, 0.1, 0.1]),
                       torque_offset=np.array([0.3, -0.4, 0.2, 0.05, -0.05, 0.03]))


def scaled_sensors(arm: ArmModel) -> ArmSensors:
    """:data:`REALISTIC` carried to any arm by its effort limits: 20-bit encoders, torque
    noise 0.27 % and offsets of alternating sign 0.2 % of each joint's effort limit (the
    UR5's shoulder: 0.4 N m of 150)."""
    e = np.asarray(arm.effort_limit, dtype=float)
    sign = np.where(np.arange(arm.n) % 2 == 0, 1.0, -1.0)
    return ArmSensors(2 ** 20, 0.0027 * e, 0.002 * e * sign)


@dataclass
class ArmRun:
    """A simulated run: truth and measurements at the sample instants.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Time (s).
    q, qd, qdd : ndarray, shape (N, n)
        True joint positions, velocities, accelerations (rad, rad/s, rad/s²).
    tau : ndarray, shape (N, n)
        Applied joint torque (N m), constant over the step that starts at t.
    position, velocity, effort : ndarray, shape (N, n)
        Measured: quantised position, its backward difference, and the torque sensor's
        reading τ + offset + noise.
    """

    t: FloatArray
    q: FloatArray
    qd: FloatArray
    qdd: FloatArray
    tau: FloatArray
    position: FloatArray
    velocity: FloatArray
    effort: FloatArray


def simulate_arm(mjcf_xml: str, arm: ArmModel, nominal: JointDynamics,
                 trajectory: FourierTrajectory, duration: float, rate: float = 1000.0,
                 sensors: ArmSensors | None = None, seed: int = 0, bandwidth: float = 20.0,
                 payload: tuple[float, float] | None = None
                 ) -> ArmRun:
    """Track an FFS trajectory in MuJoCo with computed-torque control and sample it.

    The controller commands τ = RNEA_nominal(q, q̇, a) + Ia a + Fv q̇ + Fc sign(q̇_d) with
    a = q̈_d + K_p (q_d − q) + K_d (q̇_d − q̇) (Pinocchio on the URDF's nominal inertias and
    the nominal joint dynamics), held over each MuJoCo step.

    Parameters
    ----------
    mjcf_xml : str
        The MuJoCo model (its joints named as ``arm.names``, a motor per joint).
    arm : ArmModel
        The nominal model the controller uses.
    nominal : JointDynamics
        The joint dynamics the controller compensates.
    trajectory : FourierTrajectory
        Desired motion; the arm starts on it (q(0), q̇(0)).
    duration : float
        Length (s).
    rate : float
        Sample rate (Hz); 1 / rate must be a whole number of MuJoCo steps.
    sensors : ArmSensors, optional
        Noise; none by default.
    seed : int
        Seed of the sensor noise.
    bandwidth : float
        Closed-loop natural frequency ω_n (rad/s): K_p = ω_n², K_d = 2 ω_n.
    payload : (float, float), optional
        (mass in kg, time in s): a point mass attached at the last link's origin at that
        time (a tool picked up mid-run); the mass finite and > 0, the time within the run.

    Returns
    -------
    ArmRun

    Raises
    ------
    ValueError
        If the sample period is not a whole number of MuJoCo steps, the payload is not a
        positive mass within the run, or the run diverges: a non-finite state, or a joint
        :data:`DIVERGED` rad off its trajectory (a trajectory or payload the controller
        cannot follow).
    """
    import mujoco
    import pinocchio as pin  # type: ignore[import-untyped]

    sensors = sensors or ArmSensors()
    model = mujoco.MjModel.from_xml_string(mjcf_xml)
    data = mujoco.MjData(model)
    dt = float(model.opt.timestep)
    every = round(1.0 / (rate * dt))
    if every < 1 or abs(every * dt * rate - 1.0) > 1e-9:
        raise ValueError(f"sample rate {rate} Hz is not a whole number of MuJoCo steps "
                         f"of {dt} s; use {1.0 / dt:g} Hz divided by an integer")
    if payload is not None:
        _check_payload(payload, duration)
    pm, pd = arm.pinocchio()
    steps = round(duration / dt)
    t_all = np.arange(steps, dtype=float) * dt
    q_des, qd_des, qdd_des = trajectory.evaluate(t_all)
    data.qpos[:] = q_des[0]
    data.qvel[:] = qd_des[0]
    kp, kd = bandwidth ** 2, 2.0 * bandwidth
    last = model.nbody - 1
    switch = -1 if payload is None else round(payload[1] / dt)
    n = arm.n
    keep = np.arange(0, steps, every)
    out = {k: np.empty((len(keep), n)) for k in ("q", "qd", "qdd", "tau")}
    row = 0
    for k in range(steps):
        if k == switch:
            # a point mass at the last link's frame origin adds to its mass only (its first
            # and second moments about that origin are zero)
            pi_last = body_parameters(model, last)
            pi_last[0] += payload[0]  # type: ignore[index]
            set_body_parameters(model, data, last, pi_last)
        q, v = data.qpos.copy(), data.qvel.copy()
        a_ref = qdd_des[k] + kp * (q_des[k] - q) + kd * (qd_des[k] - v)
        tau = (pin.rnea(pm, pd, q, v, a_ref) + nominal.armature * a_ref
               + nominal.damping * v + nominal.frictionloss * np.sign(qd_des[k]))
        data.ctrl[:] = tau
        mujoco.mj_step(model, data)
        if k % every == 0:
            _check_tracking(t_all[k], q, v, tau, q_des[k], arm.names)
            out["q"][row], out["qd"][row], out["tau"][row] = q, v, tau
            out["qdd"][row] = data.qacc  # the acceleration of this step's state and torque
            row += 1
    rng = np.random.default_rng(seed)
    step = 0.0 if sensors.encoder_counts <= 0 else 2.0 * np.pi / sensors.encoder_counts
    position = out["q"] if step == 0 else np.round(out["q"] / step) * step
    velocity = np.gradient(position, 1.0 / rate, axis=0)
    effort = (out["tau"] + np.asarray(sensors.torque_offset, dtype=float)
              + rng.normal(size=out["tau"].shape) * np.asarray(sensors.torque_sigma, float))
    return ArmRun(t=t_all[keep], q=out["q"], qd=out["qd"], qdd=out["qdd"], tau=out["tau"],
                  position=position, velocity=velocity, effort=effort)


def _check_payload(payload: tuple[float, float], duration: float) -> None:
    """ValueError unless the payload is a finite positive mass attached within the run."""
    mass, at = payload
    if not (np.isfinite(mass) and mass > 0):
        raise ValueError(f"payload mass must be finite and > 0 kg, got {mass:g}")
    if not 0.0 <= at < duration:
        raise ValueError(f"payload time {at:g} s is not within the {duration:g} s run; "
                         f"attach it between 0 and {duration:g} s")


def _check_tracking(t: float, q: FloatArray, v: FloatArray, tau: FloatArray,
                    q_des: FloatArray, names: tuple[str, ...]) -> None:
    """ValueError when the state at ``t`` is not finite or a joint is :data:`DIVERGED` rad
    off its trajectory."""
    state = np.concatenate([q, v, tau, q_des])
    if not np.all(np.isfinite(state)):
        raise ValueError(f"the simulation diverged at t = {t:.3f} s: the state or the "
                         "trajectory is not finite (check the trajectory file's numbers)")
    off = np.abs(q - q_des)
    j = int(np.argmax(off))
    if off[j] > DIVERGED:
        raise ValueError(f"the simulation diverged at t = {t:.3f} s: {names[j]} is "
                         f"{off[j]:.3g} rad off its trajectory (the controller cannot follow "
                         "it: a lighter payload or a slower trajectory)")
