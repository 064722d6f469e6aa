"""The data of a gap analysis: the believed model and the measured samples, the residual
r = τ − (M ν̇ + C(ν)ν + D(ν)ν + g(η)) low-passed as the identification does, and the chunks of
samples the effects predict their residual on (FRD body, NED world, SI units)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.dissipative import envelope
from dampest_ros.core.identification.regression import iter_regression
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.frames import matrix_from_euler
from dampest_ros.core.physics.rigid_body import ConfigError, RigidBody
from dampest_ros.core.physics.thrusters import Thrusters
from dampest_ros.core.signals.measurements import JointSeries
from dampest_ros.core.signals.preprocess import zero_phase
from dampest_ros.core.signals.samples import CHUNK, Samples

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

FORCE_UNITS = ("N", "N", "N", "N·m", "N·m", "N·m")


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
    flown : ndarray, shape (2, 6), optional
        Smallest and largest velocity per DOF of the data the believed model was fitted on
        (:attr:`Model.flown <dampest_ros.core.identification.model.Model.flown>`; m/s,
        rad/s): where it is trusted. Default: the range of the measured ν.
    model_rmse : ndarray, shape (6,), optional
        The believed model's own residual RMS per DOF on the data it was fitted on (N, N·m):
        how well it predicts away from the very samples it was fitted on. Default: unknown
        (zero).
    """

    def __init__(self, samples: Samples, model: DampingModel, theta: FloatArray,
                 body: RigidBody, thrusters: Thrusters | None = None,
                 joints: JointSeries | None = None, cutoff: float = 2.0, split: float = 0.7,
                 chunk: int = CHUNK, margin: float = 5.0, block: float = 10.0,
                 crossover: float = 0.3, flown: FloatArray | None = None,
                 model_rmse: FloatArray | None = None) -> None:
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
        self.flown = np.array([samples.nu.min(axis=0), samples.nu.max(axis=0)]) \
            if flown is None else np.asarray(flown, dtype=float)
        if self.flown.shape != (2, 6):
            raise ConfigError("flown", f"needs shape (2, 6), got {self.flown.shape}")
        self.model_rmse = np.zeros(6) if model_rmse is None else \
            np.asarray(model_rmse, dtype=float)
        if self.model_rmse.shape != (6,) or not np.all(np.isfinite(self.model_rmse)):
            raise ConfigError("model_rmse", "needs 6 finite numbers")
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


def bind(fn: Callable[[GapData, Chunk, FloatArray], FloatArray], data: GapData,
         p: FloatArray) -> Callable[[Chunk], FloatArray]:
    """Chunk → fn(data, chunk, p)."""
    def call(ch: Chunk) -> FloatArray:
        return fn(data, ch, p)
    return call


def noise_weights(r: FloatArray, mask: BoolArray) -> FloatArray:
    """Per-DOF weights 1/σ_i² from the residual on ``mask`` rows, shape (6,)."""
    return np.asarray(1.0 / np.maximum(np.mean(r[mask] ** 2, axis=0), 1e-12))


def rms(r: FloatArray, mask: BoolArray) -> FloatArray:
    """RMS per DOF of the residual on the ``mask`` rows, shape (6,)."""
    return np.asarray(np.sqrt(np.mean(r[mask] ** 2, axis=0)))
