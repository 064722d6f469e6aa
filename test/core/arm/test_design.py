"""Excitation design: within every limit, and a better-conditioned base regressor than
random FFS coefficients held to the same limits; the D-optimal objective gives more
information than the condition number's and a fit as good."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from dampest_ros.core.arm.base import base_parameters
from dampest_ros.core.arm.design import default_limits, design_excitation, regressor_cond
from dampest_ros.core.arm.identify import IdentifyConfig, filter_joints, identify_arm
from dampest_ros.core.arm.regressor import full_parameters, regressor
from dampest_ros.core.arm.simulate import REALISTIC, simulate_arm
from dampest_ros.io.arm import load_arm


@pytest.fixture(scope="module")
def ur5():  # type: ignore[no-untyped-def]
    arm = load_arm("ur5")
    return arm, base_parameters(arm.model), full_parameters(arm.model, arm.dynamics)


def _check(arm, design, limits, nominal) -> None:  # type: ignore[no-untyped-def]
    t = np.linspace(0.0, design.trajectory.period, 20_000)
    q, qd, qdd = design.trajectory.evaluate(t)
    tau = regressor(arm.model, q, qd, qdd) @ nominal
    assert limits.violations(q, qd, qdd, tau, arm.model.names) == []
    # the limits are used, not undershot: some joint reaches its velocity or position bound
    assert np.max(np.abs(qd).max(axis=0) / limits.velocity) > 0.95


def test_design_keeps_limits_and_lowers_cond(ur5) -> None:  # type: ignore[no-untyped-def]
    arm, base, nominal = ur5
    limits = default_limits(arm.model, span=1.0, velocity=1.0, acceleration=4.0)
    d = design_excitation(arm.model, base, nominal, limits, harmonics=3, base_frequency=0.2,
                          iterations=2, baseline=3)
    _check(arm, d, limits, nominal)
    assert d.cond < d.cond_start
    assert regressor_cond(arm.model, base, d.trajectory) == pytest.approx(d.cond)
    # a torque bound that binds is kept; one below holding the arm at q0 is refused, named
    tight = default_limits(arm.model, span=1.0, velocity=1.0, acceleration=4.0)
    tight.effort[1] = 62.0  # holding at q0 takes 52 N m, sliding friction 3 more
    d2 = design_excitation(arm.model, base, nominal, tight, harmonics=3, base_frequency=0.2,
                           iterations=1, baseline=1)
    _check(arm, d2, tight, nominal)
    tight.effort[1] = 20.0
    with pytest.raises(ValueError, match=r"shoulder_lift_joint \|torque\| .* exceeds 20 N m"):
        design_excitation(arm.model, base, nominal, tight, harmonics=3, base_frequency=0.2,
                          iterations=1, baseline=1)


@pytest.mark.slow
def test_designed_excitation_is_5x_better_conditioned(ur5) -> None:  # type: ignore[no-untyped-def]
    arm, base, nominal = ur5
    limits = default_limits(arm.model)
    d = design_excitation(arm.model, base, nominal, limits, iterations=40, baseline=16)
    _check(arm, d, limits, nominal)
    assert d.cond_random / d.cond >= 5.0


def test_default_limits_are_each_joints_own_range() -> None:
    arm = load_arm(str(Path(__file__).parents[2] / "data" / "z1like.urdf")).model
    limits = default_limits(arm, span=1.0)
    # joint 2 is limited to [0, 2.967], joint 3 to [-2.88, 0]: centred in them, not at 0
    assert limits.lower[1:3] == pytest.approx([0.4835, -2.44])
    assert limits.upper[1:3] == pytest.approx([2.4835, -0.44])
    # a range narrower than 2 span is the range; the UR5's ±2π gives ±span
    assert default_limits(arm, span=2.0).lower[4] == -1.344
    assert np.array_equal(default_limits(load_arm("ur5").model, span=0.7).upper, [0.7] * 6)
    # no limits (continuous): ±span around 0; one finite limit: from the point nearest 0
    free = replace(arm, lower=np.array([-np.inf, 0.5, -np.inf, -1.0, -1.0, -1.0]),
                   upper=np.array([np.inf, np.inf, -0.2, 1.0, 1.0, 1.0]))
    limits = default_limits(free, span=1.0)
    assert limits.lower[:3].tolist() == [-1.0, 0.5, -1.2]
    assert limits.upper[:3].tolist() == [1.0, 1.5, -0.2]


@pytest.mark.slow
def test_d_optimal_design_has_more_information_and_fits_as_well(ur5) -> None:  # type: ignore[no-untyped-def]
    """The D-optimal design beside the condition-number one, same seed, limits and
    iterations: a larger log det, and base parameters fitted from 30 s of REALISTIC data on
    each (noise seeds 1-3) as close to MuJoCo's truth in their own σ, and closer in the
    condition-number design's σ (the smaller confidence volume shows in the errors)."""
    arm, base, nominal = ur5
    limits = default_limits(arm.model)
    truth = base.of(full_parameters(arm.model, arm.dynamics, REALISTIC.torque_offset))
    prior = nominal.copy()
    prior[:60] *= 1.2
    cfg = IdentifyConfig()
    errors, sigmas, designs = {}, {}, {}
    for objective in ("cond", "dopt"):
        d = design_excitation(arm.model, base, nominal, limits, iterations=10, baseline=4,
                              objective=objective)
        _check(arm, d, limits, nominal)
        designs[objective] = d
        fits = [identify_arm(arm.model, base, filter_joints(run.t, run.position, run.effort,
                                                             cfg), prior, cfg).wls
                for run in (simulate_arm(arm.mjcf, arm.model, arm.dynamics, d.trajectory, 30.0,
                                         1000.0, REALISTIC, seed=seed) for seed in (1, 2, 3))]
        errors[objective] = np.array([np.abs(f.theta - truth) for f in fits])
        sigmas[objective] = np.array([f.std for f in fits])
    cond, dopt = designs["cond"], designs["dopt"]
    assert dopt.logdet > cond.logdet + 10.0 and cond.logdet > cond.logdet_random
    z = {k: float(np.median(errors[k] / sigmas[k])) for k in errors}
    assert z["dopt"] <= 1.0 and z["dopt"] <= z["cond"] + 0.1
    # the same errors in the condition-number design's σ: the D-optimal fit is closer
    assert np.median(errors["dopt"] / sigmas["cond"]) < np.median(errors["cond"]
                                                                     / sigmas["cond"])
    print({k: round(v, 3) for k, v in z.items()}, "log det", round(cond.logdet, 2),
          round(dopt.logdet, 2), "random", round(cond.logdet_random, 2))
