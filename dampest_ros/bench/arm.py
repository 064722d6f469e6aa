"""The arm rows (group ``arm``): identification of long 1 kHz UR5 joint logs."""

from __future__ import annotations

import argparse
import time

from dampest_ros.bench.runner import child


def arm_identify(hours: str) -> dict[str, float]:
    """``hours`` of 1 kHz UR5 joint data (an FFS trajectory, 5 harmonics at 0.1 Hz, the
    torque of the model's true parameters, 20-bit encoders, torque noise 0.4–0.1 N m; one
    period computed and repeated) identified as ``dampest arm identify`` does it (zero-phase
    filter, decimation, regressor in chunks, OLS, WLS, physically consistent fit), timed
    from the arrays on (the bag reading is not in it)."""
    import numpy as np

    from dampest_ros.core.arm.base import base_parameters
    from dampest_ros.core.arm.ffs import random_trajectory
    from dampest_ros.core.arm.identify import IdentifyConfig, filter_joints, identify_arm
    from dampest_ros.core.arm.regressor import full_parameters, regressor
    from dampest_ros.core.arm.simulate import REALISTIC
    from dampest_ros.io.arm import load_arm

    arm = load_arm("ur5")
    base = base_parameters(arm.model)
    traj = random_trajectory(np.zeros(6), 5, 0.1, np.full(6, 1.0), np.random.default_rng(3))
    q, qd, qdd = traj.evaluate(np.arange(10_000) / 1000.0)
    truth = full_parameters(arm.model, arm.dynamics, np.asarray(REALISTIC.torque_offset))
    reps = round(float(hours) * 360)
    step = 2.0 * np.pi / REALISTIC.encoder_counts
    position = np.round(np.tile(q, (reps, 1)) / step) * step
    effort = np.tile(regressor(arm.model, q, qd, qdd) @ truth, (reps, 1))
    effort += np.random.default_rng(1).normal(size=effort.shape) * REALISTIC.torque_sigma
    t = np.arange(len(effort)) / 1000.0
    cfg = IdentifyConfig()
    t0 = time.perf_counter()
    res = identify_arm(arm.model, base, filter_joints(t, position, effort, cfg),
                       full_parameters(arm.model, arm.dynamics), cfg)
    seconds = time.perf_counter() - t0
    z = np.abs(res.wls.theta - base.of(truth)) / res.wls.std
    return {"seconds": seconds, "samples": float(len(t)), "max_z": float(z.max())}


def arm_rows(args: argparse.Namespace, tmp: str) -> list[tuple[str, ...]]:
    """Arm identification of ``--hours`` of 1 kHz joint data."""
    rows: list[tuple[str, ...]] = []
    for hours in args.hours:
        arm = child("arm.arm_identify", str(hours))
        rows.append((f"arm identify {hours:g} h of 1 kHz UR5 joint data (arrays)",
                     f"{arm['seconds']:.1f} s", f"{arm['samples']:.0f} samples, WLS "
                     f"max |error|/sigma {arm['max_z']:.1f}", "≤ 10 s", f"{arm['peak_mb']:.0f}"))
    return rows
