"""Excitation protocols: what the vehicle is asked to do while data are recorded.

A protocol is generated block by block on the control grid (vectorised within a block) into
velocity references, roll/pitch/depth references and an open-loop wrench; a velocity PI
controller tracks them so that the vehicle stays within its limits. Memory is that of a
block whatever the duration (:class:`ProtocolStream`), and the blocks concatenate to the protocol
sampled at once (:meth:`ProtocolStream.sample`): the random levels are drawn as they are needed
from copies of the seed's stream advanced to where each signal's draws begin, the smoothing
filters carry their state across blocks, and derivatives look one sample into the next
block. The offline simulation and the simulator node fly the same :class:`ProtocolStream`.

- ``A``: low-speed steps then slow sines, one degree of freedom at a time (linear regime).
- ``B``: ramped surge with PRBS on top, multi-level PRBS on sway and yaw rate, and smooth
  random roll, pitch and depth manoeuvres, so one run excites all six DOFs over their range.
- ``C``: multisine wrench 0.1–10 Hz on all six DOFs (frequency response, fluid memory), with
  a slow controller holding the mean.
- ``axes``: one DOF at a time over its whole range, every other velocity held at zero:
  square waves of rising amplitude (20 … 100 % of the range) in surge, sway, heave and yaw
  rate, sines of rising rate in roll and pitch. The damping along each axis (Fossen's
  pure-axis coefficients X_u, X_u|u|, …) is then flown, not extrapolated from mixed motion.
- ``fourier``: finite-Fourier-series velocity trajectories (period 50 s, 5 harmonics).
- ``optimal``: finite-Fourier-series velocity, roll, pitch and depth references (period
  10 s, 5 harmonics up to 0.5 Hz) whose coefficients are optimised for the condition number
  of the damping regressor within the speed limits, ±25° of roll and pitch, ±2 m of depth
  and 70 % of every thruster's thrust (:mod:`dampest_ros.core.simulation.vehicle_design`, the arm's
  design engine); the design and its condition numbers are :attr:`ProtocolStream.design`.
- ``hover`` (the simulator node only): station keeping at constant depth.
"""

from __future__ import annotations

import copy
import itertools
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.simulation.design import Design, FourierTrajectory, Kinematic
from dampest_ros.core.simulation.vehicle_design import (
    design_vehicle,
    nominal_wrench,
    vehicle_limits,
)

FloatArray = NDArray[np.float64]

PROTOCOLS = ("A", "B", "C", "axes", "fourier", "optimal")
#: What the simulator node flies: the protocols and station keeping.
LIVE_PROTOCOLS = (*PROTOCOLS, "hover")
#: Control ticks per generated block (4096 ticks × 16 numbers × 8 B = 512 kB).
BLOCK = 4096


@dataclass
class Excitation:
    """A protocol sampled on the control grid (the whole of it, or one block).

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

    @property
    def ticks(self) -> int:
        """Control instants K."""
        return len(self.t)

    @property
    def dt(self) -> float:
        """Control period (s)."""
        return float(self.t[1] - self.t[0])

    @property
    def initial_depth(self) -> float:
        """Depth reference at the start (m)."""
        return float(self.depth_ref[0])

    def command(self, k: int, nu: FloatArray, roll: float, pitch: float,
                depth: float) -> FloatArray:
        """Velocity command at tick k: reference plus attitude and depth correction."""
        cmd = self.nu_ref[k].copy()
        # outer loops: ν_cmd = ν_ref + k (x_ref − x) for depth, roll, pitch
        cmd[2] += 0.8 * (self.depth_ref[k] - depth)
        cmd[3] += 1.5 * (self.attitude_ref[k, 0] - roll)
        cmd[4] += 1.5 * (self.attitude_ref[k, 1] - pitch)
        return cmd

    def feedforward(self, k: int) -> FloatArray:
        """Open-loop wrench at tick k (N, N·m), shape (6,)."""
        return self.tau_ff[k]


@dataclass
class _Raw:
    """One block before differentiation: ``grad`` (n, m) are the signals whose time
    derivatives become the velocity references of columns ``cols``."""

    nu_ref: FloatArray
    attitude_ref: FloatArray
    depth_ref: FloatArray
    tau_ff: FloatArray
    grad: FloatArray


class ProtocolStream:
    """A protocol generated block by block (:data:`BLOCK` control ticks at a time).

    Read it forward, tick by tick (:meth:`command`, :meth:`feedforward`: what
    :func:`dampest_ros.core.simulation.simulate.run` and the simulator node do), or whole
    (:meth:`sample`); memory is that of two blocks whatever the duration.

    Parameters
    ----------
    name : str
    ticks : int
        Control instants K (0 … duration).
    dt : float
        Control period (s).
    bandwidth : ndarray, shape (6,)
        Velocity-loop bandwidth per DOF (rad/s).
    raw : callable
        ``raw()`` → a fresh iterator of consecutive raw blocks covering the K ticks.
    cols : tuple of int
        Velocity references that are the time derivatives of the raw blocks' ``grad``.
    design : Design, optional
        The optimised design of protocol ``optimal`` (its condition numbers).
    """

    def __init__(self, name: str, ticks: int, dt: float, bandwidth: FloatArray,
                 raw: Callable[[], Iterator[_Raw]], cols: tuple[int, ...] = (),
                 design: Design | None = None) -> None:
        self.name, self.ticks, self.dt = name, int(ticks), float(dt)
        self.bandwidth = np.asarray(bandwidth, dtype=float)
        self._raw, self._cols = raw, list(cols)
        self.design = design
        self._iter: Iterator[Excitation] | None = None
        self._block: Excitation | None = None
        self._k0 = 0

    @property
    def initial_depth(self) -> float:
        """Depth reference at t = 0 (m)."""
        return float(next(self._raw()).depth_ref[0])

    def blocks(self) -> Iterator[Excitation]:
        """The protocol from its start, one sampled block after the other."""
        raws = self._raw()
        k0, prev = 0, None
        cur = next(raws)
        for nxt in itertools.chain(raws, (None,)):
            n = len(cur.depth_ref)
            nu_ref = cur.nu_ref
            if self._cols:
                # the derivative of a block's samples needs one sample either side of it:
                # the same central differences (one-sided at the ends) as the whole signal
                ext = np.concatenate([g for g in (prev, cur.grad,
                                                  None if nxt is None else nxt.grad[:1])
                                      if g is not None])
                lo = 0 if prev is None else 1
                nu_ref[:, self._cols] = np.gradient(ext, self.dt, axis=0)[lo:lo + n]
                prev = cur.grad[-1:]
            t = np.arange(k0, k0 + n, dtype=float) * self.dt
            yield Excitation(self.name, t, nu_ref, cur.attitude_ref, cur.depth_ref,
                             cur.tau_ff, self.bandwidth)
            k0 += n
            if nxt is not None:
                cur = nxt

    def sample(self) -> Excitation:
        """The whole protocol as one :class:`Excitation` (K samples: memory grows with the
        duration; for plots, tests and short runs)."""
        parts = list(self.blocks())

        def whole(field: str) -> FloatArray:
            return np.concatenate([getattr(p, field) for p in parts])

        return Excitation(self.name, whole("t"), whole("nu_ref"), whole("attitude_ref"),
                          whole("depth_ref"), whole("tau_ff"), self.bandwidth)

    def _at(self, k: int) -> tuple[Excitation, int]:
        """The block holding tick k and k's index in it (forward only)."""
        if self._iter is None or k < self._k0:
            self._iter, self._block, self._k0 = self.blocks(), None, 0
        if self._block is None:
            self._block = next(self._iter)
        while k >= self._k0 + len(self._block.t):
            self._k0 += len(self._block.t)
            self._block = next(self._iter)
        return self._block, k - self._k0

    def command(self, k: int, nu: FloatArray, roll: float, pitch: float,
                depth: float) -> FloatArray:
        """Velocity command at tick k (:meth:`Excitation.command`)."""
        block, i = self._at(k)
        return block.command(i, nu, roll, pitch, depth)

    def feedforward(self, k: int) -> FloatArray:
        """Open-loop wrench at tick k (N, N·m), shape (6,)."""
        block, i = self._at(k)
        return block.feedforward(i)


def speed_limits(vehicle: Vehicle, fraction: float = 0.5,
                 force: FloatArray | None = None) -> FloatArray:
    """Steady speed per DOF reached with ``fraction`` of the largest thrust, shape (6,).

    Solves D(ν)ν = fraction · τ_max along each axis by bisection on the nominal model.

    Parameters
    ----------
    vehicle : Vehicle
    fraction : float
    force : ndarray, shape (6,), optional
        The 99th percentile of the measured |τ_i| (N, N·m; an
        :class:`~dampest_ros.core.signals.extent.Extent`'s ``force``): gives τ_max for a
        vehicle without thrusters
        (:meth:`~dampest_ros.core.physics.vehicle.Vehicle.wrench_scale`).

    Returns
    -------
    ndarray, shape (6,)
        m/s and rad/s.
    """
    tau = fraction * vehicle.wrench_scale(force)
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


#: Draws per chunk of a PRBS's switch times, levels and signs.
_DRAWS = 4096


class _Levels:
    """Multi-level PRBS: uniform random levels in ±amp (|level| ≥ lowest·amp) held for
    uniform random times in ``hold``, drawn as the time advances.

    Sampled at once, n = ⌊t_end / hold_min⌋ + 2 switch times (cumulated holds), then n + 1
    level magnitudes, then n + 1 signs come from the generator in that order; here three
    copies of it, advanced to where each of the three runs begins, draw them in chunks (the
    same numbers: a uniform is the stream's next 64-bit draw, a sign its next 32 bits, the
    half of a draw left over kept in the generator for the next sign, also across signals).

    Parameters
    ----------
    bits : numpy.random.PCG64
        The stream at this signal's first draw (not advanced here).
    t_end : float
        Last instant (s).
    amp : float
    hold : (float, float)
        Hold time range (s).
    lowest : float
    """

    def __init__(self, bits: np.random.PCG64, t_end: float, amp: float,
                 hold: tuple[float, float], lowest: float = 0.0) -> None:
        n = int(t_end / hold[0]) + 2
        self.n, self.amp, self.hold, self.lowest = n, amp, hold, lowest
        buffered = int(bits.state["has_uint32"])
        self.durations = np.random.Generator(_advanced(bits, 0))
        self.magnitudes = np.random.Generator(_advanced(bits, n))
        self.signs = np.random.Generator(_advanced(bits, 2 * n + 1, bits))
        # the signs take n + 1 halves, the first from the buffer if one is there
        halves = n + 1 - buffered
        #: the stream after this signal's draws (where the next signal begins)
        self.after = _advanced(bits, 2 * n + 1 + (halves + 1) // 2)
        if halves % 2:
            last = _advanced(bits, 2 * n + (halves + 1) // 2).random_raw()
            _buffer(self.after, 1, int(last) >> 32)
        self.switch = np.zeros(0)
        self.level = np.zeros(0)
        self.drawn = 0
        self.carry = 0.0

    def __call__(self, t: FloatArray) -> FloatArray:
        """Levels at the instants t (increasing, after those of the previous call)."""
        while self.drawn < self.n and (not len(self.switch) or self.switch[-1] < t[-1]):
            m = min(_DRAWS, self.n - self.drawn)
            # cumulated holds, continuing the sum exactly as one cumsum would
            s = np.cumsum(np.concatenate(
                [[self.carry], self.durations.uniform(self.hold[0], self.hold[1], m)]))[1:]
            self.carry = float(s[-1])
            ml = m + (self.drawn + m == self.n)  # n + 1 levels in all
            lv = (self.magnitudes.uniform(self.lowest, 1.0, ml)
                  * self.signs.choice([-1.0, 1.0], ml) * self.amp)
            self.switch = np.concatenate([self.switch, s])
            self.level = np.concatenate([self.level, lv])
            self.drawn += m
        out = self.level[np.searchsorted(self.switch, t)]
        # switch times before the last instant are before every later one too
        drop = int(np.searchsorted(self.switch, t[-1]))
        self.switch, self.level = self.switch[drop:], self.level[drop:]
        return np.asarray(out, dtype=float)


def _advanced(bits: np.random.PCG64, draws: int,
              buffer_of: np.random.PCG64 | None = None) -> np.random.PCG64:
    """A copy of ``bits`` advanced by ``draws`` 64-bit draws (advancing empties its 32-bit
    buffer; ``buffer_of``: restore that generator's)."""
    b = copy.deepcopy(bits)
    b.advance(draws)
    if buffer_of is not None:
        st = buffer_of.state
        _buffer(b, int(st["has_uint32"]), int(st["uinteger"]))
    return b


def _buffer(bits: np.random.PCG64, has: int, value: int) -> None:
    """Set the 32-bit half-draw a PCG64 keeps for its next 32-bit output."""
    st = bits.state
    st["has_uint32"], st["uinteger"] = has, value
    bits.state = st


class _Smooth:
    """Critically damped second-order low-pass (two first-order stages, time constant tau)
    of a signal given block by block, each stage started at the signal's first value."""

    def __init__(self, dt: float, tau: float) -> None:
        a = float(np.exp(-dt / tau))
        self.b, self.a = [1 - a], [1, -a]
        self.x0: FloatArray | None = None
        self.y0: FloatArray | None = None
        self.z1: FloatArray | None = None
        self.z2: FloatArray | None = None

    def __call__(self, x: FloatArray) -> FloatArray:
        from scipy import signal  # ~0.4 s to import: not for those who only read the limits

        if self.x0 is None:
            self.x0 = x[0].copy()
            self.z1 = np.zeros((1, *x.shape[1:]))
            self.z2 = np.zeros((1, *x.shape[1:]))
        # y_k = a y_{k−1} + (1 − a) x_k on x − x_0 (zero initial state), twice
        y, self.z1 = signal.lfilter(self.b, self.a, x - self.x0, axis=0, zi=self.z1)
        y = y + self.x0
        if self.y0 is None:
            self.y0 = y[0].copy()
        out, self.z2 = signal.lfilter(self.b, self.a, y - self.y0, axis=0, zi=self.z2)
        return np.asarray(out + self.y0, dtype=float)


def _grid(ticks: int, dt: float) -> Iterator[FloatArray]:
    """The control instants k·dt, :data:`BLOCK` at a time."""
    for k0 in range(0, ticks, BLOCK):
        yield np.arange(k0, min(k0 + BLOCK, ticks), dtype=float) * dt


def _zeros(t: FloatArray, depth: float, grad: int = 0) -> _Raw:
    n = len(t)
    return _Raw(np.zeros((n, 6)), np.zeros((n, 2)), np.full(n, depth), np.zeros((n, 6)),
                np.zeros((n, grad)))


def make_excitation(name: str, vehicle: Vehicle, duration: float, seed: int = 0,
                    control_rate: float = 50.0, depth: float = 5.0,
                    amplitude: float = 1.0) -> Excitation:
    """ProtocolStream ``name`` sampled at once (:func:`protocol` followed by
    :meth:`ProtocolStream.sample`; memory grows with the duration)."""
    return protocol(name, vehicle, duration, seed, control_rate, depth, amplitude).sample()


def protocol(name: str, vehicle: Vehicle, duration: float, seed: int = 0,
             control_rate: float = 50.0, depth: float = 5.0,
             amplitude: float = 1.0) -> ProtocolStream:
    """ProtocolStream ``name`` for ``vehicle`` over ``duration`` seconds, generated block by block.

    Parameters
    ----------
    name : {'A', 'B', 'C', 'axes', 'fourier', 'optimal', 'hover'}
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
    ProtocolStream
    """
    if name not in LIVE_PROTOCOLS:
        raise ConfigError("protocol", f"unknown protocol {name!r}; use one of {PROTOCOLS}")
    dt = 1.0 / control_rate
    if not duration >= dt:
        raise ConfigError("duration", f"must be at least one control step ({dt:g} s), "
                                      f"got {duration}")
    # the instants 0, dt, … ≤ duration (numpy's arange count)
    ticks = math.ceil((duration + 0.5 * dt) / dt)
    if name == "hover":
        return ProtocolStream(name, ticks, dt, np.full(6, 1.0),
                              lambda: (_zeros(t, depth) for t in _grid(ticks, dt)))
    vehicle.need_thrusters("simulating the vehicle (the thrust limits of its excitation)")
    rng = np.random.default_rng(seed)
    lim = speed_limits(vehicle) * amplitude
    max_angle = np.deg2rad(25.0) * min(amplitude, 1.0)
    t_end = (ticks - 1) * dt
    if name == "A":
        return ProtocolStream(name, ticks, dt, np.full(6, 1.5),
                              lambda: (_protocol_a(t, duration, lim, depth)
                                       for t in _grid(ticks, dt)))
    if name == "B":
        bits = rng.bit_generator
        assert isinstance(bits, np.random.PCG64)
        return ProtocolStream(name, ticks, dt, np.full(6, 3.0),
                              lambda: _protocol_b(ticks, dt, bits, t_end, duration, lim,
                                                  max_angle, depth), cols=(2, 3, 4))
    if name == "C":
        return _protocol_c(vehicle, rng, ticks, dt, depth, amplitude)
    if name == "axes":
        return ProtocolStream(name, ticks, dt, np.full(6, 3.0),
                              lambda: _protocol_axes(ticks, dt, duration, lim, max_angle,
                                                     depth), cols=(2, 3, 4))
    if name == "fourier":
        return _protocol_fourier(rng, ticks, dt, lim, max_angle, depth)
    design = design_vehicle(vehicle, vehicle_limits(vehicle, lim, max_angle), seed=seed)
    wrench = nominal_wrench(vehicle)
    return ProtocolStream(name, ticks, dt, np.full(6, 3.0),
                          lambda: (_protocol_optimal(design.trajectory, wrench, t, depth)
                                   for t in _grid(ticks, dt)), design=design)


def _protocol_optimal(traj: FourierTrajectory, wrench: Kinematic, t: FloatArray,
                      depth: float) -> _Raw:
    """The designed FFS at the instants t: ν_ref = q̇, roll and pitch q₃, q₄, depth + q₂,
    and the nominal model's τ along it as feed-forward (the controller corrects the rest)."""
    raw = _zeros(t, depth)
    q, qd, qdd = traj.evaluate(t)
    raw.nu_ref[:] = qd
    raw.attitude_ref[:] = q[:, 3:5]
    raw.depth_ref += q[:, 2]
    raw.tau_ff[:] = wrench(q, qd, qdd)
    return raw


def _protocol_a(t: FloatArray, duration: float, lim: FloatArray, depth: float) -> _Raw:
    """ProtocolStream A at the instants t: one DOF at a time, steps at ±5 % of the range, then a
    slow sine (0.05 Hz)."""
    raw = _zeros(t, depth)
    order = [0, 1, 2, 5, 3, 4]
    seg = duration / len(order)
    for k, i in enumerate(order):
        m = (t >= k * seg) & (t < (k + 1) * seg)
        ts = t[m] - k * seg
        # angular rates capped so that roll and pitch stay within about 10°
        a = 0.05 * lim[i] if i < 3 or i == 5 else min(0.05 * lim[i], 0.1)
        steps = a * np.where((ts // 8.0) % 4 < 2, 1.0, -1.0) * ((ts // 8.0) % 2)
        sine = a * np.sin(2 * np.pi * 0.05 * ts)
        raw.nu_ref[m, i] = np.where(ts < seg / 2, steps, sine)
    return raw


def _protocol_b(ticks: int, dt: float, bits: np.random.PCG64, t_end: float,
                duration: float, lim: FloatArray, max_angle: float,
                depth: float) -> Iterator[_Raw]:
    """ProtocolStream B block by block: surge a triangle ramp from −0.3 U to U plus PRBS,
    sway and yaw rate multi-level PRBS, smooth random depth, roll and pitch (whose
    derivatives are the heave, roll and pitch rate references)."""
    tau_d = 0.6  # heave: smooth random depth changes whose peak rate is about the range
    specs = ((0.2 * lim[0], (1.0, 4.0), 0.0), (0.9 * lim[1], (1.0, 4.0), 0.2),
             (0.7 * lim[5], (1.0, 4.0), 0.2), (0.5 * math.e * tau_d * lim[2], (1.5, 4.0), 0.0),
             (max_angle, (0.8, 2.5), 0.0), (max_angle, (0.8, 2.5), 0.0))
    levels = []
    for amp, hold, lowest in specs:  # in the order the stream's draws were made
        levels.append(_Levels(bits, t_end, amp, hold, lowest))
        bits = levels[-1].after
    smooth_depth = _Smooth(dt, tau_d)
    smooth_angles = [_Smooth(dt, 0.15), _Smooth(dt, 0.15)]
    # band-limit the steps (time constant 0.15 s): thrust content stays below ~3 Hz,
    # where the identification looks, instead of jumping at every level change
    smooth_steps = _Smooth(dt, 0.15)
    period = min(duration / 2.0, 200.0)
    for t in _grid(ticks, dt):
        raw = _zeros(t, depth, 3)
        tri = 2.0 * np.abs((t / period) % 1.0 - 0.5)  # 1 → 0 → 1
        raw.nu_ref[:, 0] = lim[0] * (1.0 - 1.3 * tri) + levels[0](t)
        raw.nu_ref[:, 1] = levels[1](t)
        raw.nu_ref[:, 5] = levels[2](t)
        d = smooth_depth(levels[3](t))
        raw.depth_ref += d
        raw.grad[:, 0] = d
        for j in range(2):
            raw.attitude_ref[:, j] = smooth_angles[j](levels[4 + j](t))
            raw.grad[:, 1 + j] = raw.attitude_ref[:, j]
        raw.nu_ref[:, [0, 1, 5]] = smooth_steps(raw.nu_ref[:, [0, 1, 5]])
        yield raw


#: Amplitudes of the axes protocol's legs (share of the DOF's range), flown in this order.
AXIS_LEVELS = (0.2, 0.4, 0.6, 0.8, 1.0)


def _protocol_axes(ticks: int, dt: float, duration: float, lim: FloatArray,
                   max_angle: float, depth: float) -> Iterator[_Raw]:
    """ProtocolStream axes block by block: a leg per DOF (surge, sway, heave, yaw, roll,
    pitch), each a sixth of the run. Translations and yaw rate: +a, −a square waves held
    for equal times, a rising through :data:`AXIS_LEVELS` of the range, band-limited
    (0.3 s); the depth reference is the running integral of the heave (it returns after
    every pair). Roll and pitch: attitude sines of amplitude ``max_angle`` whose peak rate
    rises through the same shares of the range (at most 0.5 Hz), with continuous phase
    (the rates are the derivatives of the angles)."""
    order = (0, 1, 2, 5, 3, 4)
    seg = duration / len(order)
    hold = seg / (2 * len(AXIS_LEVELS))
    share = np.asarray(AXIS_LEVELS)
    signed = np.repeat(share, 2) * np.tile([1.0, -1.0], len(share))
    smooth = _Smooth(dt, 0.3)
    dive, phase = 0.0, np.zeros(2)
    for t in _grid(ticks, dt):
        raw = _zeros(t, depth, 3)
        leg = np.minimum((t // seg).astype(int), len(order) - 1)
        step = np.minimum(((t - leg * seg) // hold).astype(int), len(signed) - 1)
        dof = np.asarray(order)[leg]
        for i in (0, 1, 2, 5):
            raw.nu_ref[:, i] = np.where(dof == i, lim[i] * signed[step], 0.0)
        raw.nu_ref[:, [0, 1, 2, 5]] = smooth(raw.nu_ref[:, [0, 1, 2, 5]])
        # depth = depth_0 + ∫ w dt: the running sum continued from the last block's
        # (the same additions, in the same order, as one sum over the whole run)
        dive_t = np.cumsum(np.concatenate([[dive], raw.nu_ref[:, 2] * dt]))[1:]
        dive = float(dive_t[-1])
        raw.depth_ref += dive_t
        raw.grad[:, 0] = dive_t
        for j, i in enumerate((3, 4)):
            # φ = A sin Φ, Φ = ∫ ω dt with A ω = share · range on the DOF's own leg
            omega = np.where(dof == i, np.minimum(share[step // 2] * lim[i] / max_angle,
                                                  np.pi), 0.0)
            phase_t = np.cumsum(np.concatenate([[phase[j]], omega * dt]))[1:]
            phase[j] = phase_t[-1]
            raw.attitude_ref[:, j] = max_angle * np.sin(phase_t)
            raw.grad[:, 1 + j] = raw.attitude_ref[:, j]
        yield raw


def _protocol_c(vehicle: Vehicle, rng: np.random.Generator, ticks: int, dt: float,
                depth: float, amplitude: float) -> ProtocolStream:
    """Schroeder-phased multisine wrench 0.1–10 Hz, interleaved frequency lines per DOF,
    RMS 8 % of the thrust range (3 % in roll and pitch, which restoring holds)."""
    lines = np.geomspace(0.1, 10.0, 36)
    f_max = vehicle.wrench_scale()
    freq = [lines[i::6] for i in range(6)]
    phases = []
    for f in freq:
        phase = -np.pi * np.arange(len(f)) * (np.arange(len(f)) + 1) / len(f)
        phases.append(phase + rng.uniform(0, 2 * np.pi))

    def sines(t: FloatArray) -> FloatArray:
        """Σ_l sin(2π f_l t + φ_l) per DOF, shape (n, 6)."""
        return np.stack([np.sin(2 * np.pi * f[None, :] * t[:, None] + ph).sum(axis=1)
                         for f, ph in zip(freq, phases, strict=True)], axis=1)

    # the RMS over the whole run (closed form: the time to start does not grow with it)
    rms = np.sqrt([_mean_square(2 * np.pi * f * dt, ph, ticks)
                   for f, ph in zip(freq, phases, strict=True)])
    share = np.array([0.08, 0.08, 0.08, 0.03, 0.03, 0.08])

    def raw() -> Iterator[_Raw]:
        for t in _grid(ticks, dt):
            r = _zeros(t, depth)
            x = sines(t)
            for i in range(6):
                r.tau_ff[:, i] = share[i] * amplitude * f_max[i] * x[:, i] / rms[i]
            yield r

    return ProtocolStream("C", ticks, dt, np.array([0.3, 0.3, 0.3, 2.0, 2.0, 0.3]), raw)


def _mean_square(theta: FloatArray, phase: FloatArray, ticks: int) -> float:
    """Mean over k = 0 … K−1 of x_k², x_k = Σ_l sin(θ_l k + φ_l), in closed form.

    Parameters
    ----------
    theta, phase : ndarray, shape (L,)
        Phase increment per tick and initial phase of each line (rad); the θ_l ± θ_m are
        not multiples of 2π but where they are exactly 0.
    ticks : int
        K.

    Returns
    -------
    float
    """
    def cos_sum(c: FloatArray, d: FloatArray) -> FloatArray:
        # Σ_k cos(c k + d) = sin(K c / 2) / sin(c / 2) · cos(d + (K − 1) c / 2); K cos d at c = 0
        s = np.sin(c / 2)
        zero = c == 0.0
        ratio = np.sin(ticks * c / 2) / np.where(zero, 1.0, s)
        return np.where(zero, ticks * np.cos(d), ratio * np.cos(d + (ticks - 1) * c / 2))

    # sin a sin b = (cos(a − b) − cos(a + b)) / 2, summed over every pair of lines
    diff = cos_sum(theta[:, None] - theta[None, :], phase[:, None] - phase[None, :])
    total = cos_sum(theta[:, None] + theta[None, :], phase[:, None] + phase[None, :])
    return float((diff - total).sum() / (2 * ticks))


def _protocol_fourier(rng: np.random.Generator, ticks: int, dt: float, lim: FloatArray,
                      max_angle: float, depth: float) -> ProtocolStream:
    """Finite-Fourier-series velocity (surge, sway, heave, yaw) and angle (roll, pitch)
    trajectories: period 50 s, 5 harmonics, random coefficients, each scaled so that its
    largest value over the run is 80 % of the speed range (the angle limit)."""
    wf = 2 * np.pi / 50.0
    harm = np.arange(1, 6)
    coef = [(rng.normal(size=5), rng.normal(size=5)) for _ in range(6)]

    def series(t: FloatArray) -> FloatArray:
        """Σ_l a_l sin(l ω t) + b_l cos(l ω t) − b_l per signal, shape (n, 6)."""
        return np.stack([(a * np.sin(wf * harm * t[:, None]) + b * np.cos(wf * harm * t[:, None])
                          - b).sum(axis=1) for a, b in coef], axis=1)

    # the largest value over the run is that over one period (the series repeat)
    period = np.arange(min(ticks, round(50.0 / dt) + 1), dtype=float) * dt
    peak = np.abs(series(period)).max(axis=0)
    scale = np.concatenate([0.8 * lim[[0, 1, 2, 5]], [max_angle, max_angle]])

    def raw() -> Iterator[_Raw]:
        for t in _grid(ticks, dt):
            r = _zeros(t, depth, 2)
            s = series(t)
            for j, i in enumerate((0, 1, 2, 5)):
                r.nu_ref[:, i] = scale[j] * s[:, j] / peak[j]
            for j in range(2):
                r.attitude_ref[:, j] = scale[4 + j] * s[:, 4 + j] / peak[4 + j]
            r.grad[:] = r.attitude_ref
            yield r

    return ProtocolStream("fourier", ticks, dt, np.full(6, 2.0), raw, cols=(3, 4))
