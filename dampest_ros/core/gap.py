"""Sim-to-real gap: where measured data and a believed model disagree, and what is missing.

A user has a model of the vehicle (M, the damping D(ν) with its θ, restoring data) and data
from the real vehicle (:class:`~dampest_ros.core.samples.Samples`: ν, ν̇, τ, attitude, depth,
as a vehicle logs them; never ground truth). This module

1. compares them through the one-step inverse-dynamics residual (FRD body, NED world)

       r(t) = τ − (M ν̇ + C(ν)ν + D(ν)ν + g(η))       (N, N·m),  shape (N, 6)

   i.e. ``batch.target − Φθ`` with the same parallel zero-phase low-pass as the
   identification (:func:`dampest_ros.core.batch.iter_regression`);
2. localises it (:func:`localise`): per DOF, velocity regime, frequency band (Welch PSD),
   time segment, attitude and depth;
3. names the missing effect (:func:`find_gap`): every candidate :class:`Effect` is a physical
   effect with a few unknown magnitudes p and an exact prediction ρ(p) of the residual it
   would leave in data analysed with the believed model (``r ≈ ρ(p) + noise``). Candidates
   are screened by fitting their linearisation on the first ``split`` (70 %) of the time and
   scoring the residual reduction on the rest (held out), with the error-reduction ratio and
   the BIC change as in :mod:`dampest_ros.core.selection`; the best significant one is
   refined on its exact (nonlinear) model with ``scipy.optimize.least_squares``, added, all
   added effects are refitted jointly, and the search repeats until no candidate is
   significant: "no further missing effect found".

The effects (each evaluated vectorised over chunks of samples, then low-passed like the
regression): ocean current constant in NED, buoyancy offset, CG offset, thrust-gain error,
thruster dead-zone (needs the logged rotor speeds), τ → ν delay, added-mass error (scale and
per DOF), a missing linear or quadratic damping coefficient per DOF, each cross-coupling of
:data:`dampest_ros.core.selection.DEFAULT_CROSS`, fluid memory per DOF, gyro bias and DVL bias.

Signs: with the model's residual r = τ − model(ν, ν̇, η), an effect that adds a force F to the
left-hand side of the true equation (M ν̇ + … + g + F = τ) leaves ρ = F.
"""

from __future__ import annotations

import importlib
import itertools
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, optimize, signal

from dampest_ros.core.batch import iter_regression
from dampest_ros.core.damping import (
    CrossSpec,
    DampingModel,
    DampingTerm,
    cross_term,
    filter_memory,
    linear_term,
    memory_term,
    quadratic_term,
)
from dampest_ros.core.dissipative import envelope
from dampest_ros.core.frames import matrix_from_euler
from dampest_ros.core.measurements import JointSeries
from dampest_ros.core.preprocess import zero_phase
from dampest_ros.core.rigid_body import (
    DOF_NAMES,
    FORCE_NAMES,
    AddedMassTerms,
    ConfigError,
    RigidBody,
    added_coriolis_force,
    coriolis_force,
    rigid_body_mass,
)
from dampest_ros.core.samples import CHUNK, Samples
from dampest_ros.core.selection import DEFAULT_CROSS
from dampest_ros.core.thrusters import Thrusters

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

FORCE_UNITS = ("N", "N", "N", "N·m", "N·m", "N·m")
NO_FURTHER = "no further missing effect found"


# --- data -----------------------------------------------------------------------------------


@dataclass
class Chunk:
    """Consecutive rows of one segment, with everything an effect needs to predict ρ.

    Attributes
    ----------
    rows : slice
        Rows in the full :class:`Samples`.
    t : ndarray, shape (n,)
        Time (s).
    nu, nu_dot, tau : ndarray, shape (n, 6)
        Velocity (m/s, rad/s), acceleration (m/s², rad/s²), thrust (N, N·m), FRD.
    R : ndarray, shape (n, 3, 3)
        Body (FRD) → NED rotations.
    """

    rows: slice
    t: FloatArray
    nu: FloatArray
    nu_dot: FloatArray
    tau: FloatArray
    R: FloatArray

    @property
    def down(self) -> FloatArray:
        """Rᵀ e_z, the NED down axis in the body frame, shape (n, 3)."""
        return self.R[:, 2, :]

    def __len__(self) -> int:
        return int(self.t.shape[0])


class GapData:
    """Measured samples, the believed model and the train / held-out split.

    Parameters
    ----------
    samples : Samples
        Measured data (FRD/NED).
    model : DampingModel
        The believed damping model.
    theta : ndarray, shape (p,)
        Its coefficients (positive when dissipative).
    body : RigidBody
        Believed M (rigid body + added mass) and restoring data.
    thrusters : Thrusters, optional
        Thruster geometry; with ``joints`` it enables the dead-zone candidate.
    joints : JointSeries, optional
        Logged thruster state (rotor speed in rad/s, thrust in N) on the samples' clock.
    cutoff : float
        Parallel low-pass of the regression (Hz), as in the identification.
    split : float
        Share of the time (from the start) used to fit; the rest is held out.
    chunk : int
        Samples per chunk (memory ∝ chunk).
    margin : float
        Seconds of neighbouring data filtered with each chunk.
    block : float
        Block length (s) of the robust covariance of the magnitudes.
    crossover : float
        DVL/IMU fusion crossover of the preprocessing (Hz), for the DVL-bias candidate.
    """

    def __init__(self, samples: Samples, model: DampingModel, theta: FloatArray,
                 body: RigidBody, thrusters: Thrusters | None = None,
                 joints: JointSeries | None = None, cutoff: float = 2.0, split: float = 0.7,
                 chunk: int = CHUNK, margin: float = 5.0, block: float = 10.0,
                 crossover: float = 0.3) -> None:
        if not 0.2 <= split <= 0.9:
            raise ConfigError("split", f"must be in [0.2, 0.9], got {split}")
        if len(samples) < 200:
            raise ConfigError("samples", f"{len(samples)} samples are too few")
        self.samples = samples
        self.model = model
        self.theta = np.asarray(theta, dtype=float)
        if self.theta.shape != (model.n_params,):
            raise ConfigError("theta", f"{self.theta.shape} for {model.n_params} parameters")
        self.body = body
        self.thrusters = thrusters
        self.joints = joints
        self.cutoff = float(cutoff)
        self.split = float(split)
        self.chunk = int(chunk)
        self.margin = float(margin)
        self.block = float(block)
        self.crossover = float(crossover)
        self.rate = samples.rate
        N = len(samples)
        self.train: BoolArray = np.arange(N) < round(split * N)
        self.test: BoolArray = ~self.train
        # r0 = y − Φθ with the identification's parallel low-pass (batch.iter_regression)
        self.r0 = np.zeros((N, 6))
        bounds = []
        for rows, Phi, y in iter_regression(samples, model, body, chunk=self.chunk,
                                            cutoff=self.cutoff, margin=self.margin):
            assert isinstance(rows, slice)  # contiguous chunks (no decimation)
            self.r0[rows] = y - Phi @ self.theta
            bounds.append((rows.start, rows.stop))
        self._chunks = list(self._chunk_bounds())
        if [(c.start, c.stop) for c, _, _ in self._chunks] != bounds:
            raise RuntimeError("chunk boundaries differ from batch.iter_regression")
        self._cache: dict[tuple[int, int], Chunk] = {}
        self._memo: dict[tuple[Any, ...], Any] = {}
        seconds = N / self.rate
        self.n_eff_train = min(float(self.train.sum()), 2 * self.cutoff * seconds * split) \
            if self.cutoff > 0 else float(self.train.sum())
        self.n_eff_test = min(float(self.test.sum()), 2 * self.cutoff * seconds * (1 - split)) \
            if self.cutoff > 0 else float(self.test.sum())
        block_of = np.floor((samples.t - samples.t[0]) / block).astype(np.int64)
        block_of += samples.segment * (int(block_of.max()) + 1)
        self.block_index = np.unique(block_of, return_inverse=True)[1].astype(np.int64)
        self.M_A = body.added_mass
        self.M_RB = body.M_RB
        self.n_states = len(model.memory_rates)
        # force scale per DOF on the held-out part: the thrust, or the residual where the
        # thrusters do not act (a DOF held by restoring alone)
        self.force_scale = np.maximum(np.sqrt(np.mean(samples.tau[self.test] ** 2, axis=0)),
                                      np.sqrt(np.mean(self.r0[self.test] ** 2, axis=0)))

    def _chunk_bounds(self) -> Iterator[tuple[slice, slice, slice]]:
        """(core rows, extended rows, core within extended): iter_regression's chunks."""
        s = self.samples
        pad = round(self.margin * s.rate) if self.cutoff > 0 else 0
        for seg in s.segments():
            s0, s1 = seg.start or 0, seg.stop or 0
            for start in range(s0, s1, self.chunk):
                stop = min(start + self.chunk, s1)
                a, b = max(s0, start - pad), min(s1, stop + pad)
                yield slice(start, stop), slice(a, b), slice(start - a, stop - a)

    def chunk_at(self, ext: slice) -> Chunk:
        """The :class:`Chunk` of rows ``ext`` (cached)."""
        key = (int(ext.start), int(ext.stop))
        if key not in self._cache:
            s = self.samples
            self._cache[key] = Chunk(ext, s.t[ext], s.nu[ext], s.nu_dot[ext], s.tau[ext],
                                     matrix_from_euler(s.euler[ext]))
        return self._cache[key]

    def memo(self, key: tuple[Any, ...], make: Callable[[], Any], size: int = 48) -> Any:
        """``make()`` cached under ``key`` for these data (least recently made dropped).

        Effects keep their tables here (memory states per rate, dead-zone thrust per width),
        so that a candidate object can be used with several data sets.
        """
        if key not in self._memo:
            self._memo[key] = make()
            if len(self._memo) > size:
                self._memo.pop(next(iter(self._memo)))
        return self._memo[key]

    def filtered(self, fn: Callable[[Chunk], FloatArray]) -> FloatArray:
        """``fn`` evaluated chunk by chunk, low-passed like the regression, all rows.

        Parameters
        ----------
        fn : callable
            Chunk → array of shape (n, 6, ...) (forces on the chunk's rows).

        Returns
        -------
        ndarray, shape (N, 6, ...)
        """
        out: FloatArray | None = None
        for core, ext, inner in self._chunks:
            x = fn(self.chunk_at(ext))
            if self.cutoff > 0:
                x = zero_phase(x, self.rate, self.cutoff)
            if out is None:
                out = np.zeros((len(self.samples), *x.shape[1:]))
            out[core] = x[inner]
        assert out is not None
        return out

    def static_force(self, nu: FloatArray) -> FloatArray:
        """C(ν)ν + D(ν)ν of the believed model without memory states, C_A acting as the
        vehicle's added-mass switches say, shape (n, 6)."""
        z = np.zeros((nu.shape[0], self.n_states))
        return np.asarray(self.body.coriolis_force(nu)
                          + self.model.force(nu, self.theta, z), dtype=float)

    def damping_force(self, nu: FloatArray) -> FloatArray:
        """D(ν)ν of the believed model without memory states, shape (n, 6)."""
        z = np.zeros((nu.shape[0], self.n_states))
        return self.model.force(nu, self.theta, z)

    @property
    def power_points(self) -> FloatArray:
        """Velocities where dissipativity is checked, shape (n, 6): every 5th sample and the
        5⁶ grid over the flown envelope at full size (:func:`batch.envelope`) (m/s, rad/s)."""
        def make() -> FloatArray:
            nu = self.samples.nu
            return np.concatenate([nu[::5], envelope(nu, scales=(1.0,))])

        out: FloatArray = self.memo(("power_points",), make)
        return out

    def theta_of(self, name: str) -> float:
        """The believed value of a damping parameter (0 when the model lacks it)."""
        names = self.model.parameter_names
        return float(self.theta[names.index(name)]) if name in names else 0.0


# --- effects --------------------------------------------------------------------------------


class Effect:
    """A candidate physical effect: unknown magnitudes p and the residual ρ(p) it leaves.

    Subclasses set the class attributes and implement :meth:`predict`; linear effects
    (ρ = X p) implement :meth:`columns` and set ``linear``; effects whose ρ does not depend
    on the velocity set ``applied_force``.

    Attributes
    ----------
    key : str
        Stable identifier, e.g. ``current``, ``linear.X_u``.
    family : str
        Group of alternatives, e.g. ``added_mass`` for the scale and the per-DOF versions.
    title : str
        The physical name shown to the user.
    params : tuple of str
        Names of the unknowns.
    units : tuple of str
    steps : tuple of float
        Typical resolution of each unknown: finite-difference step and solver scale.
    dofs : tuple of int
        Degrees of freedom the effect acts on directly.
    """

    key = ""
    family = ""
    title = ""
    params: tuple[str, ...] = ()
    units: tuple[str, ...] = ()
    steps: tuple[float, ...] = ()
    dofs: tuple[int, ...] = (0, 1, 2, 3, 4, 5)
    linear = False
    #: ρ does not depend on the velocity: the effect is a change of the applied force τ − ρ
    #: (or of g), which a free run can replay
    applied_force = False

    @property
    def k(self) -> int:
        """Number of unknowns."""
        return len(self.params)

    def available(self, data: GapData) -> str:
        """Empty when the effect can be tested on ``data``, else the reason it cannot."""
        return ""

    def starts(self, data: GapData) -> list[FloatArray]:
        """Starting points of the screening (a grid over a shape parameter)."""
        return [np.zeros(self.k)]

    def implausible(self, data: GapData, p: FloatArray) -> str:
        """Why magnitudes p do not describe this effect on these data (empty: they do)."""
        return ""

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Lower and upper bounds of p."""
        return np.full(self.k, -np.inf), np.full(self.k, np.inf)

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        """ρ(p) on the rows of ``ch`` (unfiltered), shape (n, 6)."""
        if self.linear:
            return np.asarray(self.columns(data, ch, p) @ p, dtype=float)
        raise NotImplementedError

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        """∂ρ/∂p at p, shape (n, 6, k): central differences unless overridden."""
        out = np.empty((len(ch), 6, self.k))
        lo, hi = self.bounds()
        for j in range(self.k):
            h = self.steps[j]
            a, b = p.copy(), p.copy()
            a[j], b[j] = max(p[j] - h, lo[j]), min(p[j] + h, hi[j])
            out[:, :, j] = (self.predict(data, ch, b) - self.predict(data, ch, a)) / (b[j] - a[j])
        return out

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        """Magnitude ± σ in physical words."""
        s = np.sqrt(np.abs(np.diag(cov)))
        return ", ".join(f"{n} = {v:.4g} ± {e:.2g} {u}".rstrip()
                         for n, v, e, u in zip(self.params, p, s, self.units, strict=True))

    def magnitude(self, p: FloatArray) -> dict[str, float]:
        """Named magnitudes (for tests, tables and the model file)."""
        return {n: float(v) for n, v in zip(self.params, p, strict=True)}

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        """How the effect enters the model: ``{'theta': {name: Δ}}``, ``{'cross': [...]}``,
        ``{'freq': [...]}``, ``{'M': ΔM (6×6)}``, ``{'terms': {switch: bool}}`` (added-mass
        switches) and/or ``{'extra': {...}}``."""
        return {"extra": self.magnitude(p)}



class LinearEffect(Effect):
    """ρ = X(ν, ν̇, τ, η) p, exactly linear."""

    linear = True

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        """X on the rows of ``ch``, shape (n, 6, k)."""
        raise NotImplementedError


class Current(Effect):
    """Ocean current constant in NED: the damping acts on ν_r = ν − [Rᵀ v_c; 0].

    With M_A ν̇_r in the true equation and ν̇_c = −ω × Rᵀ v_c for a constant NED current,

        ρ = C_A(ν_r)ν_r − C_A(ν)ν + D(ν_r)ν_r − D(ν)ν − M_A ν̇_c,

    the added-mass terms acting as the vehicle's switches say (no M_A ν̇_c without the
    inertial term, no C_A without the Coriolis term, C_A without Munk moments without them).

    Horizontal by default (north, east; m/s); ``vertical`` adds the down component.
    Memory states (if the model has them) are left out of the difference.
    """

    key = "current"
    family = "current"
    title = "ocean current (constant in NED, damping on the relative velocity)"
    dofs = (0, 1, 2, 5)

    def __init__(self, vertical: bool = False) -> None:
        self.params = ("v_north", "v_east", "v_down")[:3 if vertical else 2]
        self.units = ("m/s",) * self.k
        self.steps = (0.02,) * self.k

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        vc = np.zeros(3)
        vc[:self.k] = p
        vcb = np.einsum("nji,j->ni", ch.R, vc)  # Rᵀ v_c
        nu_c = np.concatenate([vcb, np.zeros_like(vcb)], axis=1)
        nu_r = ch.nu - nu_c
        nu_c_dot = np.concatenate([-np.cross(ch.nu[:, 3:], vcb), np.zeros_like(vcb)], axis=1)
        b = data.body
        out = (b.added_coriolis_force(nu_r) - b.added_coriolis_force(ch.nu)
               + data.damping_force(nu_r) - data.damping_force(ch.nu))
        if b.added_mass_terms.inertial:
            out -= nu_c_dot @ data.M_A.T
        return np.asarray(out, dtype=float)

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        m = self.magnitude(p)
        speed, heading = m["speed"], m["direction_deg"]
        # σ of speed and direction by linear propagation from the north/east covariance
        n, e = float(p[0]), float(p[1])
        C = cov[:2, :2]
        g_s = np.array([n, e]) / max(speed, 1e-12)
        g_d = np.degrees(np.array([-e, n]) / max(speed**2, 1e-24))
        s_s = float(np.sqrt(max(float(g_s @ C @ g_s), 0.0)))
        s_d = float(np.sqrt(max(float(g_d @ C @ g_d), 0.0)))
        text = (f"{speed:.3f} ± {s_s:.2g} m/s towards {heading:.1f}° ± {s_d:.2g}° "
                f"(north {n:+.3f}, east {e:+.3f} m/s)")
        if self.k == 3:
            text += f", down {float(p[2]):+.3f} m/s"
        return text

    def magnitude(self, p: FloatArray) -> dict[str, float]:
        out = super().magnitude(p)
        out["speed"] = float(np.hypot(p[0], p[1]))
        out["direction_deg"] = float(np.degrees(np.arctan2(p[1], p[0])) % 360.0)
        return out

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        vc = np.zeros(3)
        vc[:self.k] = p
        return {"extra": {"current_ned": [float(x) for x in vc]}}


class Buoyancy(LinearEffect):
    """Buoyancy minus weight differs by ΔB (N, positive: lighter in water than believed).

    The extra buoyancy acts upwards at the centre of buoyancy r_b:
    ρ = ΔB [Rᵀe_z; r_b × Rᵀe_z].
    """

    applied_force = True
    key = "buoyancy"
    family = "buoyancy"
    title = "buoyancy/weight offset (net buoyancy differs)"
    params = ("delta_B",)
    units = ("N",)
    steps = (0.5,)
    dofs = (2,)

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        d = ch.down
        return np.concatenate([d, np.cross(data.body.r_b, d)], axis=1)[:, :, None]

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        s = float(np.sqrt(abs(cov[0, 0])))
        word = "lighter" if p[0] > 0 else "heavier"
        grams = abs(float(p[0])) / 9.81 * 1000
        return f"ΔB = {float(p[0]):+.3g} ± {s:.2g} N ({word} in water by {grams:.0f} g)"

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"extra": {"buoyancy_offset": float(p[0])}}



class CGOffset(Effect):
    """Centre of gravity offset δ (m, FRD) from the believed r_g.

    Changes the restoring moment −δ × W Rᵀe_z and, through M_RB, the rigid-body inertia and
    Coriolis forces: ρ = ΔM_RB ν̇ + ΔC_RB(ν)ν + Δg(η). (A centre-of-buoyancy offset of
    −(W/B) δ gives the same restoring moment without the inertia change.)
    """

    key = "cg_offset"
    family = "cg_offset"
    title = "centre of gravity offset (restoring moment)"
    params = ("dx", "dy", "dz")
    units = ("m", "m", "m")
    steps = (0.002, 0.002, 0.002)
    dofs = (3, 4)

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        b = data.body
        M1 = rigid_body_mass(b.mass, b.inertia, b.r_g + p)
        dM = M1 - data.M_RB
        d = ch.down
        out = ch.nu_dot @ dM.T + coriolis_force(M1, ch.nu) - coriolis_force(data.M_RB, ch.nu)
        # Δg(η) = −[0; δ × f_g] with f_g = W Rᵀe_z
        out[:, 3:] -= np.cross(p, b.weight * d)
        return np.asarray(out, dtype=float)

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        s = np.sqrt(np.abs(np.diag(cov)))
        return "δ = [" + ", ".join(f"{1e3 * v:+.2f} ± {1e3 * e:.2g}" for v, e in
                                   zip(p, s, strict=True)) + "] mm (FRD)"

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"extra": {"cg_offset": [float(x) for x in p]}}


class ThrustGain(LinearEffect):
    """Actual thrust = (1 + ε) × logged thrust: ρ = −ε τ."""

    applied_force = True
    key = "thrust_gain"
    family = "thrusters"
    title = "thrust-gain error (actual thrust = (1 + ε) × logged)"
    params = ("epsilon",)
    units = ("",)
    steps = (0.01,)

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        return -ch.tau[:, :, None]

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        return (f"ε = {100 * float(p[0]):+.2f} ± {100 * float(np.sqrt(abs(cov[0, 0]))):.2g} % "
                "of the logged thrust")

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"extra": {"thrust_gain_error": float(p[0])}}



class Delay(Effect):
    """The vehicle feels the logged thrust d seconds late: ρ = τ(t) − τ(t − d)."""

    applied_force = True
    key = "delay"
    family = "thrusters"
    title = "time delay τ → ν (thrust acts later than logged)"
    params = ("delay",)
    units = ("s",)
    steps = (0.01,)
    grid = (0.03, 0.08, 0.14, 0.22, 0.32, 0.45)

    def starts(self, data: GapData) -> list[FloatArray]:
        return [np.array([d]) for d in self.grid]

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        return np.zeros(1), np.ones(1)

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        # τ(t − d) by a band-limited (Fourier) fractional shift of the mirrored chunk, so
        # that ρ is smooth in d (linear interpolation has a kink at every sample period)
        n = len(ch)

        def spectrum() -> tuple[FloatArray, NDArray[np.complex128]]:
            ext = np.concatenate([ch.tau, ch.tau[::-1]], axis=0)
            return (np.asarray(np.fft.rfftfreq(2 * n, d=1.0 / data.rate), dtype=float),
                    np.fft.rfft(ext, axis=0))

        f, spec = data.memo(("tau_spectrum", ch.rows.start, ch.rows.stop), spectrum)
        shift = np.exp(-2j * np.pi * f * float(p[0]))[:, None]
        delayed = np.fft.irfft(spec * shift, n=2 * n, axis=0)[:n]
        return np.asarray(ch.tau - delayed, dtype=float)

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        return (f"d = {1e3 * float(p[0]):.1f} ± {1e3 * float(np.sqrt(abs(cov[0, 0]))):.2g} ms")

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"extra": {"delay": float(p[0])}}



class DeadZone(Effect):
    """Rotors slower than n_dz (rev/s) give no thrust; the logged thrust does not know it.

    ρ = T_alloc f_lost, f_lost,j = logged thrust of thruster j while |n_j| < n_dz, resampled
    onto the samples the way the preprocessing resamples thrust (window centres, linear).
    Needs the logged rotor speeds (``thrusters/state`` of a bag).
    """

    applied_force = True
    key = "deadzone"
    family = "thrusters"
    title = "thruster dead-zone (no thrust at low rotor speed)"
    params = ("n_deadzone",)
    units = ("rev/s",)
    steps = (0.4,)
    grid = (1.5, 3.0, 4.5, 6.0, 8.0, 10.0, 13.0)

    def available(self, data: GapData) -> str:
        if data.joints is None or data.thrusters is None or len(data.joints) < 2:
            return "needs the logged rotor speeds (thrusters/state); CSV input has none"
        if not set(data.thrusters.names) <= set(data.joints.names):
            return "the logged thruster names do not match the vehicle's"
        return ""

    def starts(self, data: GapData) -> list[FloatArray]:
        return [np.array([g]) for g in self.grid]

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        return np.zeros(1), np.full(1, 30.0)

    def lost(self, data: GapData, n_dz: float) -> FloatArray:
        """τ lost in the dead-zone on every sample, shape (N, 6) (cached per n_dz)."""
        def table() -> FloatArray:
            j, th = data.joints, data.thrusters
            assert j is not None and th is not None
            order = [j.names.index(n) for n in th.names]
            n = j.velocity[:, order] / (2 * np.pi)
            f = np.where(np.abs(n) < n_dz, j.effort[:, order], 0.0)
            tau = f @ th.allocation.T
            window = float(np.median(np.diff(j.stamp)))
            tc = j.stamp - window / 2  # a message reports the mean over the window before it
            t = data.samples.t
            return np.stack([np.interp(t, tc, tau[:, i]) for i in range(6)], axis=1)

        out: FloatArray = data.memo(("deadzone", round(float(n_dz), 6)), table)
        return out

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        return self.lost(data, max(float(p[0]), 0.0))[ch.rows]

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        s = float(np.sqrt(abs(cov[0, 0])))
        return (f"n_dz = {float(p[0]):.2f} ± {s:.2g} rev/s ({60 * float(p[0]):.0f} rpm); "
                "no thrust below it")

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"extra": {"thruster_deadzone": float(p[0])}}



#: Ways an added-mass error can act: as the vehicle's switches say, or through one term only
ADDED_MASS_FORMS = ("acting", "inertial", "coriolis")


def _form_terms(terms: AddedMassTerms, form: str) -> AddedMassTerms:
    """The added-mass switches of a candidate's ``form`` on a vehicle with ``terms``.

    ``acting``: the vehicle's; ``inertial``: M_A ν̇ only; ``coriolis``: C_A(ν)ν only, with
    the vehicle's Munk switch when its Coriolis term acts, else with the Munk moments (the
    whole C_A, as gz-sim applies it).
    """
    if form == "acting":
        return terms
    if form == "inertial":
        return AddedMassTerms(inertial=True, coriolis=False, munk=False)
    return AddedMassTerms(inertial=False, coriolis=True,
                          munk=terms.munk or not terms.coriolis)


def _added_mass_force(M_A: FloatArray, terms: AddedMassTerms, ch: Chunk) -> FloatArray:
    """M_A ν̇ (if ``terms.inertial``) + the acting part of C_A(ν)ν, shape (n, 6)."""
    out = added_coriolis_force(M_A, terms, ch.nu)
    if terms.inertial:
        out = out + ch.nu_dot @ M_A.T
    return np.asarray(out, dtype=float)


def _form_available(terms: AddedMassTerms, form: str, acting_key: str) -> str:
    """Why an added-mass ``form`` is not a separate candidate on a vehicle with ``terms``."""
    t = _form_terms(terms, form)
    if not (t.inertial or t.coriolis):
        return "the vehicle's added-mass switches turn every added-mass effect off"
    if form != "acting" and t == terms:
        return f"the same as {acting_key} under the vehicle's added-mass switches"
    return ""


class AddedMassScale(LinearEffect):
    """M_A scaled by (1 + ε) in the terms of ``form``: ρ = ε × (those terms of M_A).

    ``acting``: the terms the vehicle's ``added_mass_terms`` switch on (M_A changes);
    ``inertial``: ε M_A ν̇ only; ``coriolis``: ε C_A(ν)ν only. The model file has one M_A for
    all its terms, so a one-term form is written as the nearest switch: the term acts
    (factor [on] + ε ≥ ½) or not; the factor itself is kept under ``model.gap``. A plant
    without the inertial term analysed with a model that has it shows ε ≈ −1 in the
    inertial form (MuJoCo's fluid model, gz-sim's ``disable_added_mass``).
    """

    family = "added_mass"
    params = ("epsilon",)
    units = ("",)
    steps = (0.02,)

    def __init__(self, form: str = "acting") -> None:
        if form not in ADDED_MASS_FORMS:
            raise ConfigError("form", f"unknown added-mass form {form!r}; use one of "
                              f"{ADDED_MASS_FORMS}")
        self.form = form
        self.key = "added_mass_scale" if form == "acting" else f"added_mass_{form}"
        self.title = {"acting": "added-mass error (all of M_A scaled)",
                      "inertial": "inertial added-mass error (M_A ν̇ scaled, C_A(ν)ν not)",
                      "coriolis": "added-mass Coriolis error (C_A(ν)ν scaled, M_A ν̇ not)",
                      }[form]

    def available(self, data: GapData) -> str:
        if not np.any(data.M_A):
            return "the model has no added mass to scale"
        return _form_available(data.body.added_mass_terms, self.form, "added_mass_scale")

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        t = _form_terms(data.body.added_mass_terms, self.form)
        return _added_mass_force(data.M_A, t, ch)[:, :, None]

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        what = {"acting": "M_A", "inertial": "M_A ν̇", "coriolis": "C_A(ν)ν"}[self.form]
        return (f"ε = {100 * float(p[0]):+.2f} ± {100 * float(np.sqrt(abs(cov[0, 0]))):.2g} % "
                f"of {what}")

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        if self.form == "acting":
            return {"M": float(p[0]) * data.M_A}
        terms = data.body.added_mass_terms
        factor = float(getattr(terms, self.form)) + float(p[0])
        on = factor >= 0.5
        switch = {self.form: on}
        if self.form == "coriolis":
            switch["munk"] = on and (terms.munk or not terms.coriolis)
        return {"terms": switch, "extra": {f"added_mass_{self.form}_factor": factor}}


class AddedMassDof(LinearEffect):
    """Added mass of one DOF wrong by Δm (kg or kg·m²), acting as the vehicle's switches say:
    ρ = Δm e_i ν̇_i (if inertial) + the acting part of C(Δm E_ii, ν)ν."""

    family = "added_mass"
    units = ("kg",)

    def __init__(self, dof: int) -> None:
        self.dof = dof
        n = DOF_NAMES[dof]
        self.key = f"added_mass.{n}"
        self.params = (f"{FORCE_NAMES[dof]}_{n}dot",)
        self.title = f"added-mass error in {n} ({self.params[0]}, ∝ {n}̇)"
        self.units = ("kg",) if dof < 3 else ("kg·m²",)
        self.steps = (0.5,) if dof < 3 else (0.01,)
        self.dofs = (dof,)

    def available(self, data: GapData) -> str:
        return _form_available(data.body.added_mass_terms, "acting", self.key)

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        E = np.zeros((6, 6))
        E[self.dof, self.dof] = 1.0
        return _added_mass_force(E, data.body.added_mass_terms, ch)[:, :, None]

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        return (f"Δ{self.params[0]} = {float(p[0]):+.4g} ± {float(np.sqrt(abs(cov[0, 0]))):.2g} "
                f"{self.units[0]}")

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        E = np.zeros((6, 6))
        E[self.dof, self.dof] = float(p[0])
        return {"M": E}


class Coefficient(LinearEffect):
    """A damping coefficient of one DOF missing or wrong: linear (ν_i) or quadratic (|ν_i|ν_i).

    ρ = Δθ α(ν) ν_i e_i with α = 1 (e.g. X_u) or |ν_i| (e.g. X_uu).
    """

    family = "damping"

    def __init__(self, dof: int, quadratic: bool) -> None:
        self.dof = dof
        self.quadratic = quadratic
        n = DOF_NAMES[dof]
        self.name = f"{FORCE_NAMES[dof]}_{n}{n}" if quadratic else f"{FORCE_NAMES[dof]}_{n}"
        self.key = ("quadratic." if quadratic else "linear.") + self.name
        self.params = (self.name,)
        self.title = (f"{'quadratic' if quadratic else 'linear'} damping in {n} "
                      f"({self.name}, force ∝ {n + '|' + n + '|' if quadratic else n})")
        lin = dof < 3
        self.units = ((("N·s²/m²" if lin else "N·m·s²") if quadratic else
                       ("N·s/m" if lin else "N·m·s")),)
        self.steps = (1.0,) if lin else (0.05,)
        self.dofs = (dof,)

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        x = np.zeros((len(ch), 6, 1))
        v = ch.nu[:, self.dof]
        x[:, self.dof, 0] = np.abs(v) * v if self.quadratic else v
        return x

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        return (f"Δ{self.name} = {float(p[0]):+.4g} ± {float(np.sqrt(abs(cov[0, 0]))):.2g} "
                f"{self.units[0]}")

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"theta": {self.name: float(p[0])}}


class Cross(LinearEffect):
    """A cross-coupling damping coefficient, e.g. sway–yaw Y_v|r|: ρ = θ α(ν) ν_col e_row."""

    family = "damping"
    units = ("SI",)

    def __init__(self, spec: CrossSpec) -> None:
        self.spec = spec
        self._model = DampingModel([cross_term([spec])])
        self.key = f"cross.{spec.label}"
        self.params = (spec.label,)
        a = spec.alpha.label()
        self.title = (f"cross-coupling {spec.label} ({FORCE_NAMES[spec.row]} force ∝ "
                      f"{DOF_NAMES[spec.col]}{'' if a == '1' else '·' + a})")
        self.steps = (1.0,) if spec.row < 3 else (0.1,)
        self.dofs = (spec.row,)

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        return self._model.regressor(ch.nu)

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        return f"{self.spec.label} = {float(p[0]):+.4g} ± {float(np.sqrt(abs(cov[0, 0]))):.2g}"

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        s = self.spec
        return {"cross": [{"row": FORCE_NAMES[s.row], "col": DOF_NAMES[s.col],
                           "alpha": s.alpha.label(), "name": s.label, "value": float(p[0])}]}


class Memory(Effect):
    """Fluid memory in one DOF: K(t) = c e^{−λt}, ρ = c z e_i with ż = −λ z + ν_i.

    The states run over whole segments (from z = 0 at each segment start).
    """

    family = "memory"
    grid = (0.15, 0.3, 0.6, 1.2, 2.4, 4.8, 9.6)

    def __init__(self, dof: int) -> None:
        self.dof = dof
        n = DOF_NAMES[dof]
        self.key = f"memory.{n}"
        self.params = ("c", "lambda")
        self.title = f"fluid memory in {n} (force ∝ ν filtered by e^(−λt))"
        self.units = ("N/m" if dof < 3 else "N·m", "1/s")
        self.steps = (0.5 if dof < 3 else 0.05, 0.05)
        self.dofs = (dof,)

    def implausible(self, data: GapData, p: FloatArray) -> str:
        # the regression sees ν low-passed at the cutoff f_c: a kernel faster than
        # 2π f_c / 2 is indistinguishable from linear damping, one slower than the grid is a
        # trend or an offset
        fast = np.pi * data.cutoff if data.cutoff > 0 else 0.5 * np.pi * data.rate
        if float(p[1]) >= fast:
            return (f"λ = {float(p[1]):.3g} 1/s is faster than the regression resolves "
                    f"({fast:.3g} 1/s): that is linear damping, not memory")
        if float(p[1]) <= 1.05 * self.grid[0] / 2:
            return f"λ = {float(p[1]):.3g} 1/s: a trend or an offset, not memory"
        return ""

    def states(self, data: GapData, lam: float) -> FloatArray:
        """z for every sample at rate λ, shape (N,) (cached)."""
        def make() -> FloatArray:
            s = data.samples
            z = np.zeros(len(s))
            for sl in s.segments():
                z[sl] = filter_memory(s.t[sl], s.nu[sl, self.dof:self.dof + 1],
                                      np.array([lam]))[:, 0]
            return z

        out: FloatArray = data.memo(("memory", self.dof, round(float(lam), 9)), make)
        return out

    def starts(self, data: GapData) -> list[FloatArray]:
        return [np.array([0.0, lam]) for lam in self.grid]

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        return np.array([-np.inf, 0.05]), np.array([np.inf, 20.0])

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        out = np.zeros((len(ch), 6))
        out[:, self.dof] = float(p[0]) * self.states(data, float(p[1]))[ch.rows]
        return out

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        out = np.zeros((len(ch), 6, 2))
        lam, h = float(p[1]), self.steps[1] * float(p[1])
        out[:, self.dof, 0] = self.states(data, lam)[ch.rows]
        dz = (self.states(data, lam + h) - self.states(data, lam - h))[ch.rows] / (2 * h)
        out[:, self.dof, 1] = float(p[0]) * dz
        return out

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        s = np.sqrt(np.abs(np.diag(cov)))
        return (f"c = {float(p[0]):.4g} ± {s[0]:.2g} {self.units[0]}, λ = {float(p[1]):.3g} ± "
                f"{s[1]:.2g} 1/s (steady gain c/λ = {float(p[0] / p[1]):.3g})")

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"freq": [{"dof": DOF_NAMES[self.dof], "rate": float(p[1]), "c": float(p[0])}]}


class GyroBias(Effect):
    """Constant gyro bias b (rad/s, FRD): the logs hold ω + b, and the body-frame
    acceleration the preprocessing forms (Rᵀ d/dt(Rv) − ω × v) holds −b × v.

    ρ = M [b × v; 0] + F(ν − [0; b]) − F(ν), F(ν) = C(ν)ν + D(ν)ν (M and C_A acting as
    the vehicle's added-mass switches say).
    """

    key = "gyro_bias"
    family = "sensor_bias"
    title = "gyro bias (measured angular rate offset)"
    params = ("bias_p", "bias_q", "bias_r")
    units = ("rad/s",) * 3
    steps = (0.005,) * 3
    dofs = (3, 4, 5)

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        beta = np.concatenate([np.zeros(3), p])
        acc = np.zeros((len(ch), 6))
        acc[:, :3] = np.cross(p, ch.nu[:, :3])
        return np.asarray(acc @ data.body.M_inertial.T + data.static_force(ch.nu - beta)
                          - data.static_force(ch.nu), dtype=float)

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        s = np.sqrt(np.abs(np.diag(cov)))
        return "b_gyro = [" + ", ".join(f"{np.degrees(v):+.3f} ± {np.degrees(e):.2g}"
                                        for v, e in zip(p, s, strict=True)) + "] °/s (p, q, r)"

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"extra": {"gyro_bias": [float(x) for x in p]}}


class DvlBias(Effect):
    """Constant DVL velocity bias b (m/s, FRD) seen through the DVL/IMU fusion.

    The preprocessing fuses R v_dvl below the crossover f_c with the integrated IMU above it
    (:func:`dampest_ros.core.preprocess.fuse_velocity`), so the logged velocity and its
    derivative carry β = Rᵀ LP_c(R b) and β̇ = Rᵀ d/dt LP_c(R b) − ω × β (both → b and 0
    when the attitude changes slowly):

        ρ = −M [β̇; 0] + F(ν − [β; 0]) − F(ν),   F(ν) = C(ν)ν + D(ν)ν

    (M and C_A acting as the vehicle's added-mass switches say).
    """

    key = "dvl_bias"
    family = "sensor_bias"
    title = "DVL bias (measured velocity offset, fixed in the body)"
    params = ("bias_u", "bias_v", "bias_w")
    units = ("m/s",) * 3
    steps = (0.01,) * 3
    dofs = (0, 1, 2)

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        b_ned = np.einsum("nij,j->ni", ch.R, p)
        lp = zero_phase(b_ned, data.rate, data.crossover)
        lp_dot = zero_phase(b_ned, data.rate, data.crossover, derivative=True)
        beta = np.einsum("nji,nj->ni", ch.R, lp)
        beta_dot = np.einsum("nji,nj->ni", ch.R, lp_dot) - np.cross(ch.nu[:, 3:], beta)
        acc = np.concatenate([beta_dot, np.zeros_like(beta)], axis=1)
        shift = np.concatenate([beta, np.zeros_like(beta)], axis=1)
        return np.asarray(-acc @ data.body.M_inertial.T + data.static_force(ch.nu - shift)
                          - data.static_force(ch.nu), dtype=float)

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        s = np.sqrt(np.abs(np.diag(cov)))
        return "b_dvl = [" + ", ".join(f"{v:+.4f} ± {e:.2g}" for v, e in
                                       zip(p, s, strict=True)) + "] m/s (u, v, w)"

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"extra": {"dvl_bias": [float(x) for x in p]}}


def library(names: Sequence[str] | None = None) -> list[Effect]:
    """The candidate effects, all or those whose key or family is in ``names``.

    Parameters
    ----------
    names : sequence of str, optional
        Keys (``current``, ``linear.X_u``, ``cross.Y_vr``, ``memory.u``…) or families
        (``current``, ``buoyancy``, ``cg_offset``, ``thrusters``, ``added_mass``,
        ``damping``, ``memory``, ``sensor_bias``) or ``all``.

    Returns
    -------
    list of Effect
    """
    effects: list[Effect] = [Current(), Buoyancy(), CGOffset(), ThrustGain(), DeadZone(),
                             Delay()]
    effects += [AddedMassScale(form) for form in ADDED_MASS_FORMS]
    effects += [AddedMassDof(i) for i in range(6)]
    effects += [Coefficient(i, q) for i in range(6) for q in (False, True)]
    effects += [Cross(CrossSpec.from_dict(c)) for c in DEFAULT_CROSS]
    effects += [Memory(i) for i in (0, 1, 2, 5)]
    effects += [GyroBias(), DvlBias()]
    if names is None or "all" in names:
        return effects
    wanted = set(names)
    chosen = [e for e in effects if e.key in wanted or e.family in wanted]
    known = {e.key for e in effects} | {e.family for e in effects}
    unknown = wanted - known
    if unknown:
        raise ConfigError("candidates", f"unknown {sorted(unknown)}; use 'all', a family "
                          f"{sorted({e.family for e in effects})} or a key such as "
                          f"{[e.key for e in effects[:8]]}")
    return chosen


# --- screening and fitting ------------------------------------------------------------------


@dataclass
class Screen:
    """One candidate screened against the current residual.

    Attributes
    ----------
    effect : Effect
    p : ndarray, shape (k,)
        Magnitudes fitted on the training part (linearised model).
    rss_train, rss_test : ndarray, shape (6,)
        Residual sums of squares per DOF after the fit.
    heldout : float
        Held-out reduction of the weighted residual sum of squares (0..1).
    heldout_dof : ndarray, shape (6,)
        Held-out reduction per DOF.
    gain : float
        Held-out log-likelihood gain ½ n_eff Σ_i log(RSS_i,before / RSS_i,after).
    dbic : float
        BIC change on the training part (negative: evidence for the effect).
    err : float
        Error-reduction ratio on the training part (weighted).
    relevance : float
        Held-out RMS of the force the effect explains, as a share of the force scale of its
        DOF (:attr:`GapData.force_scale`), largest over DOFs.
    significant : bool
    note : str
        Why the fitted magnitudes do not describe the effect (then not significant).
    """

    effect: Effect
    p: FloatArray
    rss_train: FloatArray
    rss_test: FloatArray
    heldout: float
    heldout_dof: FloatArray
    gain: float
    dbic: float
    err: float
    relevance: float
    significant: bool = False
    note: str = ""

    def score(self, n_eff: float) -> float:
        """Held-out evidence for ranking: the gain less ½ k log n_eff (parsimony)."""
        return self.gain - 0.5 * self.effect.k * float(np.log(max(n_eff, 2.0)))


@dataclass
class Step:
    """One accepted effect and the state of the model after it.

    Attributes
    ----------
    effect : Effect
    screen : Screen
        The screening result that chose it.
    p : ndarray, shape (k,)
        Magnitudes after the exact refit (all added effects refitted jointly).
    cov : ndarray, shape (k, k)
        Block-robust covariance of p.
    rms_before, rms_after : ndarray, shape (6,)
        Held-out residual RMS per DOF before and after the step (N, N·m).
    bic_before, bic_after : float
        BIC of the training part (n_eff Σ_i log(RSS_i/N) + k log n_eff).
    runner_up : str
        Title of the second-best candidate (what it competed with).
    """

    effect: Effect
    screen: Screen
    p: FloatArray
    cov: FloatArray
    rms_before: FloatArray
    rms_after: FloatArray
    bic_before: float
    bic_after: float
    runner_up: str = ""

    @property
    def description(self) -> str:
        """The magnitude in words."""
        return self.effect.describe(self.p, self.cov)

    @property
    def reduction(self) -> FloatArray:
        """Held-out RMS reduction per DOF (0..1), shape (6,)."""
        return np.asarray(1.0 - self.rms_after / np.maximum(self.rms_before, 1e-300))


@dataclass
class GapResult:
    """Outcome of :func:`find_gap`.

    Attributes
    ----------
    steps : list of Step
    effects : list of (Effect, ndarray)
        The added effects with their final (jointly refitted) magnitudes.
    covs : list of ndarray
        Their covariances.
    r0 : ndarray, shape (N, 6)
        Residual of the believed model.
    r : ndarray, shape (N, 6)
        Residual after the added effects.
    screens : list of list of Screen
        All screening results of every round (the last round found nothing significant).
    skipped : dict of str to str
        Candidates that could not be tested, with the reason.
    conclusion : str
    rejected : dict of str to str
        Significant candidates that were not added, with the reason of their last rejection
        (:func:`rejection`).
    """

    steps: list[Step]
    effects: list[tuple[Effect, FloatArray]]
    covs: list[FloatArray]
    r0: FloatArray
    r: FloatArray
    screens: list[list[Screen]] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)
    conclusion: str = NO_FURTHER
    rejected: dict[str, str] = field(default_factory=dict)

    @property
    def named(self) -> list[str]:
        """Keys of the effects named, in order."""
        return [s.effect.key for s in self.steps]


@dataclass(frozen=True)
class GapOptions:
    """Thresholds of the search.

    Attributes
    ----------
    min_heldout : float
        Smallest held-out reduction of the weighted residual sum of squares (share).
    min_heldout_dof : float
        Smallest held-out reduction of the residual sum of squares in the best DOF.
    min_bic : float
        Smallest BIC decrease on the training part (10: "very strong" evidence).
    min_relevance : float
        Smallest held-out force the effect explains in some DOF, as a share of that DOF's
        force scale: effects far below the force level are real but do not matter (e.g. the
        drift of a gyro's bias within its specification).
    max_steps : int
    max_tries : int
        Significant candidates tried per round before the search stops (each is refitted
        and may be rejected, :func:`rejection`).
    refit_nfev : int
        Function evaluations of the exact refit.
    """

    min_heldout: float = 0.03
    min_heldout_dof: float = 0.10
    min_bic: float = 10.0
    min_relevance: float = 0.0025
    max_steps: int = 6
    max_tries: int = 6
    refit_nfev: int = 30


def _bind(fn: Callable[[GapData, Chunk, FloatArray], FloatArray], data: GapData,
          p: FloatArray) -> Callable[[Chunk], FloatArray]:
    """Chunk → fn(data, chunk, p)."""
    def call(ch: Chunk) -> FloatArray:
        return fn(data, ch, p)
    return call


def _weights(r: FloatArray, mask: BoolArray) -> FloatArray:
    """Per-DOF weights 1/σ_i² from the residual on ``mask`` rows, shape (6,)."""
    return np.asarray(1.0 / np.maximum(np.mean(r[mask] ** 2, axis=0), 1e-12))


def _lsq(X: FloatArray, y: FloatArray, w: FloatArray) -> FloatArray:
    """Weighted least squares Σ_n Σ_i w_i (y_ni − X_ni p)², minimum-norm for zero columns.

    Parameters
    ----------
    X : ndarray, shape (n, 6, k)
    y : ndarray, shape (n, 6)
    w : ndarray, shape (6,)
    """
    A = np.einsum("nik,nil,i->kl", X, X, w)
    b = np.einsum("nik,ni,i->k", X, y, w)
    d = np.sqrt(np.maximum(np.diag(A), 0.0))
    ok = d > 1e-9 * max(float(d.max()), 1e-300)
    p = np.zeros(X.shape[2])
    if ok.any():
        s = 1.0 / d[ok]
        As = A[np.ix_(ok, ok)] * np.outer(s, s)
        p[ok] = s * linalg.lstsq(As, s * b[ok], cond=1e-10)[0]
    return p


def _bic(rss: FloatArray, n: float, n_eff: float, k: int) -> float:
    """n_eff Σ_i log(RSS_i / n) + k log n_eff."""
    return float(n_eff * np.sum(np.log(np.maximum(rss, 1e-300) / n)) + k * np.log(n_eff))


def screen(data: GapData, effect: Effect, r: FloatArray, w: FloatArray,
           opts: GapOptions) -> Screen:
    """Fit ``effect``'s linearisation to the residual on the training part; score it on the
    held-out part.

    For each starting point p0 (:meth:`Effect.starts`) the residual is regressed on
    ρ(p0) + J(p0) Δp; the start with the smallest weighted training residual wins.

    Parameters
    ----------
    data : GapData
    effect : Effect
    r : ndarray, shape (N, 6)
        Current residual (N, N·m).
    w : ndarray, shape (6,)
        Per-DOF weights 1/σ².
    opts : GapOptions

    Returns
    -------
    Screen
    """
    tr, te = data.train, data.test
    best: tuple[float, FloatArray, FloatArray] | None = None
    for p0 in effect.starts(data):
        off = np.zeros_like(r) if effect.linear else \
            data.filtered(_bind(effect.predict, data, p0))
        X = data.filtered(_bind(effect.columns, data, p0))
        dp = _lsq(X[tr], (r - off)[tr], w)
        e = r - off - X @ dp
        cost = float(np.sum(w * np.sum(e[tr] ** 2, axis=0)))
        if best is None or cost < best[0]:
            best = (cost, p0 + dp, e)
    assert best is not None
    _, p, e = best
    lo, hi = effect.bounds()
    p = np.clip(p, lo, hi)
    before_tr = np.sum(r[tr] ** 2, axis=0)
    before_te = np.sum(r[te] ** 2, axis=0)
    rss_tr = np.sum(e[tr] ** 2, axis=0)
    rss_te = np.sum(e[te] ** 2, axis=0)
    heldout = 1.0 - float(w @ rss_te / (w @ before_te))
    heldout_dof = 1.0 - rss_te / np.maximum(before_te, 1e-300)
    gain = 0.5 * data.n_eff_test * float(np.sum(np.log(np.maximum(before_te, 1e-300)
                                                        / np.maximum(rss_te, 1e-300))))
    n_tr = float(tr.sum())
    dbic = _bic(rss_tr, n_tr, data.n_eff_train, effect.k) - _bic(before_tr, n_tr,
                                                                 data.n_eff_train, 0)
    err = 1.0 - float(w @ rss_tr / (w @ before_tr))
    explained = np.sqrt(np.mean((r - e)[te] ** 2, axis=0))
    relevance = float(np.max(explained / np.maximum(data.force_scale, 1e-300)))
    note = effect.implausible(data, p)
    sig = (heldout >= opts.min_heldout and float(heldout_dof.max()) >= opts.min_heldout_dof
           and dbic <= -opts.min_bic and relevance >= opts.min_relevance and not note)
    return Screen(effect, p, rss_tr, rss_te, heldout, heldout_dof, gain, dbic, err, relevance,
                  sig, note)


def correction(data: GapData, effects: Sequence[tuple[Effect, FloatArray]]) -> FloatArray:
    """Σ_e ρ_e(p_e), low-passed like the regression, shape (N, 6)."""
    out = np.zeros((len(data.samples), 6))
    if not effects:
        return out

    def total(ch: Chunk) -> FloatArray:
        return np.asarray(np.sum([e.predict(data, ch, p) for e, p in effects], axis=0),
                          dtype=float)

    return out + data.filtered(total)


def refit(data: GapData, effects: Sequence[tuple[Effect, FloatArray]], w: FloatArray,
          max_nfev: int = 30, reweight: int = 2) -> tuple[list[FloatArray], list[FloatArray]]:
    """Refit the magnitudes of all ``effects`` jointly on their exact models.

    Minimises Σ_train Σ_i w_i (r0 − Σ_e ρ_e(p_e))² with ``scipy.optimize.least_squares``
    (trust region, analytic columns for linear effects, central differences otherwise), then
    a block-robust covariance A⁻¹ (Σ_b s_b s_bᵀ) A⁻¹ of the magnitudes, blocks of
    ``data.block`` seconds (the residuals are correlated by the low-pass). The per-DOF
    weights start at ``w`` and are re-estimated ``reweight`` times from the residual the
    effects leave, so that they reflect the noise rather than the gap being explained.

    Returns
    -------
    ps : list of ndarray
        Magnitudes per effect.
    covs : list of ndarray
        Covariance per effect.
    """
    tr = data.train
    sizes = [e.k for e, _ in effects]
    cuts = np.cumsum(sizes)[:-1]
    x0 = np.concatenate([p for _, p in effects])
    lo = np.concatenate([e.bounds()[0] for e, _ in effects])
    hi = np.concatenate([e.bounds()[1] for e, _ in effects])
    # strictly inside finite bounds (least_squares' trust region needs an interior start)
    fin_lo, fin_hi = np.isfinite(lo), np.isfinite(hi)
    inner_lo, inner_hi = lo.copy(), hi.copy()
    inner_lo[fin_lo] += 1e-9 * (1 + np.abs(lo[fin_lo]))
    inner_hi[fin_hi] -= 1e-9 * (1 + np.abs(hi[fin_hi]))
    x0 = np.minimum(np.maximum(x0, inner_lo), inner_hi)
    scale = np.concatenate([np.asarray(e.steps, dtype=float) for e, _ in effects])
    sw = np.sqrt(w)
    lin_cols = {i: data.filtered(_bind(e.columns, data, np.zeros(e.k)))
                for i, (e, _) in enumerate(effects) if e.linear}

    def split(x: FloatArray) -> list[tuple[Effect, FloatArray]]:
        return [(e, p) for (e, _), p in zip(effects, np.split(x, cuts), strict=True)]

    def resid(x: FloatArray) -> FloatArray:
        parts = split(x)
        rho = np.zeros_like(data.r0)
        nonlin = [(e, p) for e, p in parts if not e.linear]
        if nonlin:
            rho += correction(data, nonlin)
        for i, (_, p) in enumerate(parts):
            if i in lin_cols:
                rho += lin_cols[i] @ p
        return np.asarray(((data.r0 - rho)[tr] * sw).ravel(), dtype=float)

    def jac(x: FloatArray) -> FloatArray:
        cols = []
        for i, (e, p) in enumerate(split(x)):
            X = lin_cols[i] if i in lin_cols else data.filtered(_bind(e.columns, data, p))
            cols.append(-(X[tr] * sw[None, :, None]).reshape(-1, e.k))
        return np.concatenate(cols, axis=1)

    x = x0
    for _ in range(reweight + 1):
        res = optimize.least_squares(resid, x, jac=jac, bounds=(lo, hi), x_scale=scale,
                                     method="trf", max_nfev=max_nfev, xtol=1e-6, ftol=1e-8)
        x = res.x
        # per-DOF weights from the residual the effects leave (the noise, not the gap)
        w = _weights(resid(x).reshape(-1, 6) / sw, np.ones(int(tr.sum()), dtype=bool))
        sw = np.sqrt(w)
    # block-robust covariance on the training rows
    J = jac(x).reshape(int(tr.sum()), 6, -1) / -sw[None, :, None]
    e = resid(x).reshape(-1, 6) / sw
    A = np.einsum("nik,nil,i->kl", J, J, w)
    g = np.einsum("nik,ni,i->nk", J, e, w)
    blocks = data.block_index[tr]
    S = np.zeros((int(blocks.max()) + 1, len(x)))
    np.add.at(S, blocks - int(blocks.min()), g)
    S = S[np.any(S != 0, axis=1)]
    B = len(S)
    Ainv = linalg.pinv(A)
    cov = Ainv @ (S.T @ S * (B / max(B - 1, 1))) @ Ainv
    ps = list(np.split(x, cuts))
    idx = np.split(np.arange(len(x)), cuts)
    return ps, [cov[np.ix_(i, i)] for i in idx]


def _rms(r: FloatArray, mask: BoolArray) -> FloatArray:
    return np.asarray(np.sqrt(np.mean(r[mask] ** 2, axis=0)))


def find_gap(data: GapData, candidates: Sequence[Effect] | None = None,
             options: GapOptions | None = None,
             progress: Callable[[str], None] | None = None) -> GapResult:
    """Name the missing effects one at a time until none is significant.

    Each round: weights 1/σ_i² from the current residual on the training part; every
    candidate not yet added is screened (:func:`screen`); the significant ones
    are tried in order of their held-out log-likelihood gain, less ½ log n_eff per unknown:
    all added effects and the candidate are refitted jointly on their exact models
    (:func:`refit`), and the candidate is added unless :func:`rejection` finds a reason
    (a DOF's held-out residual grows, M would not be positive definite, D(ν) would generate
    energy), in which case the next one is tried (at most ``options.max_tries`` per round;
    a candidate rejected in one round is tried again in the next, when another effect may
    have taken the share of the residual it traded against). The held-out RMS per DOF
    before and after and the training BIC are recorded.

    Parameters
    ----------
    data : GapData
    candidates : sequence of Effect, optional
        Default: :func:`library`.
    options : GapOptions, optional
    progress : callable, optional
        Receives one line of text per step and per rejected candidate.

    Returns
    -------
    GapResult
    """
    opts = options or GapOptions()
    cands = list(candidates) if candidates is not None else library()
    skipped = {e.key: why for e in cands if (why := e.available(data))}
    cands = [e for e in cands if e.key not in skipped]
    added: list[tuple[Effect, FloatArray]] = []
    covs: list[FloatArray] = []
    steps: list[Step] = []
    screens: list[list[Screen]] = []
    rejected: dict[str, str] = {}
    r = data.r0.copy()
    tr, te = data.train, data.test
    n_tr = float(tr.sum())
    k_total = 0
    conclusion = NO_FURTHER
    while True:
        w = _weights(r, tr)
        done = {a.key for a, _ in added}
        round_ = [screen(data, e, r, w, opts) for e in cands if e.key not in done]
        round_.sort(key=lambda s: -s.score(data.n_eff_test))
        screens.append(round_)
        ok = [s for s in round_ if s.significant]
        if ok and len(steps) >= opts.max_steps:
            conclusion = (f"stopped after --max-steps {opts.max_steps}; "
                          f"{ok[0].effect.title} is still significant")
            break
        chosen = None
        for cand in ok[:opts.max_tries]:
            trial = [*added, (cand.effect, cand.p)]
            ps, cs = refit(data, trial, w, opts.refit_nfev)
            new = [(e, p) for (e, _), p in zip(trial, ps, strict=True)]
            r_new = data.r0 - correction(data, new)
            why = rejection(data, new, r, r_new, cand.effect.k, opts.min_relevance)
            if not why:
                chosen = cand, new, cs, r_new
                rejected.pop(cand.effect.key, None)
                break
            rejected[cand.effect.key] = why
            if progress:
                progress(f"rejected: {cand.effect.title}: {why}")
        if chosen is None:
            break
        best, new, cs, r_new = chosen
        if progress:
            progress(f"step {len(steps) + 1}: {best.effect.title} (held-out −"
                     f"{100 * best.heldout:.1f} %, ΔBIC {best.dbic:.0f})")
        bic_before = _bic(np.sum(r[tr] ** 2, axis=0), n_tr, data.n_eff_train, k_total)
        k_total += best.effect.k
        bic_after = _bic(np.sum(r_new[tr] ** 2, axis=0), n_tr, data.n_eff_train, k_total)
        runner = next((s.effect.title for s in round_ if s is not best), "")
        steps.append(Step(best.effect, best, new[-1][1], cs[-1], _rms(r, te), _rms(r_new, te),
                          bic_before, bic_after, runner))
        added, covs, r = new, cs, r_new
    return GapResult(steps, added, covs, data.r0, r, screens, skipped, conclusion, rejected)


def rejection(data: GapData, effects: Sequence[tuple[Effect, FloatArray]], r_before: FloatArray,
              r_after: FloatArray, k: int, min_change: float = GapOptions.min_relevance
              ) -> str:
    """Why the model with ``effects`` (the last one new) must not be accepted; empty if it may.

    Reasons, in this order:

    - a DOF's held-out residual grows: its mean square rises by more than the
      4 k / n_eff,train an effect with k unknowns fitted to noise alone is expected to add,
      and its RMS by more than ``min_change`` × the DOF's force scale (a change that does
      not matter, as in :attr:`GapOptions.min_relevance`) (an effect that is there lowers
      the residual of every DOF it acts on; one that trades a DOF against another
      describes a modelling error, not itself);
    - the updated M_RB + M_A is not symmetric positive definite (or M_A not positive
      semi-definite);
    - the updated D(ν) generates energy: νᵀD(ν)ν below the believed model's smallest value
      (and below 0) on the data or on a grid over the flown envelope
      (:meth:`GapData.power_points`), or a fluid-memory gain c < 0 (an active kernel).

    Parameters
    ----------
    data : GapData
    effects : sequence of (Effect, ndarray)
    r_before, r_after : ndarray, shape (N, 6)
        Residual before and after the step (N, N·m).
    k : int
        Unknowns of the new effect.
    min_change : float
        Smallest rise of a DOF's held-out RMS that counts, as a share of its force scale.
    """
    te = data.test
    ms0 = np.mean(r_before[te] ** 2, axis=0)
    ms1 = np.mean(r_after[te] ** 2, axis=0)
    worse = ((ms1 > ms0 * (1.0 + 4.0 * k / max(data.n_eff_train, 1.0)))
             & (np.sqrt(ms1) - np.sqrt(ms0) > min_change * data.force_scale))
    if worse.any():
        i = int(np.argmax(np.where(worse, ms1 / np.maximum(ms0, 1e-300), 0.0)))
        return (f"the held-out residual of {FORCE_NAMES[i]} grows (RMS "
                f"{np.sqrt(ms0[i]):.3g} → {np.sqrt(ms1[i]):.3g} {FORCE_UNITS[i]})")
    upd = updated_model(data, effects)
    try:
        upd.body(data)
    except ConfigError as exc:
        return f"the mass matrix would be invalid: {exc.field} {exc.reason}"
    return dissipation_violation(data, upd.model, upd.theta)


def dissipation_violation(data: GapData, model: DampingModel, theta: FloatArray) -> str:
    """Where ``model`` with ``theta`` generates energy and the believed model does not;
    empty if nowhere.

    νᵀD(ν)ν (static terms, W) is evaluated on :meth:`GapData.power_points`; the bound is the
    believed model's smallest value there when that is negative, else 0 (less 1e-9 of the
    believed model's largest |νᵀD(ν)ν| for rounding). Fluid-memory gains must be ≥ 0 (or not
    below the believed model's smallest).
    """
    pts = data.power_points
    P0 = data.model.dissipation(pts, data.theta)
    P = model.dissipation(pts, theta)
    floor = min(float(P0.min()), 0.0) - 1e-9 * max(float(np.abs(P0).max()), 1.0)
    if float(P.min()) < floor:
        j = int(np.argmin(P))
        nu = ", ".join(f"{n} {v:+.2g}" for n, v in zip(DOF_NAMES, pts[j], strict=True) if v)
        return (f"D(ν) would generate energy: νᵀD(ν)ν = {float(P[j]):.3g} W at ν = "
                f"({nu or 'rest'})")
    c0, c = data.model.memory_gain(data.theta), model.memory_gain(theta)
    c_floor = min(float(c0.min()) if c0.size else 0.0, 0.0)
    if c.size and float(c.min()) < c_floor:
        return f"a fluid-memory gain c = {float(c.min()):.3g} < 0 would generate energy"
    return ""


# --- localisation -----------------------------------------------------------------------------


@dataclass
class LocalRow:
    """Residual RMS per DOF in one subset of the data.

    Attributes
    ----------
    group : str
        ``all``, ``speed``, ``sign``, ``band``, ``time``, ``attitude`` or ``depth``.
    label : str
        The subset, e.g. ``|u| high``, ``0.05–0.2 Hz``, ``t 100–200 s``.
    share : float
        Share of the samples (or of the bandwidth) in the subset.
    rms : ndarray, shape (6,)
        Residual RMS per DOF in the subset (N, N·m).
    """

    group: str
    label: str
    share: float
    rms: FloatArray


BANDS = (0.0, 0.05, 0.2, 0.5, 1.0, 2.0)


def localise(samples: Samples, r: FloatArray, n_time: int = 6,
             bands: Sequence[float] = BANDS, passband: float = 0.0) -> list[LocalRow]:
    """Where the residual is: RMS per DOF by velocity regime, band, time, attitude, depth.

    Parameters
    ----------
    samples : Samples
    r : ndarray, shape (N, 6)
        Residual (N, N·m).
    n_time : int
        Number of equal time segments.
    bands : sequence of float
        Band edges (Hz) of the residual spectrum (Welch PSD per segment, averaged).
    passband : float
        Highest frequency the residual holds (the regression's low-pass, Hz); bands stop
        there and their ``share`` is their share of [0, passband]. 0: the Nyquist frequency.

    Returns
    -------
    list of LocalRow
        The first row is ``all``; in band rows ``rms`` is the band's RMS (√∫PSD df).
    """
    rows = [LocalRow("all", "all data", 1.0, _rms(r, np.ones(len(r), dtype=bool)))]
    nu = samples.nu
    for i, n in enumerate(DOF_NAMES):
        a = np.abs(nu[:, i])
        med = float(np.median(a))
        for label, m in ((f"|{n}| low (< {med:.2g})", a < med),
                         (f"|{n}| high (≥ {med:.2g})", a >= med)):
            if m.any():
                rows.append(LocalRow("speed", label, float(m.mean()), _rms(r, m)))
        for label, m in ((f"{n} > 0", nu[:, i] > 0), (f"{n} < 0", nu[:, i] < 0)):
            if m.any():
                rows.append(LocalRow("sign", label, float(m.mean()), _rms(r, m)))
    rate = samples.rate
    top = passband if 0 < passband < rate / 2 else rate / 2
    f, P = residual_psd(samples, r)
    edges = [b for b in bands if b < top] + [top]
    for lo, hi in itertools.pairwise(edges):
        m = (f >= lo) & (f < hi)
        df = float(f[1] - f[0]) if len(f) > 1 else 1.0
        rows.append(LocalRow("band", f"{lo:g}–{hi:g} Hz", (hi - lo) / top,
                             np.sqrt(np.sum(P[m], axis=0) * df)))
    t = samples.t
    cuts = np.linspace(t[0], t[-1] + 1e-9, n_time + 1)
    for a, b in itertools.pairwise(cuts):
        m = (t >= a) & (t < b)
        if m.any():
            rows.append(LocalRow("time", f"t {a - t[0]:.0f}–{b - t[0]:.0f} s", float(m.mean()),
                                 _rms(r, m)))
    for j, name in ((0, "roll"), (1, "pitch")):
        a = np.degrees(np.abs(samples.euler[:, j]))
        med = float(np.median(a))
        for label, m in ((f"|{name}| < {med:.0f}°", a < med), (f"|{name}| ≥ {med:.0f}°",
                                                                a >= med)):
            if m.any():
                rows.append(LocalRow("attitude", label, float(m.mean()), _rms(r, m)))
    d = samples.depth
    if np.isfinite(d).any():
        med = float(np.nanmedian(d))
        for label, m in ((f"depth < {med:.1f} m", d < med), (f"depth ≥ {med:.1f} m", d >= med)):
            if m.any():
                rows.append(LocalRow("depth", label, float(m.mean()), _rms(r, m)))
    return rows


def residual_psd(samples: Samples, r: FloatArray, mask: BoolArray | None = None,
                 window: float = 40.0) -> tuple[FloatArray, FloatArray]:
    """One-sided Welch PSD of r, averaged over segments (weighted by their length).

    Parameters
    ----------
    samples : Samples
    r : ndarray, shape (N, 6)
    mask : ndarray of bool, shape (N,), optional
        Rows to use (each contiguous run within a segment is one record).
    window : float
        Welch segment length (s).

    The mean is kept (no detrending): a constant offset (e.g. a buoyancy error) is part of
    the residual and belongs to the lowest band.

    Returns
    -------
    f : ndarray, shape (F,)
        Hz.
    P : ndarray, shape (F, 6)
        (N² or (N·m)²) per Hz.
    """
    rate = samples.rate
    keep = np.ones(len(r), dtype=bool) if mask is None else mask
    nper = max(16, min(round(window * rate), int(keep.sum())))
    f = np.fft.rfftfreq(nper, 1.0 / rate)
    P = np.zeros((len(f), 6))
    total = 0
    for sl in samples.segments():
        rows = np.flatnonzero(keep[sl]) + (sl.start or 0)
        n = len(rows)
        if n < nper or np.any(np.diff(rows) != 1):
            continue
        _, p = signal.welch(r[rows], fs=rate, nperseg=nper, axis=0, detrend=False)
        P += p * n
        total += n
    if total == 0:
        x = r[keep]
        _, p = signal.welch(x, fs=rate, nperseg=min(nper, len(x)), axis=0, detrend=False)
        f = np.fft.rfftfreq(min(nper, len(x)), 1.0 / rate)
        return np.asarray(f, dtype=float), np.asarray(p, dtype=float)
    return np.asarray(f, dtype=float), np.asarray(P / total, dtype=float)


def concentration(rows: Sequence[LocalRow], top: int = 3) -> list[tuple[int, str, float]]:
    """Per DOF, the subsets where the residual RMS is most above its overall RMS.

    Band rows are compared by RMS per unit bandwidth against the whole spectrum's.

    Returns
    -------
    list of (dof, label, ratio)
        ``top`` entries per DOF, largest ratio first.
    """
    total = rows[0].rms
    out = []
    for i in range(6):
        scored = []
        for row in rows[1:]:
            if row.group == "band":
                ratio = float(row.rms[i] / max(total[i], 1e-300) / np.sqrt(max(row.share,
                                                                                1e-12)))
            else:
                ratio = float(row.rms[i] / max(total[i], 1e-300))
            scored.append((ratio, row.label))
        scored.sort(reverse=True)
        out += [(i, label, ratio) for ratio, label in scored[:top]]
    return out


# --- the model with the effects ------------------------------------------------------------


@dataclass
class UpdatedModel:
    """The believed model with named effects added (:func:`updated_model`).

    Attributes
    ----------
    model : DampingModel
    theta : ndarray, shape (p',)
    M : ndarray, shape (6, 6)
        M_RB + M_A (kg, kg·m, kg·m²).
    M_A : ndarray, shape (6, 6)
        Its added mass.
    added_mass_terms : AddedMassTerms
        Which effects of M_A act.
    extra : dict
        The effects that are not part of the damping or the mass (current, buoyancy, …).
    """

    model: DampingModel
    theta: FloatArray
    M: FloatArray
    M_A: FloatArray
    added_mass_terms: AddedMassTerms
    extra: dict[str, Any]

    def body(self, data: GapData) -> RigidBody:
        """The believed rigid body with this M_A and these switches (ConfigError when M_A is
        not symmetric positive semi-definite or M not positive definite)."""
        b = data.body
        return RigidBody(b.mass, b.inertia, b.r_g, b.r_b, b.volume, self.M_A, b.rho, b.gravity,
                         self.added_mass_terms)


def _with_bases(old: DampingTerm | None, new: DampingTerm) -> DampingTerm:
    """``old`` (if any) with the bases of ``new`` appended."""
    return DampingTerm(new.kind, (old or new).meaning, (old.bases if old else []) + new.bases)


def updated_model(data: GapData, effects: Sequence[tuple[Effect, FloatArray]]) -> UpdatedModel:
    """The believed model with the named effects added.

    Damping coefficients change θ: a coefficient or cross-coupling the model already has
    (by name, in any of its terms) is updated by the effect's Δ; one it lacks is added to its
    term. Memory becomes a state (a state of the same DOF and rate is updated); added-mass
    errors change M or the added-mass switches; every other effect (current, buoyancy, CG,
    thrusters, delay, sensor bias) is returned in ``extra``.

    Returns
    -------
    UpdatedModel
    """
    values = dict(zip(data.model.parameter_names, data.theta.tolist(), strict=True))
    terms: dict[str, DampingTerm] = {t.kind: t for t in data.model.terms}
    M = data.body.M.copy()
    switches = data.body.added_mass_terms.as_dict()
    extra: dict[str, Any] = {}
    freq: dict[tuple[int, float], float] = {}
    old = terms.get("freq")
    if old is not None:
        freq = {(int(d), float(r)): values[n] for d, r, n in
                zip(old.state_dofs, old.rates, old.parameter_names, strict=True)}
    for e, p in effects:
        u = e.model_update(data, p)
        for name, d in u.get("theta", {}).items():
            if name not in values:
                dof = FORCE_NAMES.index(name.split("_")[0])
                quad = name.split("_")[1] == DOF_NAMES[dof] * 2
                kind = "quadratic" if quad else "linear"
                terms[kind] = _with_bases(terms.get(kind), quadratic_term([dof]) if quad
                                          else linear_term([dof]))
            values[name] = values.get(name, 0.0) + float(d)
        for c in u.get("cross", []):
            if c["name"] not in values:
                terms["cross"] = _with_bases(terms.get("cross"),
                                             cross_term([CrossSpec.from_dict(c)]))
            values[c["name"]] = values.get(c["name"], 0.0) + float(c["value"])
        for f in u.get("freq", []):
            key = (DOF_NAMES.index(f["dof"]), float(f["rate"]))
            freq[key] = freq.get(key, 0.0) + float(f["c"])
        if "M" in u:
            M = M + np.asarray(u["M"], dtype=float)
        switches.update(u.get("terms", {}))
        extra.update(u.get("extra", {}))
    if freq:
        rates: dict[str | int, list[float]] = {}
        for d, r in freq:
            rates.setdefault(d, []).append(r)
        mem = memory_term(rates)
        terms["freq"] = mem
        values.update({n: freq[(int(d), float(r))] for n, d, r in
                       zip(mem.parameter_names, mem.state_dofs, mem.rates, strict=True)})
    order = ("linear", "quadratic", "cross", "freq", "added", "residual")
    model = DampingModel([terms[k] for k in order if k in terms])
    theta = np.array([values.get(n, 0.0) for n in model.parameter_names])
    switches["munk"] = switches["munk"] and switches["coriolis"]
    return UpdatedModel(model, theta, M, M - data.M_RB, AddedMassTerms(**switches), extra)


# --- free run ----------------------------------------------------------------------------------


DOF_WORDS = ("surge", "sway", "heave", "roll", "pitch", "yaw")


def divergence_reason(model: DampingModel, theta: FloatArray, nu: FloatArray,
                      reach: float = 3.0, points: int = 400) -> str:
    """Why a free run of ``model`` can run away: a DOF whose steady damping force stops
    growing with speed.

    Along each DOF axis and sign, the steady force f(s) = ±[D(s e_i) s e_i]_i (memory
    states at their steady value ν/λ) is evaluated from rest to ``reach`` × the largest
    flown speed; where it peaks and then falls, a thrust above the peak has no steady speed.

    Parameters
    ----------
    model : DampingModel
    theta : ndarray, shape (p,)
    nu : ndarray, shape (N, 6)
        Flown velocities (m/s, rad/s).
    reach : float
    points : int

    Returns
    -------
    str
        E.g. ``diverges: Z_ww < 0 leaves no steady heave speed above 62 N``; empty when
        every axis' force grows with speed.
    """
    s = np.linspace(0.0, reach * max(float(np.abs(nu).max()), 1e-3), points)
    rates, dofs = model.memory_rates, model.memory_dofs
    for i in range(6):
        for sign in (1.0, -1.0):
            v = np.zeros((points, 6))
            v[:, i] = sign * s
            z = v[:, dofs] / rates if len(rates) else None
            f = sign * model.force(v, theta, z)[:, i]
            k = int(np.argmax(f))
            if k == points - 1 and f[1] >= 0:
                continue
            Phi = model.regressor(v[-1:], z[-1:] if z is not None else None)[0, i]
            names = [n for n, th, x in zip(model.parameter_names, theta, Phi, strict=True)
                     if th < 0 and x != 0]
            what = " and ".join(names) + " < 0" if names else "the damping"
            return (f"diverges: {what} leaves no steady {DOF_WORDS[i]} speed above "
                    f"{float(f[k]):.3g} {FORCE_UNITS[i]} ({'+' if sign > 0 else '−'}"
                    f"{DOF_NAMES[i]})")
    return ""


def free_run_errors(data: GapData, effects: Sequence[tuple[Effect, FloatArray]],
                    seconds: float = 120.0) -> dict[str, Any] | str:
    """Free-run velocity RMSE of the believed model and of the model with the effects.

    Uses :func:`dampest_ros.core.validate.free_run_error` when that module exists. The model
    with the effects has the changed damping terms, M and added-mass switches; effects that
    change the applied force (thrust gain, buoyancy, delay, dead-zone) enter as a corrected
    τ. Current, CG offset and sensor biases depend on the state and are not represented in
    the free run. A run that diverges has RMSE inf and a reason (:func:`divergence_reason`).

    Returns
    -------
    dict with ``nominal`` and ``final`` (RMSE per DOF, shape (6,)), ``seconds``,
    ``omitted`` (titles of effects left out) and ``notes`` (model → why its run diverged),
    or a string saying why it was skipped or failed.
    """
    try:
        validate = importlib.import_module("dampest_ros.core.validate")
        free_run_error = validate.free_run_error
        longest = validate.longest_segment
    except (ImportError, AttributeError):
        return "free run skipped: dampest_ros.core.validate.free_run is not available"
    s = data.samples
    rows = longest(s, seconds)
    upd = updated_model(data, effects)
    try:
        body = upd.body(data)
    except ConfigError as exc:
        return f"free run skipped: the corrected mass matrix is invalid ({exc})"
    dtau = np.zeros((len(s), 6))
    omitted = []
    for e, p in effects:
        if e.applied_force:
            # the applied force the vehicle felt: τ − ρ (ρ = what the effect left in r)
            dtau -= data.filtered(_bind(e.predict, data, p))
        elif e.model_update(data, p).keys() <= {"extra"}:
            omitted.append(e.title)
    # the filtered correction is applied to the sampled τ (which is not filtered at 2 Hz);
    # the difference is the correction's content above the cutoff, which is small
    fixed = Samples(s.t, s.nu, s.nu_dot, s.tau + dtau, s.euler, s.depth, s.segment)
    runs = {"believed": (s, data.model, data.body, data.theta),
            "with the named effects": (fixed, upd.model, body, upd.theta)}
    rmse: dict[str, FloatArray] = {}
    notes: dict[str, str] = {}
    with np.errstate(all="ignore"):
        for name, (smp, model, b, theta) in runs.items():
            try:
                rmse[name] = np.asarray(free_run_error(smp, model, b, theta, rows)["rmse"],
                                        dtype=float)
            except (ValueError, ArithmeticError, linalg.LinAlgError) as exc:
                return f"free run failed for the {name} model: {exc}"
            if not np.all(np.isfinite(rmse[name])):
                notes[name] = (divergence_reason(model, theta, s.nu[rows])
                               or "diverges (no single degree of freedom explains it)")
    return {"nominal": rmse["believed"], "final": rmse["with the named effects"],
            "seconds": float((rows.stop - rows.start) / s.rate), "omitted": omitted,
            "notes": notes}
