"""Base parameters: structurally zero columns that hold rounding are not counted, on an arm of
our own (Z1-like, pitch joints written as rpy-turned z axes) and on the shipped UR5."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dampest_ros.core.arm.base import base_parameters
from dampest_ros.core.arm.regressor import full_parameters, regressor
from dampest_ros.io.arm import load_arm

Z1LIKE = Path(__file__).parents[2] / "data" / "z1like.urdf"


def _states(arm, seed: int):  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(seed)
    return (rng.uniform(-np.pi, np.pi, (300, arm.n)), rng.normal(size=(300, arm.n)),
            rng.normal(size=(300, arm.n)))


@pytest.fixture(scope="module")
def z1like():  # type: ignore[no-untyped-def]
    return load_arm(str(Z1LIKE))


def test_rounding_columns_are_structurally_zero(z1like) -> None:  # type: ignore[no-untyped-def]
    arm = z1like.model
    W = regressor(arm, *_states(arm, 5)).reshape(-1, 14 * arm.n)
    norm = np.linalg.norm(W, axis=0)
    rounding = (norm > 0) & (norm < 1e-12 * norm.max())
    assert rounding.sum() == 2  # cos(π/2) left in two columns (norms 5e-32 and 1e-14)
    base = base_parameters(arm)
    # 36 rigid-body combinations, Ia of joints 3-6 (joint 1's and 2's fold into links),
    # Fv, Fc, off of every joint: the count of the UR5, which has the same axis pattern
    assert base.size == 58
    assert not set(np.flatnonzero(rounding)) & set(base.independent.tolist())
    names = [base.names[i] for i in np.flatnonzero(rounding)]
    assert set(names) <= set(base.unidentifiable())
    # the base regressor is well conditioned, and recombines the full one exactly
    Yb = base.columns(W)
    assert np.linalg.cond(Yb / np.linalg.norm(Yb, axis=0)) < 1e4
    pi = full_parameters(arm, z1like.dynamics, np.arange(1.0, 7.0))
    assert np.abs(Yb @ base.of(pi) - W @ pi).max() < 1e-12 * np.abs(W @ pi).max()


def test_ur5_base_is_unchanged() -> None:
    base = base_parameters(load_arm("ur5").model)
    # the split of the UR5 from before structurally zero columns were set aside (it has none
    # with rounding): the same columns kept, the same combinations
    assert base.independent.tolist() == [
        11, 15, 17, 18, 19, 20, 21, 23, 25, 26, 27, 28, 29, 31, 33, 35, 36, 37, 38, 39, 41, 42,
        44, 45, 47, 48, 49, 51, 53, 54, 55, 56, 57, 58, 60, 61, 62, 63, 64, 65, 66, 67, 68, 69,
        70, 71, 72, 73, 74, 75, 76, 77, 78, 79, 80, 81, 82, 83]
    assert np.abs(base.beta).sum() == pytest.approx(28.400043278970635, rel=1e-12)


def test_a_right_angle_written_to_five_digits_is_not_a_base_parameter(outside_arm) -> None:  # type: ignore[no-untyped-def]
    """The xArm7's URDF turns its axes by rpy = 1.5708, 3.7e-6 rad off π/2: a combination the
    algebra folds had a pivot of 5e-6 and was counted (70 base parameters), and its
    information matrix was singular. Now it has the 69 of the Panda, whose URDF writes π/2
    to full precision, and the fold leaves a torque error of that relative size."""
    path, lock = outside_arm("xarm7")
    arm = load_arm(path, lock=lock).model
    base = base_parameters(arm)
    assert base.size == 69
    W = regressor(arm, *_states(arm, 5)).reshape(-1, 14 * arm.n)
    pi = full_parameters(arm, load_arm(path).dynamics, np.arange(1.0, 8.0))
    err = np.abs(base.columns(W) @ base.of(pi) - W @ pi).max() / np.abs(W @ pi).max()
    assert 1e-8 < err < 1e-5
    assert base_parameters(arm, tol=1e-8).size == 70  # the rounding-only tolerance of before
    panda_path, panda_lock = outside_arm("panda")
    assert base_parameters(load_arm(panda_path, lock=panda_lock).model).size == 69


def test_rounded_right_angles_on_light_links_are_folded(outside_arm) -> None:  # type: ignore[no-untyped-def]
    """The SO-101 writes π and π/2 to six and five digits (joint frames 3-4e-6 rad off
    square) on links of 0.1 kg: a mass column the algebra zeroes was left at 1e-4 of the
    largest, above the column test, and scaled to unit norm it took a pivot, so that two
    genuine combinations stood at pivots of 5e-4 and 4e-4 (49 base parameters) and the
    information matrix of a 60 s trajectory was singular. Split as the arm with square
    frames, it has 47, and the folds leave a torque error of the rounding's size."""
    path, lock = outside_arm("so101")
    arm = load_arm(path, lock=lock).model
    base = base_parameters(arm)
    assert base.size == 47
    W = regressor(arm, *_states(arm, 5)).reshape(-1, 14 * arm.n)
    pi = full_parameters(arm, load_arm(path, lock=lock).dynamics, np.arange(1.0, 6.0))
    err = np.abs(base.columns(W) @ base.of(pi) - W @ pi).max() / np.abs(W @ pi).max()
    assert err < 1e-5
