"""Dynamic-parameter and joint-friction identification of serial arms: the arm
description, finite-Fourier-series excitation and its design, the regressor τ = Y(q, q̇, q̈) π
with friction columns, base parameters, least squares and physically consistent fits, MuJoCo
data and the online estimator. numpy/scipy, Pinocchio and MuJoCo only (no io, cli or ros)."""
