"""Batch identification of the damping: regression, fit, uncertainty and checks.

The regression form F = Φ(ν)θ, parallel-filtered (:mod:`.regression`), the batch fit with
prior, constraints and held coefficients (:mod:`.batch`, :mod:`.quadratic`,
:mod:`.covariance`), dissipativity νᵀD(ν)ν ≥ 0 (:mod:`.dissipative`), the structure search
(:mod:`.selection`, its cross-validation budget :mod:`.cv_budget`, :mod:`.memory_rates`,
:mod:`.frequency`; the default structure, library terms where a model misfits:
:mod:`.misfit`), the τ delay (:mod:`.delay`),
pooled logs (:mod:`.pool`), held-out and free-run validation (:mod:`.validate`), and the
identified model every tool passes around (:mod:`.model`, :mod:`.identified`).

May import: :mod:`dampest_ros.core.signals` and :mod:`dampest_ros.core.physics`; never
:mod:`dampest_ros.core.simulation` (an estimate never depends on how data were made).
"""
