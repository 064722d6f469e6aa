"""Excitation protocols: what the vehicle is asked to do while data are recorded.

A protocol is sampled once on the control grid (vectorised) into velocity references,
roll/pitch/depth references and an open-loop wrench; a velocity PI controller tracks them
so that the vehicle stays within its limits.

- ``A``: low-speed steps then slow sines, one degree of freedom at a time (linear regime).
- ``B``: ramped surge with PRBS on top, multi-level PRBS on sway and yaw rate, and smooth
  random roll, pitch and depth manoeuvres, so one run excites all six DOFs over their range.
- ``C``: multisine wrench 0.1–10 Hz on all six DOFs (frequency response, fluid memory), with
  a slow controller holding the mean.
- ``fourier``: finite-Fourier-series velocity trajectories (period 50 s, 5 harmonics).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from dampest_ros.core.rigid_body import ConfigError
from dampest_ros.core.vehicle import Vehicle

FloatArray = NDArray[np.float64]

PROTOCOLS = ("A", "B", "C", "fourier")


@dataclass
class Excitation:
    """A protocol sampled on the control grid.

    Attributes
    ----------
    name : str
    t : ndarray, shape (K,)
        Control instants (s).
    nu_ref : ndarray, shape (K, 6)
        Velocity feed-forward references (FRD; m/s, rad/s).
    attitude_ref : ndarray, shape (K, 2)
        Roll and pitch references (rad).
    depth_ref : ndarray, shape (K,)
        Depth reference (m).
    tau_ff : ndarray, shape (K, 6)
        Open-loop wrench added to the controller output (N, N·m).
    bandwidth : ndarray, shape (6,)
        Velocity-loop bandwidth per DOF (rad/s).
    """

    name: str
    t: FloatArray
    nu_ref: FloatArray
    attitude_ref: FloatArray
    depth_ref: FloatArray
    tau_ff: FloatArray
    bandwidth: FloatArray

    def command(self, k: int, nu: FloatArray, roll: float, pitch: float,
                depth: float) -> FloatArray:
        """Velocity command at tick k: reference plus attitude and depth correction."""
        cmd = self.nu_ref[k].copy()
        # outer loops: ν_cmd = ν_ref + k (x_ref − x) for depth, roll, pitch
        cmd[2] += 0.8 * (self.depth_ref[k] - depth)
        cmd[3] += 1.5 * (self.attitude_ref[k, 0] - roll)
        cmd[4] += 1.5 * (self.attitude_ref[k, 1] - pitch)
        return cmd


def speed_limits(vehicle: Vehicle, fraction: float = 0.5,
                 tau_measured: FloatArray | None = None) -> FloatArray:
    """Steady speed per DOF reached with ``fraction`` of the largest thrust, shape (6,).

    Solves D(ν)ν = fraction · τ_max along each axis by bisection on the nominal model.

    Parameters
    ----------
    vehicle : Vehicle
    fraction : float
    tau_measured : ndarray, shape (n, 6), optional
        Measured τ (N, N·m); gives τ_max for a vehicle without thrusters
        (:meth:`~dampest_ros.core.vehicle.Vehicle.wrench_scale`).

    Returns
    -------
    ndarray, shape (6,)
        m/s and rad/s.
    """
    tau = fraction * vehicle.wrench_scale(tau_measured)
    out = np.empty(6)
    for i in range(6):
        lo, hi = 0.0, 20.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            nu = np.zeros((1, 6))
            nu[0, i] = mid
            f = vehicle.damping.force(nu, vehicle.theta,
                                      np.zeros((1, len(vehicle.damping.memory_rates))))[0, i]
            lo, hi = (mid, hi) if f < tau[i] else (lo, mid)
        out[i] = lo
    return out


def _levels(t: FloatArray, rng: np.random.Generator, amp: float, hold: tuple[float, float],
            lowest: float = 0.0) -> FloatArray:
    """Multi-level PRBS: uniform random levels in ±amp (|level| ≥ lowest·amp), random holds."""
    n = int(t[-1] / hold[0]) + 2
    switch = np.cumsum(rng.uniform(hold[0], hold[1], n))
    level = rng.uniform(lowest, 1.0, n + 1) * rng.choice([-1.0, 1.0], n + 1) * amp
    return np.asarray(level[np.searchsorted(switch, t)], dtype=float)


def _smooth(x: FloatArray, dt: float, tau: float) -> FloatArray:
    """Critically damped second-order low-pass (two first-order stages, time constant tau)."""
    a = np.exp(-dt / tau)
    y = signal.lfilter([1 - a], [1, -a], x - x[0], axis=0) + x[0]
    return np.asarray(signal.lfilter([1 - a], [1, -a], y - y[0], axis=0) + y[0], dtype=float)


def _smooth_random(t: FloatArray, rng: np.random.Generator, amp: float,
                   hold: tuple[float, float], tau: float) -> tuple[FloatArray, FloatArray]:
    """Smooth random signal and its derivative (for angles and depth)."""
    dt = float(t[1] - t[0])
    x = _smooth(_levels(t, rng, amp, hold), dt, tau)
    return x, np.gradient(x, dt)


def make_excitation(name: str, vehicle: Vehicle, duration: float, seed: int = 0,
                    control_rate: float = 50.0, depth: float = 5.0,
                    amplitude: float = 1.0) -> Excitation:
    """Sample protocol ``name`` for ``vehicle`` over ``duration`` seconds.

    Parameters
    ----------
    name : {'A', 'B', 'C', 'fourier'}
    vehicle : Vehicle
        Nominal vehicle: its thrust limits and damping set the speed range.
    duration : float
        Length (s).
    seed : int
        Random seed of the PRBS levels, phases and coefficients.
    control_rate : float
        Rate of the control grid (Hz).
    depth : float
        Mean depth (m).
    amplitude : float
        Scale of all amplitudes (1 = the protocol's default share of the speed range).

    Returns
    -------
    Excitation
    """
    if name not in PROTOCOLS:
        raise ConfigError("protocol", f"unknown protocol {name!r}; use one of {PROTOCOLS}")
    vehicle.need_thrusters("simulating the vehicle (the thrust limits of its excitation)")
    if duration <= 0:
        raise ConfigError("duration", f"must be > 0, got {duration}")
    rng = np.random.default_rng(seed)
    dt = 1.0 / control_rate
    t = np.arange(0.0, duration + 0.5 * dt, dt)
    K = len(t)
    lim = speed_limits(vehicle) * amplitude
    nu_ref = np.zeros((K, 6))
    att = np.zeros((K, 2))
    dep = np.full(K, depth)
    tau_ff = np.zeros((K, 6))
    bw = np.full(6, 2.0)
    max_angle = np.deg2rad(25.0) * min(amplitude, 1.0)

    if name == "A":
        # one DOF at a time: steps at ±5 % of the range, then a slow sine (0.05 Hz)
        order = [0, 1, 2, 5, 3, 4]
        seg = duration / len(order)
        for k, i in enumerate(order):
            m = (t >= k * seg) & (t < (k + 1) * seg)
            ts = t[m] - k * seg
            # angular rates capped so that roll and pitch stay within about 10°
            a = 0.05 * lim[i] if i < 3 or i == 5 else min(0.05 * lim[i], 0.1)
            steps = a * np.where((ts // 8.0) % 4 < 2, 1.0, -1.0) * ((ts // 8.0) % 2)
            sine = a * np.sin(2 * np.pi * 0.05 * ts)
            nu_ref[m, i] = np.where(ts < seg / 2, steps, sine)
        bw[:] = 1.5
    elif name == "B":
        # surge: triangle ramp from −0.3 U to U plus PRBS; sway/yaw: multi-level PRBS
        period = min(duration / 2.0, 200.0)
        tri = 2.0 * np.abs((t / period) % 1.0 - 0.5)  # 1 → 0 → 1
        nu_ref[:, 0] = lim[0] * (1.0 - 1.3 * tri) + _levels(t, rng, 0.2 * lim[0], (1.0, 4.0))
        nu_ref[:, 1] = _levels(t, rng, 0.9 * lim[1], (1.0, 4.0), lowest=0.2)
        nu_ref[:, 5] = _levels(t, rng, 0.7 * lim[5], (1.0, 4.0), lowest=0.2)
        # heave: smooth random depth changes whose peak rate is about the heave range
        tau_d = 0.6
        d, w = _smooth_random(t, rng, 0.5 * np.e * tau_d * lim[2], (1.5, 4.0), tau_d)
        dep += d
        nu_ref[:, 2] = w
        # roll, pitch: smooth random angles, their rates as references
        for j, i in enumerate((3, 4)):
            ang, rate = _smooth_random(t, rng, max_angle, (0.8, 2.5), 0.15)
            att[:, j] = ang
            nu_ref[:, i] = rate
        # band-limit the steps (time constant 0.15 s): thrust content stays below ~3 Hz,
        # where the identification looks, instead of jumping at every level change
        nu_ref[:, [0, 1, 5]] = _smooth(nu_ref[:, [0, 1, 5]], dt, 0.15)
        bw[:] = 3.0
    elif name == "C":
        # Schroeder-phased multisine 0.1–10 Hz, interleaved frequency lines per DOF
        lines = np.geomspace(0.1, 10.0, 36)
        f_max = vehicle.wrench_scale()
        for i in range(6):
            f = lines[i::6]
            phase = -np.pi * np.arange(len(f)) * (np.arange(len(f)) + 1) / len(f)
            phase = phase + rng.uniform(0, 2 * np.pi)
            x = np.sin(2 * np.pi * f[None, :] * t[:, None] + phase).sum(axis=1)
            # RMS 8 % of the thrust range (3 % in roll and pitch, which restoring holds)
            share = 0.08 if i in (0, 1, 2, 5) else 0.03
            tau_ff[:, i] = share * amplitude * f_max[i] * x / np.sqrt(np.mean(x * x))
        bw[:] = [0.3, 0.3, 0.3, 2.0, 2.0, 0.3]
    else:  # fourier
        wf = 2 * np.pi / 50.0
        harm = np.arange(1, 6)
        for i in (0, 1, 2, 5):
            a, b = rng.normal(size=5), rng.normal(size=5)
            x = (a * np.sin(wf * harm * t[:, None]) + b * np.cos(wf * harm * t[:, None]) - b)
            s = x.sum(axis=1)
            nu_ref[:, i] = 0.8 * lim[i] * s / np.abs(s).max()
        for j, i in enumerate((3, 4)):
            a, b = rng.normal(size=5), rng.normal(size=5)
            x = (a * np.sin(wf * harm * t[:, None]) + b * np.cos(wf * harm * t[:, None]) - b)
            s = x.sum(axis=1)
            att[:, j] = max_angle * s / np.abs(s).max()
            nu_ref[:, i] = np.gradient(att[:, j], dt)
        bw[:] = 2.0
    return Excitation(name, t, nu_ref, att, dep, tau_ff, bw)
