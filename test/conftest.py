"""Fixtures shared by the tests: the figures a report saves, and the check that every axis
of them carries a unit."""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from matplotlib.figure import Figure

from dampest_ros.core.arm.design import default_limits, within_limits
from dampest_ros.core.arm.ffs import FourierTrajectory, random_trajectory
from dampest_ros.core.arm.model import ArmModel, JointDynamics
from dampest_ros.core.arm.simulate import ArmSensors, scaled_sensors

#: A unit in brackets or parentheses, e.g. (N), (N·s/m), [m/s], (N²/Hz), (unitless).
UNIT = re.compile(r"[(\[][^()\[\]]*[A-Za-z²][^()\[\]]*[)\]]")


@pytest.fixture
def saved_figures(monkeypatch: pytest.MonkeyPatch) -> list[Figure]:
    """Every Figure saved from now on (Figure.savefig wrapped)."""
    saved: list[Figure] = []
    original = Figure.savefig

    def savefig(self: Figure, *args: Any, **kwargs: Any) -> None:
        saved.append(self)
        original(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", savefig)
    return saved


def label_problems(figures: list[Figure]) -> list[str]:
    """Axes whose x or y axis lacks a label with a unit. An x axis shared with a labelled
    one (the bottom row of a column) counts as labelled; categorical x ticks (words, no
    scale) need no unit."""
    problems = []
    for fig in figures:
        for ax in fig.axes:
            if not ax.get_visible():
                continue
            where = f"{fig.texts[0].get_text() if fig.texts else ''}/{ax.get_title()}"
            if not UNIT.search(ax.get_ylabel()):
                problems.append(f"{where}: y label {ax.get_ylabel()!r}")
            siblings = ax.get_shared_x_axes().get_siblings(ax)
            ticks = [t.get_text() for t in ax.get_xticklabels()]
            categorical = bool(ticks) and all(re.fullmatch(r"[a-z .]+", t) for t in ticks)
            if not categorical and not any(UNIT.search(s.get_xlabel()) for s in siblings):
                problems.append(f"{where}: x label {ax.get_xlabel()!r}")
    return problems



@pytest.fixture
def axis_unit_problems() -> Callable[[list[Figure]], list[str]]:
    """:func:`label_problems`, for tests that check figures."""
    return label_problems


#: Outside arms of the pinned example-robot-data wheel (requirements/lock.txt): URDF path
#: under its robots folder, and the gripper joints held fixed.
OUTSIDE_ARMS = {
    "ur10": ("ur_description/urdf/ur10_robot.urdf", ()),
    "kinova": ("kinova_description/robots/kinova.urdf", ()),
    "z1": ("z1_description/urdf/z1.urdf", ("jointGripper",)),
    "panda": ("panda_description/urdf/panda.urdf",
              ("panda_finger_joint1", "panda_finger_joint2")),
    "xarm7": ("xarm_description/urdf/xarm7.urdf", ()),
}


@pytest.fixture(scope="session")
def outside_arm() -> Callable[[str], tuple[str, tuple[str, ...]]]:
    """The URDF path of an example-robot-data arm and the joints to lock, by short name."""
    from importlib.metadata import distribution

    robots = distribution("example-robot-data").locate_file(
        "cmeel.prefix/share/example-robot-data/robots")

    def find(name: str) -> tuple[str, tuple[str, ...]]:
        path, lock = OUTSIDE_ARMS[name]
        return str(robots / path), lock  # type: ignore[operator]

    return find


class OutsideSim:
    """One rule for every outside arm: its simulated joint terms, sensors and trajectories."""

    @staticmethod
    def joint_terms(arm: ArmModel) -> JointDynamics:
        """Armature, viscous and Coulomb friction in proportion to each joint's effort limit
        (the UR5 preset's shoulder: 0.25 kg m², 2 N m s/rad, 3 N m of 150 N m)."""
        e = arm.effort_limit
        return JointDynamics(armature=0.0015 * e, damping=0.015 * e, frictionloss=0.02 * e)

    @staticmethod
    def sensors(arm: ArmModel) -> ArmSensors:
        """20-bit encoders, torque noise 0.27 % and offsets ±0.2 % of the effort limit."""
        return scaled_sensors(arm)

    @staticmethod
    def trajectory(arm: ArmModel, nominal: np.ndarray, harmonics: int, frequency: float,
                   seed: int) -> FourierTrajectory:
        """Random FFS coefficients within the default design limits of the arm's own
        joints."""
        lim = default_limits(arm)
        q0 = 0.5 * (lim.lower + lim.upper)
        traj = random_trajectory(q0, harmonics, frequency, lim.velocity,
                                 np.random.default_rng(seed))
        return within_limits(arm, traj, lim, nominal)


@pytest.fixture(scope="session")
def outside() -> type[OutsideSim]:
    """The joint terms, sensors and trajectories of the outside-arm tests."""
    return OutsideSim
