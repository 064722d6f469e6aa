"""The online estimator behind the estimator node: joins the sample streams by exact stamp,
builds the parallel-filtered regression
(:class:`~dampest_ros.core.online.regression.OnlineRegression`) and runs the RLS
(:class:`~dampest_ros.core.online.rls.least_squares.RecursiveLeastSquares`).

Inputs per sample stamp (integer nanoseconds, identical on the four streams): velocity ν,
acceleration ν̇ and wrench τ (FRD, SI) and the attitude for g(η) (the IMU orientation at the
sample instant, ROS order [x, y, z, w], FLU → ENU; converted through
:mod:`dampest_ros.core.physics.frames`). Samples are processed in chunks of ``chunk`` (the
regression is vectorised over a chunk; the RLS updates sample by sample).

The dampest/* topics carry the preprocessor's samples in that form
(:func:`~dampest_ros.core.signals.samples.wire_stamp`, :func:`attitude_quaternion`);
:meth:`OnlineEstimator.add_sample` feeds a sample exactly as it arrives through them, so that
an offline run (``dampest identify --method rls``) takes the nodes' code path number for
number.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.dissipative import project
from dampest_ros.core.identification.model import Model
from dampest_ros.core.online.regression import OnlineRegression
from dampest_ros.core.online.rls.least_squares import (
    OUTLIER_GATE,
    Diagnostics,
    RecursiveLeastSquares,
    RLSConfig,
)
from dampest_ros.core.online.sample import OnlineSample
from dampest_ros.core.physics import frames
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import DOF_NAMES, ConfigError
from dampest_ros.core.physics.vehicle import Vehicle, measured_wrench_scale
from dampest_ros.core.signals.samples import wire_stamp

FloatArray = NDArray[np.float64]

STREAMS = ("velocity", "acceleration", "wrench", "attitude")
#: Block length (s) over which the residual correlation that widens θ's standard deviation is
#: measured (:class:`~dampest_ros.core.online.rls.monitors.CorrelationFactor`): residuals stay
#: correlated over seconds (sensor-bias drift, model error).
CORRELATION_SECONDS = 5.0
_WIDTH = {"velocity": 6, "acceleration": 6, "wrench": 6, "attitude": 4}


@dataclass(frozen=True)
class EstimatorConfig:
    """Settings of :class:`OnlineEstimator`.

    Attributes
    ----------
    forgetting_factor : float
        λ in [0.9, 1].
    forgetting_mode : {'exponential', 'directional'}
    rate : float
        Sample rate of the streams (Hz).
    cutoff : float
        Parallel low-pass of y and Φ (Hz).
    chunk : int
        Samples processed at once.
    prior_scale : float
        Without a prior file: prior standard deviation = prior_scale × the parameter's
        scale (|nominal θ|, or the largest |θ| of its term when the nominal is 0).
    max_pending : float
        Partial samples (not all streams seen) older than this (s) are dropped.
    outlier_gate : float
        Squared Mahalanobis distance above which a raw sample is rejected
        (:class:`~dampest_ros.core.online.rls.monitors.OutlierGate`; ≤ 0: none). The gate opens
        after
        :data:`CORRELATION_SECONDS` of samples and its innovation variances average over
        twice that.
    dissipative : bool
        Publish the estimate projected onto νᵀD(ν)ν ≥ 0 over the flown envelope
        (:func:`~dampest_ros.core.identification.dissipative.project`), the constraint the batch fit
        imposes; the coefficients it moves are marked as not identified. False: the raw RLS
        estimate.
    """

    forgetting_factor: float = 0.999
    forgetting_mode: str = "exponential"
    rate: float = 50.0
    cutoff: float = 2.0
    chunk: int = 10
    prior_scale: float = 10.0
    max_pending: float = 1.0
    outlier_gate: float = OUTLIER_GATE
    dissipative: bool = True

    def __post_init__(self) -> None:
        RLSConfig(forgetting_factor=self.forgetting_factor,
                  forgetting_mode=self.forgetting_mode)  # validates both
        if not 0 < self.cutoff < 0.5 * self.rate:
            raise ConfigError("cutoff", f"must be in (0, rate/2), got {self.cutoff}")
        if self.chunk < 1:
            raise ConfigError("chunk", f"must be ≥ 1, got {self.chunk}")
        if self.prior_scale <= 0:
            raise ConfigError("prior_scale", "must be > 0")


def attitude_quaternion(euler: FloatArray) -> FloatArray:
    """The ROS orientation [x, y, z, w] (base_link FLU → odom ENU) of roll, pitch, yaw
    (FRD → NED, rad, shape (3,)); shape (4,), w ≥ 0."""
    q = frames.matrix_to_quat(frames.rotation(frames.matrix_from_euler(euler)))
    return np.asarray(q[[1, 2, 3, 0]], dtype=float)


def attitude_euler(q: FloatArray) -> FloatArray:
    """Roll, pitch, yaw (FRD → NED, rad, shape (..., 3)) of ROS orientations [x, y, z, w]
    (FLU → ENU, shape (..., 4)); the inverse of :func:`attitude_quaternion`."""
    R = frames.rotation(frames.quat_to_matrix(q[..., [3, 0, 1, 2]]))
    return np.asarray(frames.euler_from_matrix(R), dtype=float)


def restrict(model: DampingModel, theta: FloatArray, kinds: Sequence[str] | None
             ) -> tuple[DampingModel, FloatArray]:
    """The terms of ``model`` of the given kinds (None or empty: all), with their θ."""
    if not kinds:
        return model, np.asarray(theta, dtype=float)
    missing = [k for k in kinds if model.term(k) is None]
    if missing:
        raise ConfigError("terms", f"the vehicle has no {missing} term; it has {model.kinds}")
    sub = DampingModel([t for t in model.terms if t.kind in kinds])
    values = dict(zip(model.parameter_names, theta, strict=True))
    return sub, sub.theta_from_dict({n: values[n] for n in sub.parameter_names})


def nominal_of(structure: DampingModel, model: DampingModel, theta: FloatArray) -> FloatArray:
    """θ of ``structure``'s parameters taken by name from ``model``'s θ, 0 for a parameter
    ``model`` does not have (a selected term: nothing is known of it), shape (p,)."""
    values = dict(zip(model.parameter_names, np.asarray(theta, dtype=float), strict=True))
    return np.array([values.get(n, 0.0) for n in structure.parameter_names])


def parameter_scale(model: DampingModel, nominal: FloatArray) -> FloatArray:
    """|nominal θ_j|, or the largest |θ| of the same term when that is 0 (then 1), (p,)."""
    s = np.abs(np.asarray(nominal, dtype=float)).copy()
    for t in model.terms:
        sl = model.slice(t.kind)
        fill = float(s[sl].max()) if s[sl].size and s[sl].max() > 0 else 1.0
        s[sl] = np.where(s[sl] > 0, s[sl], fill)
    return s


class OnlineEstimator:
    """Stamp matching, regression and RLS for one vehicle.

    Parameters
    ----------
    vehicle : Vehicle
        Body (M, restoring) and the nominal damping (term structure, prior mean, scales).
    terms : sequence of str, optional
        Term kinds to identify (default: all of the vehicle's).
    config : EstimatorConfig, optional
    prior : tuple (names, theta, theta_std), optional
        Prior mean and standard deviation by name (a model file); parameters it does not
        name keep the default prior. A std of 0 or non-finite means the default.
    keep_samples : bool
        Keep every sample used in ``samples_log`` (to compare with the batch path).
    structure : DampingModel, optional
        The terms to identify instead of the vehicle's (e.g. a model file's, from a
        structure search); the vehicle's θ is the prior of the parameters it shares, 0 of
        the others.
    """

    def __init__(self, vehicle: Vehicle, terms: Sequence[str] | None = None,
                 config: EstimatorConfig | None = None,
                 prior: tuple[Sequence[str], FloatArray, FloatArray] | None = None,
                 keep_samples: bool = False, structure: DampingModel | None = None) -> None:
        self.vehicle = vehicle
        self.cfg = config or EstimatorConfig()
        if structure is None:
            self.model, self.nominal = restrict(vehicle.damping, vehicle.theta, terms)
        elif terms:
            raise ConfigError("terms", "give the term kinds or a structure, not both")
        else:
            self.model = structure
            self.nominal = nominal_of(structure, vehicle.damping, vehicle.theta)
        self.body = vehicle.body
        self.M = vehicle.body.M
        self.names = self.model.parameter_names
        scale = parameter_scale(self.model, self.nominal)
        theta0 = self.nominal.copy()
        std0 = self.cfg.prior_scale * scale
        if prior is not None:
            pn, pt, ps = prior
            for n, v, sd in zip(pn, np.asarray(pt, float), np.asarray(ps, float), strict=True):
                if n in self.names:
                    j = self.names.index(n)
                    theta0[j] = v
                    if np.isfinite(sd) and sd > 0:
                        std0[j] = sd
        self.prior_theta, self.prior_std = theta0, std0
        # weights: 1 % of the largest thrust per DOF as the noise level (the estimated noise
        # scales the reported uncertainty; see RLSConfig.adapt_weights). Without thrusters the
        # largest τ comes from the data: the RLS starts once the first CORRELATION_SECONDS of
        # samples are there, with the scale of their measured τ (until then it holds the prior)
        self._scale_from_data = vehicle.thrusters is None
        self.rls = self._make_rls(np.ones(6) if self._scale_from_data
                                  else vehicle.wrench_scale())
        self.regression = OnlineRegression(self.model, self.body, self.cfg.rate, self.cfg.cutoff)
        self.counts = {"velocity": 0, "acceleration": 0, "wrench": 0, "attitude": 0,
                       "matched": 0, "unmatched": 0, "rejected_nonfinite": 0,
                       "used": 0, "dropped_out_of_order": 0}
        self._pending: OrderedDict[int, dict[str, FloatArray]] = OrderedDict()
        self._ready: list[tuple[int, dict[str, FloatArray]]] = []
        self._last_matched = -1
        self.last_sample_t = math.nan
        self.keep_samples = keep_samples
        self.samples_log: list[OnlineSample] = []
        # per-DOF smallest and largest velocity of the samples used (m/s, rad/s)
        self.flown = np.array([np.full(6, np.inf), np.full(6, -np.inf)])
        self._published: tuple[FloatArray, FloatArray, dict[str, str]] | None = None

    def _make_rls(self, wrench_scale: FloatArray) -> RecursiveLeastSquares:
        """The RLS from the prior, with noise variances (1 % of ``wrench_scale``)², (6,)."""
        noise = tuple(float(x) for x in (0.01 * np.asarray(wrench_scale, dtype=float)) ** 2)
        # the least residual correlation (the floor of the measured one): white noise through
        # the parallel low-pass, rate / (2 · cutoff) samples per independent one (as the
        # batch path's AIC counts n_eff = 2 · cutoff · T)
        return RecursiveLeastSquares(self.prior_theta, self.prior_std**2, RLSConfig(
            forgetting_factor=self.cfg.forgetting_factor,
            forgetting_mode=self.cfg.forgetting_mode, noise_var=noise,
            correlation_block=max(1, round(CORRELATION_SECONDS * self.cfg.rate)),
            correlation_prior=max(1.0, self.cfg.rate / (2.0 * self.cfg.cutoff)),
            outlier_gate=self.cfg.outlier_gate,
            gate_warmup=max(1, round(CORRELATION_SECONDS * self.cfg.rate)),
            gate_window=max(1.0, 2.0 * CORRELATION_SECONDS * self.cfg.rate)))

    # --- inputs ------------------------------------------------------------------------

    def add(self, stream: str, stamp_ns: int, value: FloatArray) -> int:
        """One sample stream message (FRD, SI, shape (6,); attitude (4,) [x, y, z, w] FLU →
        ENU); returns the number of samples processed."""
        self.counts[stream] += 1
        v = np.asarray(value, dtype=float)
        if v.shape != (_WIDTH[stream],) or not np.all(np.isfinite(v)) or \
                (stream == "attitude" and float(v @ v) < 1e-12):
            self.counts["rejected_nonfinite"] += 1
            return 0
        if stamp_ns <= self._last_matched:
            self.counts["dropped_out_of_order"] += 1
            return 0
        entry = self._pending.setdefault(int(stamp_ns), {})
        entry[stream] = v
        if len(entry) == len(STREAMS):
            del self._pending[int(stamp_ns)]
            # everything older than a completed sample can no longer complete in order
            while self._pending and next(iter(self._pending)) < stamp_ns:
                self._pending.popitem(last=False)
                self.counts["unmatched"] += 1
            self._last_matched = int(stamp_ns)
            self.counts["matched"] += 1
            self._ready.append((int(stamp_ns), entry))
        else:
            limit = stamp_ns - int(self.cfg.max_pending * 1e9)
            while self._pending and next(iter(self._pending)) < limit:
                self._pending.popitem(last=False)
                self.counts["unmatched"] += 1
        return self.process()

    def add_sample(self, s: OnlineSample) -> int:
        """One preprocessor sample as the dampest/* topics deliver it: stamp rounded to the
        nanosecond, attitude as the ROS quaternion, unusable samples not sent (the
        preprocess node publishes only usable ones); returns the samples processed.

        The FLU ↔ FRD conversions on the way are sign changes, exact in floating point."""
        if not s.usable:
            return 0
        ns = wire_stamp(s.t)
        return (self.add("velocity", ns, s.nu) + self.add("acceleration", ns, s.nu_dot)
                + self.add("wrench", ns, s.tau)
                + self.add("attitude", ns, attitude_quaternion(s.euler)))

    # --- processing ----------------------------------------------------------------------

    def process(self, force: bool = False) -> int:
        """Run the regression and RLS on the ready samples (at least ``chunk`` of them, or
        all when ``force``); returns the number of samples used."""
        if not self._ready or (len(self._ready) < self.cfg.chunk and not force):
            return 0
        if self._scale_from_data:
            # no thrusters: wait for CORRELATION_SECONDS of samples, scale by their τ
            if len(self._ready) < CORRELATION_SECONDS * self.cfg.rate and not force:
                return 0
            tau = np.array([e["wrench"] for _, e in self._ready])
            before, self.rls = self.rls, self._make_rls(measured_wrench_scale(tau))
            self.rls.lam, self.rls.frozen = before.lam, before.frozen  # set meanwhile
            self._scale_from_data = False
        batch, self._ready = self._ready, []
        euler = attitude_euler(np.array([e["attitude"] for _, e in batch]))
        samples = [OnlineSample(stamp * 1e-9, e["velocity"], e["acceleration"], e["wrench"],
                                euler[k], math.nan, True)
                   for k, (stamp, e) in enumerate(batch)]
        if self.keep_samples:
            self.samples_log += samples
        # raw samples whose innovation the RLS finds implausible enter the filter as zeros
        T, Phi, y = self.regression.process(samples, self.rls.outliers)
        self.rls.update_many(Phi, y, T)
        self.counts["used"] += len(T)
        nu = np.array([s.nu for s in samples])
        self.flown = np.array([np.minimum(self.flown[0], nu.min(axis=0)),
                               np.maximum(self.flown[1], nu.max(axis=0))])
        if samples:
            self.last_sample_t = samples[-1].t
        return len(T)

    # --- state ---------------------------------------------------------------------------

    @property
    def theta(self) -> FloatArray:
        """Current estimate, shape (p,): the RLS estimate, projected onto the dissipativity
        constraint over the flown envelope unless the config says otherwise (the raw one is
        ``rls.theta``)."""
        return self._projection()[0]

    @property
    def constrained(self) -> dict[str, str]:
        """The coefficients the dissipativity constraint holds in :attr:`theta`, with the
        reason (empty when the RLS estimate is dissipative over the flown envelope)."""
        return self._projection()[1]

    @property
    def held(self) -> dict[str, str]:
        """The coefficients the data have not determined, with the reason: those of a DOF
        the samples do not excite (they stay at the prior) and those the dissipativity
        constraint holds (:attr:`constrained`)."""
        d = self.rls.diagnostics(condition=False)
        dof = self.rls.parameter_dof
        out = {n: f"not excited: the samples do not excite DOF {DOF_NAMES[dof[j]]}, so the "
                  "RLS estimate stays at its prior"
               for j, n in enumerate(self.names) if not d.excited[dof[j]]}
        return {**out, **self.constrained}

    def _projection(self) -> tuple[FloatArray, dict[str, str]]:
        """(θ, constrained) for the current RLS estimate, computed once per estimate."""
        raw = self.rls.theta
        if not self.cfg.dissipative or not np.all(np.isfinite(self.flown)):
            return raw, {}
        if self._published is None or not np.array_equal(self._published[0], raw):
            theta, why = project(raw, self.rls.P, self.model, self.flown)
            self._published = (raw.copy(), theta, why)
        return self._published[1], self._published[2]

    @property
    def theta_std(self) -> FloatArray:
        """Its standard deviations, shape (p,): the RLS sandwich standard deviation
        (:attr:`RecursiveLeastSquares.std`: the prior's at the start, then widened by the
        correlation of the residuals measured over blocks of :data:`CORRELATION_SECONDS`)."""
        return self.rls.std

    def reset(self) -> None:
        """Back to the prior: RLS, regression filters and pending samples."""
        self.rls.reset()
        self.regression.reset()
        self._pending.clear()
        self._ready.clear()
        self._last_matched = -1
        self.flown = np.array([np.full(6, np.inf), np.full(6, -np.inf)])

    def restart_clock(self) -> None:
        """Forget the stamps seen (after a clock jump), keep the estimate."""
        self._pending.clear()
        self._ready.clear()
        self._last_matched = -1
        self.regression.reset()

    def diagnostics(self) -> Diagnostics:
        """The RLS diagnostics (condition number included)."""
        return self.rls.diagnostics(condition=True)

    def diagnostic_values(self) -> dict[str, Any]:
        """Flat key → value summary for a DiagnosticArray."""
        d = self.diagnostics()
        out: dict[str, Any] = {
            "samples": d.samples, "condition_number": d.condition_number,
            "covariance_trace": d.covariance_trace, "change_alarm": d.alarm,
            "alarm_channels": ",".join(d.alarm_channels) or "none",
            "alarm_time": self.rls.alarm_time if self.rls.alarm_time is not None else "none",
            "unexcited": ",".join(d.unexcited) or "none",
            "forgetting_factor": self.rls.lam, "frozen": self.rls.frozen,
            "cusum_max": float(np.max(d.cusum)), "count.rejected_outliers": d.outliers,
        }
        kappa = self.rls.correlation.factor  # samples per independent sample
        for i, n in enumerate(DOF_NAMES):
            out[f"excitation.{n}"] = float(d.excitation[i])
            out[f"innovation_rms.{n}"] = float(d.innovation_rms[i])
            out[f"noise_std.{n}"] = float(d.noise_std[i])
            out[f"correlation.{n}"] = float(kappa[i])
        for k in self.counts:  # every message and drop counter
            out[f"count.{k}"] = self.counts[k]
        return out

    def model_extra(self, **extra: Any) -> dict[str, Any]:
        """Extra entries of the model file: provenance and health (``extra`` overrides or
        adds entries, e.g. ``source``)."""
        d = self.rls.diagnostics(condition=False)
        return {"source": "dampest estimator_node", "vehicle": self.vehicle.name,
                "samples": int(d.samples), "forgetting_factor": float(self.rls.lam),
                "unexcited": d.unexcited or ["none"], "change_alarm": bool(d.alarm), **extra}

    def to_model(self, version: int, **extra: Any) -> Model:
        """The current estimate as a :class:`~dampest_ros.core.identification.model.Model`: θ
        (projected when the config says so), its σ, the coefficients not identified (:attr:`held`),
        the body's mass matrix, added mass and switches, and :meth:`model_extra` (``extra``
        overrides or adds entries, e.g. ``source``)."""
        return Model(self.names, self.theta, self.theta_std, self.M, version, self.model,
                     self.model_extra(**extra), M_A=self.body.added_mass,
                     added_mass_terms=self.body.added_mass_terms, held=self.held,
                     identity=self.vehicle.identity)
