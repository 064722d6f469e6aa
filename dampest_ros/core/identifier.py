"""The damping estimator as one object, with the conventions of scikit-learn and pysindy:
``DampingIdentifier(vehicle, terms, method).fit(samples)`` for the batch path,
``partial_fit(samples)`` for the recursive one, ``predict`` for the damping force D(ν)ν and
``score`` for its per-DOF R²; the result in the attributes that end in ``_``.

- :meth:`DampingIdentifier.fit` is ``dampest identify``'s batch path: the vehicle's terms
  (:func:`~dampest_ros.core.online.estimator.restrict`), its nominal θ as the prior (the value of
  what the data do not determine), the speeds the thrusters reach for the speed-coverage check
  (:func:`~dampest_ros.core.simulation.excitation.speed_limits`),
  :func:`~dampest_ros.core.identification.batch.fit`.
- :meth:`DampingIdentifier.partial_fit` is the estimator node's path
  (:class:`~dampest_ros.core.online.estimator.OnlineEstimator`: parallel-filtered regression and
  recursive least squares with forgetting factor λ); successive calls continue the estimate.
- :meth:`DampingIdentifier.score` is ``dampest identify --holdout``'s score
  (:func:`~dampest_ros.core.identification.validate.force_scores`).

All quantities FRD body frame, SI units.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.batch import Fit, FitOptions, fit
from dampest_ros.core.identification.regression import memory_states
from dampest_ros.core.identification.validate import force_scores
from dampest_ros.core.online.estimator import EstimatorConfig, OnlineEstimator, nominal_of, restrict
from dampest_ros.core.online.sample import OnlineSample
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.extent import Extent
from dampest_ros.core.signals.samples import Samples
from dampest_ros.core.simulation.excitation import speed_limits

FloatArray = NDArray[np.float64]
#: A prior by name: (parameter names, mean θ, standard deviation), each of length p.
Prior = tuple[Sequence[str], FloatArray, FloatArray]


def prior_arrays(model: DampingModel, nominal: FloatArray, prior: Prior
                 ) -> tuple[FloatArray, FloatArray]:
    """The prior mean and standard deviation in the order of ``model``'s parameters, shape
    (p,) each: ``prior``'s values where it names a parameter, else the ``nominal`` θ with an
    infinite standard deviation (no prior weight)."""
    names, theta, std = prior
    values = dict(zip(names, np.asarray(theta, dtype=float), strict=True))
    stds = dict(zip(names, np.asarray(std, dtype=float), strict=True))
    mean = np.array([values.get(n, v) for n, v in zip(model.parameter_names, nominal,
                                                       strict=True)])
    return mean, np.array([stds.get(n, np.inf) for n in model.parameter_names])


class DampingIdentifier:
    """Identify the damping coefficients θ of one vehicle from samples.

    Parameters
    ----------
    vehicle : Vehicle
        Body (M, C(ν), g(η)) and nominal damping: the term structure and the prior.
    terms : sequence of str, optional
        Term kinds to identify, e.g. ``("linear", "quadratic")`` (default: all the
        vehicle's).
    method : {'ols', 'wls', 'ridge', 'bounded', 'map'}
        Batch solver of :meth:`fit` (:class:`~dampest_ros.core.identification.batch.FitOptions`);
        :meth:`partial_fit` is always the RLS.
    cutoff : float
        Parallel low-pass of the regression (Hz), for both paths and :meth:`score`.
    forgetting_factor : float
        λ in [0.9, 1] of :meth:`partial_fit` (1: every sample weighs the same).
    prior : tuple (names, theta, theta_std), optional
        Prior mean and standard deviation by name (e.g. a model file's): the MAP prior of
        :meth:`fit` (``method="map"`` needs it) and the RLS prior of :meth:`partial_fit`.
        Parameters it does not name keep the vehicle's nominal θ (and no prior weight in MAP,
        the default prior width in the RLS).
    structure : DampingModel, optional
        The term structure :meth:`fit` identifies instead of the vehicle's (e.g. what
        :func:`~dampest_ros.core.identification.selection.select_terms` chose, or a model
        file's), in :meth:`fit` and in :meth:`partial_fit`; parameters the vehicle does not
        have start from 0.
    **fit_options
        Further :class:`~dampest_ros.core.identification.batch.FitOptions` fields (``ridge``,
        ``block``, ``max_vif``, ``dissipative``, …).

    Attributes
    ----------
    model_ : Model
        The identified model (:class:`~dampest_ros.core.identification.model.Model`: θ, σ, what the
        data did not determine, the term structure, the mass matrix), ready for
        :func:`dampest_ros.io.yaml_io.save_model`.
    coef_ : ndarray, shape (p,)
        θ.
    cov_ : ndarray, shape (p, p)
        Covariance of θ: the batch fit's (NaN rows for coefficients held at their prior), or
        the RLS's correlation scaled by its standard deviations
        (:attr:`~dampest_ros.core.online.rls.least_squares.RecursiveLeastSquares.std`).
    names_ : list of str
        Parameter names, θ order (also :attr:`feature_names`).
    fit_ : Fit or None
        The batch result (flags, combinations, metrics), after :meth:`fit`.
    estimator_ : OnlineEstimator or None
        The recursive estimator, after :meth:`partial_fit`.
    """

    def __init__(self, vehicle: Vehicle, terms: Sequence[str] | None = None,
                 method: str = "wls", *, cutoff: float = 2.0, forgetting_factor: float = 1.0,
                 prior: Prior | None = None, structure: DampingModel | None = None,
                 **fit_options: Any) -> None:
        self.vehicle = vehicle
        self.terms = list(terms) if terms else None
        self.method = method
        self.cutoff = float(cutoff)
        self.forgetting_factor = float(forgetting_factor)
        self.prior = prior
        self.structure = structure
        self.fit_options = fit_options
        FitOptions(method=method, cutoff=cutoff, **fit_options)  # validates them now
        self.fit_: Fit | None = None
        self.estimator_: OnlineEstimator | None = None

    # --- fitting ---------------------------------------------------------------------------

    def fit(self, samples: Samples) -> DampingIdentifier:
        """Batch identification over all ``samples`` (forgets any earlier fit); returns self."""
        if self.structure is None:
            model, nominal = restrict(self.vehicle.damping, self.vehicle.theta, self.terms)
        else:
            model = self.structure
            nominal = nominal_of(model, self.vehicle.damping, self.vehicle.theta)
        extent = Extent.of(samples)
        options = FitOptions(method=self.method, cutoff=self.cutoff,
                             speed_range=tuple(speed_limits(self.vehicle, force=extent.force)),
                             **self.fit_options)
        mean, std = (nominal, None) if self.prior is None else prior_arrays(model, nominal,
                                                                             self.prior)
        self.fit_ = fit(samples, model, self.vehicle.body, options, prior=mean, prior_std=std,
                        extent=extent)
        self.estimator_ = None
        self.model_ = self.fit_.to_model(model, self.vehicle.body,
                                         identity=self.vehicle.identity)
        self.coef_ = self.fit_.theta
        self.cov_ = self.fit_.cov
        self.names_ = list(self.fit_.names)
        return self

    def online(self, config: EstimatorConfig | None = None, keep_samples: bool = False
               ) -> OnlineEstimator:
        """Start the recursive estimator of :meth:`partial_fit` from the prior and return it,
        for input stream by stream (the estimator node feeds it the four dampest/* topics,
        ``dampest identify --method rls`` a bag's messages); later :meth:`partial_fit` calls
        continue it.

        Parameters
        ----------
        config : EstimatorConfig, optional
            Default: λ = ``forgetting_factor``, this ``cutoff``, 50 Hz samples.
        keep_samples : bool
            Keep every sample used (:attr:`OnlineEstimator.samples_log`).
        """
        cfg = config or EstimatorConfig(forgetting_factor=self.forgetting_factor,
                                        cutoff=self.cutoff)
        self.estimator_ = OnlineEstimator(self.vehicle, self.terms, cfg, self.prior,
                                          keep_samples=keep_samples, structure=self.structure)
        self.fit_ = None
        return self.estimator_

    def partial_fit(self, samples: Samples) -> DampingIdentifier:
        """Recursive identification: feed ``samples`` in time order to the estimator node's
        RLS, continuing from the previous call (the first one starts from the prior);
        returns self. Every call must bring samples of the same rate."""
        est = self.estimator_
        if est is None:
            est = self.online(EstimatorConfig(forgetting_factor=self.forgetting_factor,
                                              rate=samples.rate, cutoff=self.cutoff))
        elif not math.isclose(samples.rate, est.cfg.rate, rel_tol=1e-6):
            raise ConfigError("samples", f"rate {samples.rate:g} Hz differs from the "
                              f"{est.cfg.rate:g} Hz the estimate was started with")
        for k in range(len(samples)):  # the node's path, one sample at a time
            est.add_sample(OnlineSample(float(samples.t[k]), samples.nu[k], samples.nu_dot[k],
                                        samples.tau[k], samples.euler[k],
                                        float(samples.depth[k]), True))
        est.process(force=True)
        self.estimator_ = est
        self.model_ = est.to_model(version=1)
        self.coef_ = est.theta.copy()
        std = est.theta_std
        d = np.sqrt(np.maximum(np.diagonal(est.rls.P), 1e-300))
        # cov = diag(σ) · corr(P) · diag(σ): the RLS's correlation at its sandwich std
        self.cov_ = est.rls.P / np.outer(d, d) * np.outer(std, std)
        self.names_ = list(est.names)
        return self

    # --- using the fit ---------------------------------------------------------------------

    @property
    def feature_names(self) -> list[str]:
        """Parameter names, θ order (pysindy's spelling of :attr:`names_`)."""
        return self._fitted().parameter_names

    def _fitted(self) -> DampingModel:
        """The fitted term structure."""
        if not hasattr(self, "model_"):
            raise ConfigError("DampingIdentifier", "not fitted yet: call fit or partial_fit "
                              "first")
        return self.model_.structure

    def predict(self, X: Samples | FloatArray) -> FloatArray:
        """Damping force D(ν)ν (+ the memory force of a ``freq`` term) of the fitted θ.

        Parameters
        ----------
        X : Samples or ndarray, shape (n, 6)
            Samples (their ν, and their time for memory states) or body velocities
            ν (m/s, rad/s); a model with memory needs Samples.

        Returns
        -------
        ndarray, shape (n, 6)
            N and N·m, FRD.
        """
        model = self._fitted()
        if isinstance(X, Samples):
            return model.force(X.nu, self.coef_, memory_states(X, model))
        return model.force(np.asarray(X, dtype=float), self.coef_)

    def score(self, samples: Samples) -> FloatArray:
        """Per-DOF R² (Nash–Sutcliffe) of the damping force on ``samples``, shape (6,): the
        force the data demand, y = τ − M ν̇ − C(ν)ν − g(η), against Φ(ν)θ, both low-passed
        at ``cutoff`` (:func:`~dampest_ros.core.identification.validate.force_scores`)."""
        model = self._fitted()
        return force_scores(samples, model, self.vehicle.body, self.coef_, self.cutoff)["nse"]
