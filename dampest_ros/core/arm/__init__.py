"""Dynamic-parameter and joint-friction identification of serial arms: the arm
description, finite-Fourier-series excitation and its design, the regressor τ = Y(q, q̇, q̈) π
with friction columns, base parameters, least squares and physically consistent fits, MuJoCo
data and the online estimator. numpy/scipy, Pinocchio and MuJoCo only (no io, cli or ros).

May import: the Fourier design engine of :mod:`dampest_ros.core.simulation.design`, the
filtering of :mod:`dampest_ros.core.signals.preprocess` and the resampling of
:mod:`dampest_ros.core.signals.resample`, the recursive least squares of
:mod:`dampest_ros.core.online.rls` and :mod:`dampest_ros.core.physics`.
"""
