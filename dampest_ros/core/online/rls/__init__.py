"""Recursive least squares for the stacked damping parameters θ (FRD body frame; the
target and regressor of :mod:`dampest_ros.core.identification.batch`): the update maths
(:mod:`.update`), the monitors of residual correlation, change and outliers
(:mod:`.monitors`) and the estimator object with its diagnostics (:mod:`.least_squares`).
"""
