"""What the dampest sub-commands share and what their --help needs: the shared options
(each defined once, with its one help text), the input description, plain-text tables.

Light on purpose: no numpy, no core, no ROS. ``dampest CMD --help`` imports this module and
the command's own parser, nothing heavier; reading logs and models is in
:mod:`dampest_ros.cli.inputs`.
"""

from __future__ import annotations

import argparse
import math
import numbers
import os
import sys
import textwrap
import threading
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

#: Excitation protocols of the simulator (dampest_ros.core.simulation.excitation.PROTOCOLS, which a
#: test checks this against; not imported here, it pulls in scipy).
PROTOCOLS = ("A", "B", "C", "axes", "fourier", "optimal")

#: Width the plain-text descriptions are wrapped to.
WIDTH = 88


def describe(p: argparse.ArgumentParser, description: str, example: str,
             *more: str) -> None:
    """Set a command's description (``description``, then each of ``more`` as its own
    wrapped paragraph) and its example epilog; plain text (the parser keeps the layout)."""
    paragraphs = [textwrap.fill(m, WIDTH) for m in more]
    p.description = "\n\n".join([description.strip(), *paragraphs])
    p.epilog = example


#: What the bag input of identify, validate, gap and inspect may be (their --help).
BAG_HELP = (
    "Bags are rosbag2 directories (MCAP or SQLite3, as ros2 bag records them) or ROS 1 bags "
    "(.bag files, as most published marine datasets are), read the same way: a ROS 1 "
    "sensor_msgs/Imu is the sensor_msgs/msg/Imu the topic options expect (see the "
    "examples). Topic names are the same with or without the leading /: --imu-topic "
    "/imu/data is --imu-topic imu/data.")

#: What the CSV input of identify, validate and gap may look like (their --help).
CSV_HELP = (
    "CSV logs (.csv, or gzip-compressed .csv.gz) are in the seed format "
    "time,u,v,w,p,q,r,ax,ay,az,wx,wy,wz,depth,tau_X,...,tau_N[,roll,pitch,yaw] (FRD body, "
    "SI units), or in its flavours, which are detected and read: ax,ay,az an IMU's specific "
    "force (mean |a| ≈ g, either sign: az ≈ -9.8 or +9.8 level at rest) instead of u̇,v̇,ẇ; "
    "wx,wy,wz gyro rates equal to p,q,r instead of ṗ,q̇,ṙ (then differentiated); no tau "
    "columns but thrust_<name> (N) or rpm_<name> (rev/min) per thruster of the vehicle, "
    "turned into τ by its thrust curve and allocation matrix. An ambiguous log is refused "
    "with the --columns entry that settles it ('ax: acc_x' specific force, 'ax: ax' u̇; "
    "'wx: gyro_x' gyro rate, 'wx: wx' ṗ). u,v,w (and a bag's DVL velocity) are over ground "
    "(DVL bottom lock); identify, validate and gap all assume still water, so they are used "
    "as the velocity through the water too, except by gap's 'current' candidate, which "
    "estimates a constant current and applies the damping to ν − ν_c. A log of velocity "
    "through the water (water-track DVL) is read the same way. Time may be in s, ms, µs or "
    "ns (detected; named on stderr unless seconds); uneven rows are resampled onto one "
    "uniform clock with the mean step, split at steps over 1.75 median steps. A folder of "
    "per-topic CSV files (rostopic echo -p, bag-to-CSV tools) is read like a bag: topics "
    "from the file names, or name a file with --imu-topic FILE.csv etc.")

#: What the attitude and velocity topics may be besides an IMU and a DVL (--help).
SOURCE_HELP = {
    "imu": (": sensor_msgs/Imu, or the attitude (and angular rate, if filled) of a "
            "nav_msgs/Odometry or the attitude of a geometry_msgs/PoseStamped. An all-zero "
            "or absent gyro is replaced by the body rates of the attitude, an all-zero or "
            "absent accelerometer by the zero-phase derivative of the velocity, each said "
            "in one line on stderr and in the model's provenance (substitutions). A state "
            "estimator's navigation state alone: --imu-topic /nav/odom --dvl-topic "
            "/nav/odom"),
    "dvl": (": a DVL's TwistWithCovarianceStamped or TwistStamped, or a nav_msgs/Odometry "
            "(its twist: the body velocity in the child frame). A value held between "
            "updates (republished at a higher rate) is used at its updates only"),
}

#: Topic roles and their default names (docs/architecture.md §3).
DEFAULT_TOPICS = {"imu": "imu/data", "dvl": "dvl/twist", "pressure": "pressure",
                  "thrusters": "thrusters/state"}


def topic_name(text: str) -> str:
    """A ``--*-topic`` value as the commands name a bag's topics: without the leading ``/``
    (bags store ``/imu/data``; ``/imu/data`` and ``imu/data`` are the same topic).

    The type of every topic option (its default too), so that the names are normalised
    here, once, for every command that reads them.
    """
    name = text.strip().lstrip("/")
    if not name:
        raise argparse.ArgumentTypeError(f"{text!r} is not a topic name (e.g. imu/data)")
    return name


def add_topic_options(p: argparse.ArgumentParser) -> None:
    """--imu-topic, --dvl-topic, --pressure-topic, --thrusters-topic, --wrench-topic (values
    normalised by :func:`topic_name`)."""
    for role, name in DEFAULT_TOPICS.items():
        p.add_argument(f"--{role}-topic", default=name, type=topic_name, metavar="TOPIC",
                       help=f"topic of the {role} data{SOURCE_HELP.get(role, '')}, with or "
                            f"without the leading / (default: {name})")
    p.add_argument("--wrench-topic", type=topic_name, metavar="TOPIC",
                   help="topic of the body wrench τ (geometry_msgs/WrenchStamped, FLU; the "
                        "contract's 'wrench'), read instead of the thruster telemetry: the "
                        "vehicle then needs no thrusters (default: none, τ from "
                        "--thrusters-topic through the vehicle's allocation)")


def topic_roles(args: argparse.Namespace) -> dict[str, str]:
    """Role → topic of the ``--*-topic`` options; ``wrench`` only when ``--wrench-topic``
    is given (τ then comes from it, not from the thruster telemetry)."""
    topics = {role: str(getattr(args, f"{role}_topic")) for role in DEFAULT_TOPICS}
    if getattr(args, "wrench_topic", None):
        topics["wrench"] = str(args.wrench_topic)
    return topics


def add_vehicle_option(p: argparse.ArgumentParser, default: str | None = None) -> None:
    """--vehicle: a preset name or a vehicle YAML (required without a default)."""
    p.add_argument("--vehicle", required=default is None, default=default,
                   metavar="NAME|YAML",
                   help="vehicle: a preset name in config/vehicles (bluerov2_heavy, "
                        "torpedo_auv, ...) or a vehicle YAML path; its mass, added mass, "
                        "restoring data, thrusters and nominal damping (the prior and the "
                        "term structure)" + (f" (default: {default})" if default else ""))


def add_protocol_option(p: argparse.ArgumentParser) -> None:
    """--protocol: the excitation the simulator flies."""
    p.add_argument("--protocol", choices=PROTOCOLS, default="B",
                   help="excitation: A low-speed steps and sines; B ramped surge and PRBS on "
                        "all DOFs; C multisine 0.1-10 Hz; axes one DOF at a time over its "
                        "whole range (the pure-axis coefficients measured, and checked, "
                        "rather than extrapolated); fourier Fourier-series "
                        "trajectories; optimal Fourier-series references optimised for the "
                        "damping regressor's condition number within the speed and thrust "
                        "limits (designed at start, ~20 s; better conditioned than B, but B "
                        "identified as well or better in our tests, see the README) "
                        "(default: B)")


def add_columns_option(p: argparse.ArgumentParser) -> None:
    """--columns: the column map of a CSV log."""
    p.add_argument("--columns", metavar="YAML",
                   help="YAML file mapping a CSV log's column names to ours ('their name: "
                        "our name', at the top level or under 'columns:'); 'ax: acc_x' or "
                        "'ax: ax', 'wx: gyro_x' or 'wx: wx' settle what ax..az and wx..wz "
                        "are (see above)")


def add_cutoff_option(p: argparse.ArgumentParser, zero: str = "") -> None:
    """--cutoff: the low-pass of the regression (``zero``: what 0 means, when allowed)."""
    p.add_argument("--cutoff", type=float, default=2.0, metavar="HZ",
                   help="low-pass (Hz) of the force regression and its scores (default: 2"
                        + (f"; 0: {zero}" if zero else "") + ")")


def add_dask_options(p: argparse.ArgumentParser) -> None:
    """--workers, --scheduler: where several logs are read (Dask)."""
    p.add_argument("--workers", type=int, metavar="N",
                   help="several logs: Dask worker processes of the local cluster, at most "
                        "one per log and one per CPU (more is capped to that, with a note: "
                        "a worker reads one log at a time) (default: the CPU count)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="several logs: the address of a running Dask scheduler (e.g. "
                        "tcp://10.0.0.5:8786) instead of a local cluster; the workers must "
                        "see the log paths")


def tau_topic(topics: dict[str, str]) -> str:
    """The topic τ comes from: the body wrench, else the thruster telemetry."""
    return topics.get("wrench") or topics["thrusters"]


def add_preprocess_options(p: argparse.ArgumentParser) -> None:
    """Options of the preprocessing (sample rate, filter, delay)."""
    p.add_argument("--rate", type=float, default=50.0, metavar="HZ",
                   help="sample rate of the synchronised data in Hz (default: 50)")
    p.add_argument("--max-gap", type=float, default=1.0, metavar="S",
                   help="DVL gaps longer than this (s) split the data (default: 1)")
    p.add_argument("--delay", default="0", metavar="S|auto",
                   help="delay (s) of the vehicle's response after the logged thrust, or "
                        "'auto' to estimate it (the delay that fits best, printed with its σ) "
                        "and correct it (default: 0)")
    p.add_argument("--accept-frames", action="store_true",
                   help="take a bag whose IMU frames look wrong (gravity sign, tilt, yaw "
                        "rate against heading: refused by default, one line saying which) "
                        "as it is, with the findings as warnings")


#: Seconds a step runs before its progress line appears (a quicker one prints none).
PROGRESS_AFTER = 5.0


class Progress:
    """A one-line progress bar on stderr for a long loop: silent for its first ``after``
    seconds (from its creation), then redrawn at each whole percent; the line ends at 100 %."""

    def __init__(self, label: str, after: float = PROGRESS_AFTER) -> None:
        self.label, self.shown = label, -1
        self.start_at = time.monotonic() + after

    def __call__(self, done: int, total: int) -> None:
        """Redraw at each whole percent; finish the line at 100 %."""
        pct = min(100, 100 * done // max(total, 1))
        if pct == self.shown or (self.shown < 0 and time.monotonic() < self.start_at):
            return
        self.shown = pct
        bar = "#" * (pct // 4) + "." * (25 - pct // 4)
        sys.stderr.write(f"\r{self.label} [{bar}] {pct:3d}% {done}/{total}")
        if pct == 100:
            sys.stderr.write("\n")
        sys.stderr.flush()


def check_outputs(args: argparse.Namespace, files: Mapping[str, str],
                  dirs: Sequence[str] = ()) -> None:
    """Refuse, before any work, an output option the command could not write at its end.

    Parameters
    ----------
    args : Namespace
        The parsed options; an option not given (None) is skipped.
    files : mapping
        Destination of a file option (``out``, ``drift_plot``) → an example file name for
        the message (``model.yaml``): the path must not be a directory and its directory
        must exist and be writable (nothing is created).
    dirs : sequence of str
        Destinations of directory options (``report``), created with their parents: the
        path must not be a file, nor lie under one, and must be creatable.

    Raises
    ------
    OSError
        One line: the option, the path as given, what is wrong and the fix.
    """
    for dest, example in files.items():
        if (given := getattr(args, dest, None)) is not None:
            _check_file(str(given), "--" + dest.replace("_", "-"), example)
    for dest in dirs:
        if (given := getattr(args, dest, None)) is not None:
            _check_dir(str(given), "--" + dest.replace("_", "-"))


def _check_file(given: str, option: str, example: str) -> None:
    """:func:`check_outputs` of one file option."""
    path = Path(given)
    if path.is_dir():
        raise IsADirectoryError(f"{option} {given}: is a directory; give the file to write, "
                                f"e.g. {option} {path / example}")
    parent = path.parent
    if not parent.exists():
        raise FileNotFoundError(f"{option} {given}: the directory {parent} does not exist; "
                                f"create it (mkdir -p {parent}) or give another path")
    _check_writable(parent, given, option)


def _check_dir(given: str, option: str) -> None:
    """:func:`check_outputs` of one directory option (created later, parents too)."""
    path = Path(given)
    if path.exists() and not path.is_dir():
        raise NotADirectoryError(f"{option} {given}: is a file; give a directory (created "
                                 "if missing)")
    existing = next((p for p in (path, *path.parents) if p.exists()), Path.cwd())
    if existing != path:
        _check_writable(existing, given, option)


def _check_writable(directory: Path, given: str, option: str) -> None:
    """Refuse ``given`` when ``directory``, where it is to be created, is a file or is not
    writable."""
    if not directory.is_dir():
        raise NotADirectoryError(f"{option} {given}: {directory} is a file, not a directory; "
                                 "give another path")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise PermissionError(f"{option} {given}: the directory {directory} is not "
                              "writable; give another path")


class Elapsed:
    """A progress line on stderr for a step without a loop to count: silent for its first
    ``after`` seconds, then ``label: N s`` redrawn every second by a thread of its own, ended
    with the total time. Use as a context manager around the step."""

    def __init__(self, label: str, after: float = PROGRESS_AFTER) -> None:
        self.label, self.after = label, after
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._draw, name="progress", daemon=True)
        self._t0 = 0.0
        self.shown = False

    def __enter__(self) -> Elapsed:
        self._t0 = time.monotonic()
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        if self.shown:
            sys.stderr.write(f"\r{self.label}: done in {time.monotonic() - self._t0:.0f} s\n")
            sys.stderr.flush()

    def _draw(self) -> None:
        if self._stop.wait(self.after):
            return
        while True:
            self.shown = True
            sys.stderr.write(f"\r{self.label}: {time.monotonic() - self._t0:.0f} s")
            sys.stderr.flush()
            if self._stop.wait(1.0):
                return


def add_window_options(p: argparse.ArgumentParser) -> None:
    """--start, --end: the part of the log to use."""
    p.add_argument("--start", type=float, metavar="S",
                   help="use the log from S seconds after its first sample (the first "
                        "synchronised sample of a bag, the first row of a CSV; default: 0)")
    p.add_argument("--end", type=float, metavar="E",
                   help="use the log up to E seconds after its first sample (default: its end)")


def table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A plain-text table with right-aligned columns."""
    cells = [[str(h) for h in header]] + [[_fmt(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    lines = ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _fmt(x: object) -> str:
    if isinstance(x, numbers.Real) and not isinstance(x, numbers.Integral):
        return f"{x:.4g}" if math.isfinite(x) else "—"
    return str(x)


def speed_table(samples_nu: np.ndarray) -> str:
    """Min / max / RMS of each velocity component; ``samples_nu`` shape (N, 6), m/s and
    rad/s."""
    from dampest_ros.core.physics.rigid_body import DOF_NAMES  # numpy: not for --help

    rows = [(DOF_NAMES[i], float(samples_nu[:, i].min()), float(samples_nu[:, i].max()),
             math.sqrt(float((samples_nu[:, i] ** 2).mean()))) for i in range(6)]
    return table(("dof", "min", "max", "rms"), rows)


def term_list(text: str | None) -> list[str]:
    """The term kinds of a ``--terms`` comma list (empty: all terms)."""
    return [k.strip() for k in (text or "").split(",") if k.strip()]
