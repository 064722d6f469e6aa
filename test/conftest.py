"""Fixtures shared by the tests: the figures a report saves, the check that every axis
of them carries a unit, and the child processes a test starts (killed, whole process group,
when the test ends however it ends)."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest
from matplotlib.figure import Figure

if TYPE_CHECKING:  # the arm core (Pinocchio, MuJoCo) is imported by the fixtures that use it
    from dampest_ros.core.arm.ffs import FourierTrajectory
    from dampest_ros.core.arm.model import ArmModel, JointDynamics
    from dampest_ros.core.arm.simulate import ArmSensors

#: The checkout the tests run from.
REPO = Path(__file__).resolve().parents[1]
PACKAGE = "dampest_ros"
# What a user's workspace holds after cloning (pyproject.toml included: colcon must ignore it).
PACKAGE_FILES = ["package.xml", "setup.py", "setup.cfg", "pyproject.toml", "resource", PACKAGE,
                 "config", "launch"]

#: A unit in brackets or parentheses, e.g. (N), (N·s/m), [m/s], (N²/Hz), (unitless).
UNIT = re.compile(r"[(\[][^()\[\]]*[A-Za-z²][^()\[\]]*[)\]]")


#: What a test module that uses ROS says: rclpy in the test's process, a ROS domain, or node
#: processes (the child fixtures, the colcon build).
ROS_WORDS = re.compile(r"rclpy|ROS_DOMAIN_ID|children|colcon_install|ros_env")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark ``ros`` every test of a module that uses ROS. ``make test`` runs the others in
    parallel and these one at a time: two tests on one fixed ROS domain at once would see
    each other's nodes and messages, and node timings are asserted."""
    uses: dict[Path, bool] = {}
    for item in items:
        if item.path not in uses:
            uses[item.path] = bool(ROS_WORDS.search(item.path.read_text(encoding="utf-8")))
        if uses[item.path]:
            item.add_marker(pytest.mark.ros)


def record_figures(monkeypatch: pytest.MonkeyPatch) -> list[Figure]:
    """Every Figure saved from now on, until ``monkeypatch`` is undone (Figure.savefig
    wrapped)."""
    saved: list[Figure] = []
    original = Figure.savefig

    def savefig(self: Figure, *args: Any, **kwargs: Any) -> None:
        saved.append(self)
        original(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", savefig)
    return saved


@pytest.fixture
def saved_figures(monkeypatch: pytest.MonkeyPatch) -> list[Figure]:
    """Every Figure saved from now on in the test (:func:`record_figures`)."""
    return record_figures(monkeypatch)


@pytest.fixture(scope="session")
def figure_recorder() -> Callable[[pytest.MonkeyPatch], list[Figure]]:
    """:func:`record_figures`, for a module fixture that writes a report once."""
    return record_figures


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


class Children:
    """The child processes of a test (nodes, ``dampest`` commands), each started in a session
    of its own, so that its whole process group can be killed: :meth:`close` (called by the
    fixtures at the end of the test or module, failed or not) kills every group still there.
    A SIGINT lost on a loaded machine then leaves no orphan node publishing into later tests.
    """

    def __init__(self) -> None:
        self.procs: list[subprocess.Popen[Any]] = []

    @staticmethod
    def ros_env(domain: str) -> dict[str, str]:
        """The environment of a child on ROS_DOMAIN_ID ``domain``, localhost only, with one
        BLAS thread, unbuffered output, and this checkout first on PYTHONPATH."""
        env = dict(os.environ, ROS_DOMAIN_ID=domain, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                   OPENBLAS_NUM_THREADS="1", PYTHONUNBUFFERED="1")
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
        return env

    def start(self, argv: Sequence[str], log: Path | None = None, **kwargs: Any
              ) -> subprocess.Popen[Any]:
        """``subprocess.Popen(argv, **kwargs)`` in a new session; ``log``: stdout and stderr
        to that file."""
        if log is not None:
            with log.open("wb") as out:
                return self.start(argv, stdout=out, stderr=subprocess.STDOUT, **kwargs)
        proc = subprocess.Popen(list(argv), start_new_session=True, **kwargs)
        self.procs.append(proc)
        return proc

    def run(self, argv: Sequence[str], timeout: float, **kwargs: Any
            ) -> subprocess.CompletedProcess[Any]:
        """As ``subprocess.run(argv, timeout=timeout, **kwargs)`` (``capture_output`` and
        ``input`` included), the child's group killed on timeout (TimeoutExpired raised)."""
        if kwargs.pop("capture_output", False):
            kwargs.update(stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        data = kwargs.pop("input", None)
        if data is not None:
            kwargs["stdin"] = subprocess.PIPE
        proc = self.start(argv, **kwargs)
        try:
            out, err = proc.communicate(data, timeout=timeout)
        except subprocess.TimeoutExpired:
            self.kill(proc)
            proc.communicate()
            raise
        return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)

    def stop(self, proc: subprocess.Popen[Any], sig: int | None = signal.SIGINT,
             timeout: float = 30.0) -> int:
        """Send ``sig`` to ``proc`` (None: no signal, it was sent already) and wait at most
        ``timeout`` s for its exit status (its group killed, and TimeoutExpired raised, when
        it does not exit)."""
        if proc.poll() is None and sig is not None:
            proc.send_signal(sig)
        try:
            return proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.kill(proc)
            raise

    @staticmethod
    def kill(proc: subprocess.Popen[Any]) -> None:
        """SIGKILL to the process group of ``proc`` (its session), then reap it."""
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):  # the group is gone already
            pass
        proc.wait()

    def close(self) -> None:
        """Kill every child's process group (a child that exited may have left its own
        children behind)."""
        for proc in self.procs:
            self.kill(proc)
        self.procs.clear()


@pytest.fixture
def children() -> Iterator[Children]:
    """:class:`Children` of one test."""
    kids = Children()
    try:
        yield kids
    finally:
        kids.close()


@pytest.fixture(scope="module")
def module_children() -> Iterator[Children]:
    """:class:`Children` shared by the tests of a module (for module-scoped fixtures)."""
    kids = Children()
    try:
        yield kids
    finally:
        kids.close()


def find_colcon() -> Path:
    """The venv's colcon, else the one on PATH; the test is skipped without one."""
    colcon = Path(sys.executable).parent / "colcon"
    if colcon.exists():
        return colcon
    found = shutil.which("colcon")
    if found is None:
        pytest.skip("colcon not installed")
    return Path(found)


@pytest.fixture(scope="session")
def colcon_install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``colcon build`` of the package files of a clone in a temporary workspace, once per
    session (the packaging test and the multiprocess nodes only read it); returns
    install/dampest_ros."""
    ws = tmp_path_factory.mktemp("ws")
    src = ws / "src" / PACKAGE
    src.mkdir(parents=True)
    for name in PACKAGE_FILES:
        path = REPO / name
        if path.is_dir():
            shutil.copytree(path, src / name,
                            ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        else:
            shutil.copy2(path, src / name)
    env = dict(os.environ, COLCON_HOME=str(ws / "colcon_home"), COLCON_LOG_PATH=str(ws / "log"))
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    kids = Children()
    try:
        proc = kids.run([str(find_colcon()), "build", "--base-paths", "src", "--build-base",
                         "build", "--install-base", "install"], cwd=ws, env=env,
                        capture_output=True, text=True, timeout=600)
    finally:
        kids.close()
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return ws / "install" / PACKAGE


#: Outside arms of the pinned example-robot-data wheel (requirements/lock.txt): URDF path
#: under its robots folder, and the gripper joints held fixed.
OUTSIDE_ARMS = {
    "ur10": ("ur_description/urdf/ur10_robot.urdf", ()),
    "kinova": ("kinova_description/robots/kinova.urdf", ()),
    "z1": ("z1_description/urdf/z1.urdf", ("jointGripper",)),
    "panda": ("panda_description/urdf/panda.urdf",
              ("panda_finger_joint1", "panda_finger_joint2")),
    "xarm7": ("xarm_description/urdf/xarm7.urdf", ()),
    "so101": ("so_arm_description/urdf/so101.urdf", ("gripper",)),
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
        from dampest_ros.core.arm.model import JointDynamics

        e = arm.effort_limit
        return JointDynamics(armature=0.0015 * e, damping=0.015 * e, frictionloss=0.02 * e)

    @staticmethod
    def sensors(arm: ArmModel) -> ArmSensors:
        """20-bit encoders, torque noise 0.27 % and offsets ±0.2 % of the effort limit."""
        from dampest_ros.core.arm.simulate import scaled_sensors

        return scaled_sensors(arm)

    @staticmethod
    def trajectory(arm: ArmModel, nominal: np.ndarray, harmonics: int, frequency: float,
                   seed: int) -> FourierTrajectory:
        """Random FFS coefficients within the default design limits of the arm's own
        joints."""
        from dampest_ros.core.arm.design import default_limits, within_limits
        from dampest_ros.core.arm.ffs import random_trajectory

        lim = default_limits(arm)
        q0 = 0.5 * (lim.lower + lim.upper)
        traj = random_trajectory(q0, harmonics, frequency, lim.velocity,
                                 np.random.default_rng(seed))
        return within_limits(arm, traj, lim, nominal)


@pytest.fixture(scope="session")
def outside() -> type[OutsideSim]:
    """The joint terms, sensors and trajectories of the outside-arm tests."""
    return OutsideSim


@pytest.fixture(scope="session")
def linear_roll_torpedo() -> Any:
    """torpedo_auv with purely linear roll damping (K_p = 0.5885, K_pp = 0): a lightly damped
    roll mode (0.75 Hz, damping ratio 0.2) whose K_p the preprocessing must not bias."""
    from dataclasses import replace

    from dampest_ros.io.yaml_io import load_vehicle

    vehicle = load_vehicle("torpedo_auv")
    names = vehicle.damping.parameter_names
    theta = vehicle.theta.copy()
    theta[names.index("K_p")], theta[names.index("K_pp")] = 0.5885, 0.0
    return replace(vehicle, theta=theta)


@pytest.fixture(scope="session")
def heavy_b60() -> tuple[Any, Any]:
    """bluerov2_heavy (native), 60 s of protocol B, seed 3: the trajectory and what the
    default sensors measure of it (seed 3). Read only: the online, mounting and validation
    tests share it."""
    from dampest_ros.core.simulation.excitation import make_excitation
    from dampest_ros.core.simulation.sensors import measure
    from dampest_ros.core.simulation.simulate import run
    from dampest_ros.io.yaml_io import load_vehicle

    vehicle = load_vehicle("bluerov2_heavy")
    traj = run(vehicle, make_excitation("B", vehicle, 60.0, seed=3))
    return traj, measure(traj, vehicle.body.rho, vehicle.body.gravity, seed=3)


@pytest.fixture(scope="session")
def heavy_b60_online(heavy_b60: tuple[Any, Any]) -> tuple[Any, list[Any]]:
    """The default online preprocessor after the whole recording of :func:`heavy_b60`, and
    the samples it returned (read only)."""
    from dampest_ros.core.online.preprocessor import OnlinePreprocessor
    from dampest_ros.io.yaml_io import load_vehicle

    vehicle = load_vehicle("bluerov2_heavy")
    op = OnlinePreprocessor(vehicle.thrusters, vehicle.body.gravity, vehicle.body.rho)
    return op, op.run(heavy_b60[1])
