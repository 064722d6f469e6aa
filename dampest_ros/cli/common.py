"""Helpers shared by the ``dampest`` sub-commands: inputs, tables, terms."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from dampest_ros.core.preprocess import DataError, PreprocessConfig, preprocess
from dampest_ros.core.rigid_body import DOF_NAMES
from dampest_ros.core.samples import Samples
from dampest_ros.core.selection import profile_delay
from dampest_ros.core.vehicle import Vehicle
from dampest_ros.io.bag import BagSource
from dampest_ros.io.csv import load_column_map, read_csv, samples_from_columns

#: Topic roles and their default names (DESIGN.md §3).
DEFAULT_TOPICS = {"imu": "imu/data", "dvl": "dvl/twist", "pressure": "pressure",
                  "thrusters": "thrusters/state"}


def add_topic_options(p: argparse.ArgumentParser) -> None:
    """--imu-topic, --dvl-topic, --pressure-topic, --thrusters-topic."""
    for role, name in DEFAULT_TOPICS.items():
        p.add_argument(f"--{role}-topic", default=name, metavar="TOPIC",
                       help=f"topic of the {role} data (default: {name})")


def add_preprocess_options(p: argparse.ArgumentParser) -> None:
    """Options of the preprocessing (sample rate, filter, delay)."""
    p.add_argument("--rate", type=float, default=50.0,
                   help="sample rate of the synchronised data in Hz (default: 50)")
    p.add_argument("--max-gap", type=float, default=1.0,
                   help="DVL gaps longer than this (s) split the data (default: 1)")
    p.add_argument("--delay", default="0",
                   help="delay (s) of the vehicle's response after the logged thrust, or "
                        "'auto' to estimate it by cross-correlation and correct it (default: 0)")


class Progress:
    """A one-line progress bar on stderr for long inputs (silent below ``minimum`` items)."""

    def __init__(self, label: str, minimum: int = 200_000) -> None:
        self.label, self.minimum, self.shown = label, minimum, -1

    def __call__(self, done: int, total: int) -> None:
        """Redraw at each whole percent; finish the line at 100 %."""
        if total < self.minimum:
            return
        pct = min(100, 100 * done // max(total, 1))
        if pct == self.shown:
            return
        self.shown = pct
        bar = "#" * (pct // 4) + "." * (25 - pct // 4)
        sys.stderr.write(f"\r{self.label} [{bar}] {pct:3d}% {done}/{total}")
        if pct == 100:
            sys.stderr.write("\n")
        sys.stderr.flush()


def load_samples(path: str, vehicle: Vehicle, args: argparse.Namespace) -> Samples:
    """Samples from a rosbag2 directory (MCAP or SQLite3) or a CSV file."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p} does not exist")
    if p.is_file() and p.suffix.lower() == ".csv":
        cmap = load_column_map(args.columns) if getattr(args, "columns", None) else None
        return samples_from_columns(read_csv(p, cmap), max_gap=args.max_gap)
    if not p.is_dir():
        raise DataError(f"{p}: expected a rosbag2 directory or a .csv file")
    topics = {role: getattr(args, f"{role}_topic") for role in DEFAULT_TOPICS}
    # windows are read as the preprocessing needs them: memory stays flat with bag length
    rec = BagSource(p, progress=Progress(f"processing {p.name} (s of log)", minimum=600),
                    together=[topics["imu"], topics["thrusters"]])
    auto = str(args.delay).strip().lower() == "auto"
    try:
        delay = 0.0 if auto else float(args.delay)
    except ValueError:
        raise DataError(f"--delay must be a number of seconds or 'auto', got {args.delay!r}"
                        ) from None
    cfg = PreprocessConfig(rate=args.rate, max_gap=args.max_gap, delay=delay)
    samples = preprocess(rec, vehicle.thrusters, vehicle.body.gravity, vehicle.body.rho, cfg,
                         topics)
    if auto:
        delay = profile_delay(samples, vehicle.damping, vehicle.body)
        print(f"estimated delay of the response after the thrust: {delay * 1000:.0f} ms",
              file=sys.stderr)
        samples = preprocess(rec, vehicle.thrusters, vehicle.body.gravity, vehicle.body.rho,
                             replace(cfg, delay=delay), topics)
    return samples


def table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A plain-text table with right-aligned columns."""
    cells = [[str(h) for h in header]] + [[_fmt(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    lines = ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _fmt(x: object) -> str:
    if isinstance(x, float | np.floating):
        return "—" if not np.isfinite(x) else f"{x:.4g}"
    return str(x)


def speed_table(samples_nu: np.ndarray) -> str:
    """Min / max / RMS of each velocity component."""
    rows = [(DOF_NAMES[i], float(samples_nu[:, i].min()), float(samples_nu[:, i].max()),
             float(np.sqrt(np.mean(samples_nu[:, i] ** 2)))) for i in range(6)]
    return table(("dof", "min", "max", "rms"), rows)


def term_list(text: str | None) -> list[str]:
    """The term kinds of a ``--terms`` comma list (empty: all terms)."""
    return [k.strip() for k in (text or "").split(",") if k.strip()]
