"""Sim-to-real gap: where measured data and a believed model disagree, and what is missing.

A user has a model of the vehicle (M, the damping D(ν) with its θ, restoring data) and data
from the real vehicle (:class:`~dampest_ros.core.signals.samples.Samples`: ν, ν̇, τ, attitude,
depth, as a vehicle logs them; never ground truth). This package

1. compares them through the one-step inverse-dynamics residual (FRD body, NED world)

       r(t) = τ − (M ν̇ + C(ν)ν + D(ν)ν + g(η))       (N, N·m),  shape (N, 6)

   i.e. ``batch.target − Φθ`` with the same parallel zero-phase low-pass as the
   identification (:func:`dampest_ros.core.identification.batch.iter_regression`; :mod:`.data`);
2. localises it (:func:`.localise.localise`): per DOF, velocity regime, frequency band
   (Welch PSD), time segment, attitude and depth;
3. names the missing effect (:func:`.search.find_gap`): every candidate
   :class:`.effects.Effect` is a physical effect with a few unknown magnitudes p and an exact
   prediction ρ(p) of the residual it would leave in data analysed with the believed model
   (``r ≈ ρ(p) + noise``). Candidates are screened by fitting their linearisation on the first
   ``split`` (70 %) of the time and scoring the residual reduction on the rest (held out), with
   the error-reduction ratio and the BIC change as in
   :mod:`dampest_ros.core.identification.selection`; the best significant one is refined on its
   exact (nonlinear) model with ``scipy.optimize.least_squares``, all added effects are
   refitted jointly, and it is added when its magnitudes pass their Wald test and the
   held-out log-likelihood gain summed over the DOFs is significant; a DOF that grows only
   where a current moves ν_r outside the believed model's flown envelope is extrapolation,
   not evidence against it (:mod:`.trust`). The search repeats until no candidate is
   significant: "no further missing effect found". With a current named, the believed model
   is refitted at ν_r jointly with it, library terms added where its terms misfit ν_r
   (:mod:`.relative`);
4. applies what it found to the believed model and compares the free runs of both
   (:mod:`.update`).

The effects (:mod:`.effects`, :mod:`.model_effects`, the candidate set :mod:`.library`; each
evaluated vectorised over chunks of samples, then low-passed like the regression): ocean
current constant in NED, buoyancy offset, CG offset, thrust-gain error, thruster dead-zone
(needs the logged rotor speeds), τ → ν delay, added-mass error (scale and per DOF), a missing
linear or quadratic damping coefficient per DOF, each cross-coupling of
:data:`dampest_ros.core.identification.selection.DEFAULT_CROSS`, fluid memory per DOF, gyro bias and
DVL bias.

Signs: with the model's residual r = τ − model(ν, ν̇, η), an effect that adds a force F to the
left-hand side of the true equation (M ν̇ + … + g + F = τ) leaves ρ = F.

May import: :mod:`dampest_ros.core.identification`, :mod:`dampest_ros.core.signals` and
:mod:`dampest_ros.core.physics`; never the simulators (:mod:`dampest_ros.core.simulation`): the
gap is found from logs alone.
"""
