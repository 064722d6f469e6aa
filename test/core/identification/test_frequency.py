"""Frequency-domain memory identification (dampest_ros.core.identification.frequency)."""

from __future__ import annotations

import numpy as np

from dampest_ros.core.identification.batch import FitOptions, fit
from dampest_ros.core.identification.frequency import memory_impedance
from dampest_ros.core.signals.preprocess import preprocess
from dampest_ros.core.simulation.effects import Effects
from dampest_ros.core.simulation.excitation import make_excitation
from dampest_ros.core.simulation.sensors import measure
from dampest_ros.core.simulation.simulate import run
from dampest_ros.io.yaml_io import load_vehicle


def test_rational_fit_recovers_the_memory_rate_from_multisine_data() -> None:
    """Platform A, surge memory K(t) = 20 e^{−2t}, 400 s of protocol C with sensor noise."""
    v = load_vehicle("platform_a")
    effects = Effects(memory=({"dof": "u", "rate": 2.0, "c": 20.0},))
    traj = run(v, make_excitation("C", v, 400.0, seed=3), effects)
    s = preprocess(measure(traj, v.body.rho, v.body.gravity, seed=3), v)
    theta = fit(s, v.damping, v.body, FitOptions(gyro_bias=0.0, dvl_bias=0.0)).theta
    imp = memory_impedance(s, v.damping, v.body, theta, [0])[0]
    assert abs(imp.rate - 2.0) <= 0.1 * 2.0
    assert abs(imp.gain - 20.0) <= 0.2 * 20.0
    assert np.median(imp.coherence) > 0.5
