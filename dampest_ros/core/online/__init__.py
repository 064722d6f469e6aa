"""Online identification, sample by sample, in O(p²) per sample.

The causal preprocessor (:mod:`.preprocessor`) and the samples it emits (:mod:`.sample`), the
parallel-filtered regression updated per chunk (:mod:`.regression`), recursive least squares
with forgetting and its monitors (:mod:`.rls`), and the estimator behind the estimator node
that joins them (:mod:`.estimator`).

May import: :mod:`dampest_ros.core.identification`, :mod:`dampest_ros.core.signals` and
:mod:`dampest_ros.core.physics`.
"""
