"""Helpers shared by the ``dampest`` sub-commands: inputs, tables, terms."""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from dampest_ros.core.damping import DampingModel
from dampest_ros.core.preprocess import DataError, PreprocessConfig, preprocess
from dampest_ros.core.rigid_body import DOF_NAMES, ConfigError, RigidBody
from dampest_ros.core.samples import Samples
from dampest_ros.core.selection import profile_delay
from dampest_ros.core.vehicle import Vehicle
from dampest_ros.io.bag import BagSource, bag_summary, check_role_types
from dampest_ros.io.csv import is_csv, load_column_map, read_log
from dampest_ros.io.yaml_io import ModelFile, load_model

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
    "through the water (water-track DVL) is read the same way.")

#: Topic roles and their default names (docs/architecture.md §3).
DEFAULT_TOPICS = {"imu": "imu/data", "dvl": "dvl/twist", "pressure": "pressure",
                  "thrusters": "thrusters/state"}


def add_topic_options(p: argparse.ArgumentParser) -> None:
    """--imu-topic, --dvl-topic, --pressure-topic, --thrusters-topic, --wrench-topic."""
    for role, name in DEFAULT_TOPICS.items():
        p.add_argument(f"--{role}-topic", default=name, metavar="TOPIC",
                       help=f"topic of the {role} data (default: {name})")
    p.add_argument("--wrench-topic", metavar="TOPIC",
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


def bag_topics(path: Path, vehicle: Vehicle, args: argparse.Namespace) -> dict[str, str]:
    """:func:`topic_roles` of a bag, after checking that τ can be had: without
    ``--wrench-topic`` it comes from thruster telemetry, which needs the vehicle's thrusters
    (ConfigError naming both ways)."""
    topics = topic_roles(args)
    if "wrench" not in topics:
        vehicle.need_thrusters(f"τ from the thruster telemetry of {path.name} "
                               f"({topics['thrusters']})",
                               "give --wrench-topic TOPIC (a body wrench in the bag)")
    check_role_types(path, topics)
    return topics


def tau_topic(topics: dict[str, str]) -> str:
    """The topic τ comes from: the body wrench, else the thruster telemetry."""
    return topics.get("wrench") or topics["thrusters"]


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


#: Memory (bytes) per synchronised sample of identify, validate and gap, with margin: a
#: 120 s bag at 2000 Hz peaks 280 MB above the same bag at 50 Hz, about 1.2 kB a sample.
BYTES_PER_SAMPLE = 1500
#: Commands whose ``--cutoff 0`` means no low-pass (validate's scores as logged); for the
#: others the regression's low-pass needs a cutoff > 0.
CUTOFF_ZERO_IS_NONE = ("validate",)


def memory_bytes() -> float:
    """Physical memory of this machine (bytes; inf where the system does not say)."""
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return math.inf


def check_options(args: argparse.Namespace, rate: float, span: float, *,
                  resample: bool, min_rate: float = 0.0) -> float | None:
    """Refuse an absurd ``--rate``, ``--cutoff`` or ``--delay`` before any work is done.

    The one place these options are checked (identify, validate, gap; identify's rls path):
    each refusal is one ConfigError naming the option, the limit and the fix.

    Parameters
    ----------
    args : argparse.Namespace
        ``rate``, ``delay`` and, when the command has it, ``cutoff``.
    rate : float
        Sample rate of the samples (Hz): ``--rate`` for a bag, the CSV's own for a CSV.
    span : float
        Seconds of log.
    resample : bool
        The samples are made at ``--rate`` (a bag): the rate is checked, and ``--delay``
        shifts τ (a CSV's τ is used as logged: a delay is refused).
    min_rate : float
        Lowest acceptable ``--rate`` (Hz), e.g. twice the preprocessing's own low-pass.

    Returns
    -------
    float or None
        ``--delay`` in seconds; None for ``auto``.

    Raises
    ------
    ConfigError
        Naming ``--rate`` (not > ``min_rate``, or more samples than half this machine's
        memory holds), ``--cutoff`` (not in (0, rate/2); 0 passes for
        :data:`CUTOFF_ZERO_IS_NONE`) or ``--delay`` (not a number or ``auto``, negative, or
        not shorter than the log).
    """
    if resample:
        if not (math.isfinite(rate) and rate > min_rate):
            why = " (the preprocessing low-passes the sensors at half that)" if min_rate else ""
            raise ConfigError("--rate", f"{rate:g} Hz: must be above {min_rate:g} Hz{why}; "
                                        "the default is 50")
        need, have = rate * span * BYTES_PER_SAMPLE, 0.5 * memory_bytes()
        if need > have:
            raise ConfigError("--rate", f"{rate:g} Hz over {span:.0f} s of log would need "
                                        f"about {need / 1e9:.3g} GB, more than half this "
                                        f"machine's memory ({have / 1e9:.3g} GB); use --rate "
                                        f"{math.floor(have / (span * BYTES_PER_SAMPLE))} or "
                                        "less (default 50)")
    cutoff = getattr(args, "cutoff", None)
    if cutoff is not None:
        zero_ok = getattr(args, "command", None) in CUTOFF_ZERO_IS_NONE and cutoff == 0
        if not (math.isfinite(cutoff) and (cutoff > 0 or zero_ok) and cutoff < 0.5 * rate):
            raise ConfigError("--cutoff", f"{cutoff:g} Hz: must be above 0 and below the "
                                          f"Nyquist frequency {0.5 * rate:g} Hz (half the "
                                          f"{rate:g} Hz sample rate); the default is 2")
    text = str(getattr(args, "delay", "0")).strip().lower()
    if text == "auto":
        return None
    try:
        delay = float(text)
    except ValueError:
        raise ConfigError("--delay", f"must be a number of seconds or 'auto', got "
                                     f"{args.delay!r}") from None
    if not (math.isfinite(delay) and 0 <= delay < span):
        raise ConfigError("--delay", f"{delay:g} s: must be ≥ 0 and shorter than the log "
                                     f"({span:.1f} s); typical thrust delays are 0-0.5 s, or "
                                     "give 'auto'")
    if delay and not resample:
        raise ConfigError("--delay", "a CSV's tau is used as logged; shift its tau columns "
                                     "instead")
    return delay


def load_samples(path: str, vehicle: Vehicle, args: argparse.Namespace) -> Samples:
    """Samples from a rosbag2 directory (MCAP or SQLite3) or a CSV file, after
    :func:`check_options`."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p} does not exist")
    if p.is_file() and is_csv(p):
        cmap = load_column_map(args.columns) if getattr(args, "columns", None) else None
        samples, notes = read_log(p, vehicle.thrusters, vehicle.body.gravity, cmap,
                                  max_gap=args.max_gap)
        for note in notes:
            print(f"{p.name}: {note}", file=sys.stderr)
        check_options(args, samples.rate, float(samples.t[-1] - samples.t[0]),
                      resample=False)
        return samples
    if not p.is_dir():
        raise DataError(f"{p}: expected a rosbag2 directory or a .csv / .csv.gz file")
    topics = bag_topics(p, vehicle, args)
    cfg = PreprocessConfig(max_gap=args.max_gap)
    given = check_options(args, args.rate, bag_summary(p).duration, resample=True,
                          min_rate=2 * cfg.cutoff)
    auto = given is None
    delay = 0.0 if given is None else given
    cfg = replace(cfg, rate=args.rate, delay=delay)
    # windows are read as the preprocessing needs them: memory stays flat with bag length
    rec = BagSource(p, progress=Progress(f"processing {p.name} (s of log)", minimum=600),
                    together=[topics["imu"], tau_topic(topics)])
    samples = preprocess(rec, vehicle.thrusters, vehicle.body.gravity, vehicle.body.rho, cfg,
                         topics)
    if auto:
        delay = profile_delay(samples, vehicle.damping, vehicle.body)
        print(f"estimated delay of the response after the thrust: {delay * 1000:.0f} ms",
              file=sys.stderr)
        samples = preprocess(rec, vehicle.thrusters, vehicle.body.gravity, vehicle.body.rho,
                             replace(cfg, delay=delay), topics)
    return samples


def add_window_options(p: argparse.ArgumentParser) -> None:
    """--start, --end: the part of the log to use."""
    p.add_argument("--start", type=float, metavar="S",
                   help="use the log from S seconds after its first sample (the first "
                        "synchronised sample of a bag, the first row of a CSV; default: 0)")
    p.add_argument("--end", type=float, metavar="E",
                   help="use the log up to E seconds after its first sample (default: its end)")


def cut(samples: Samples, args: argparse.Namespace) -> Samples:
    """The samples between ``--start`` and ``--end`` (seconds from the first sample).

    Raises
    ------
    ConfigError
        Naming the option: not finite, start ≥ end, or beyond the log.
    """
    start, end = getattr(args, "start", None), getattr(args, "end", None)
    if start is None and end is None:
        return samples
    t0, span = float(samples.t[0]), float(samples.t[-1] - samples.t[0])
    tol = 0.5 / samples.rate if samples.rate > 0 else 1e-9
    where = f"the log spans 0 … {span:.2f} s from its first sample"
    for name, value in (("--start", start), ("--end", end)):
        if value is not None and not np.isfinite(value):
            raise ConfigError(name, f"must be a number of seconds, got {value}")
    if start is not None and not 0 <= start < span:
        raise ConfigError("--start", f"{start:g} s is beyond the log ({where})")
    if end is not None and not 0 < end <= span + tol:
        raise ConfigError("--end", f"{end:g} s is beyond the log ({where})")
    if start is not None and end is not None and start >= end:
        raise ConfigError("--start", f"{start:g} s is not before --end {end:g} s")
    lo = t0 + (start or 0.0) - 1e-9
    hi = t0 + end + 1e-9 if end is not None else np.inf
    part = samples.take((samples.t >= lo) & (samples.t <= hi))
    if len(part) < 2:
        raise ConfigError("--start" if start is not None else "--end",
                          f"--start/--end keep {len(part)} sample(s) ({where})")
    return part


#: Shortest stretch of data (s) a fit may be left with by ``--holdout``.
MIN_FIT_SECONDS = 10.0


def holdout_seconds(text: str, span: float) -> float:
    """Seconds held out by ``--holdout``: a fraction ≤ 1 of ``span`` (s), or seconds (a
    number > 1, or ``120s``)."""
    s = str(text).strip().lower()
    seconds = s.endswith("s")
    try:
        x = float(s[:-1] if seconds else s)
    except ValueError:
        raise ConfigError("--holdout", f"must be a fraction of the time (0.3) or seconds (120s),"
                          f" got {text!r}") from None
    if not np.isfinite(x) or x <= 0:
        raise ConfigError("--holdout", f"must be > 0, got {text!r}")
    return x if seconds or x > 1 else x * span


def split_holdout(samples: Samples, text: str) -> tuple[Samples, Samples]:
    """(fit, held out): the last ``--holdout`` of the time held out (:func:`holdout_seconds`).

    Raises
    ------
    ConfigError
        Naming ``--holdout``: not positive, beyond the log, no held-out sample, or less than
        :data:`MIN_FIT_SECONDS` of data left to fit.
    """
    span = float(samples.t[-1] - samples.t[0])
    h = holdout_seconds(text, span)
    if h >= span:
        raise ConfigError("--holdout", f"{h:.4g} s is beyond the log, which spans {span:.2f} s")
    held = samples.t > samples.t[-1] - h
    rest = samples.take(~held)
    fit_seconds = len(rest) / samples.rate if samples.rate > 0 else 0.0
    if fit_seconds < MIN_FIT_SECONDS:
        raise ConfigError("--holdout", f"holding out {h:.4g} s leaves {fit_seconds:.1f} s to "
                          f"fit; at least {MIN_FIT_SECONDS:g} s are needed")
    if held.sum() < 2:
        raise ConfigError("--holdout", f"{h:.4g} s holds out {int(held.sum())} sample(s); "
                          "hold out more")
    return rest, samples.take(held)


def believed_body(vehicle: Vehicle, mf: ModelFile) -> RigidBody:
    """The vehicle's rigid body with the model file's M (added mass = M − M_RB), its
    added-mass switches kept."""
    b = vehicle.body
    added = mf.M - b.M_RB
    if np.allclose(mf.M, b.M, rtol=1e-9, atol=1e-9):
        return b
    try:
        return RigidBody(b.mass, b.inertia, b.r_g, b.r_b, b.volume, 0.5 * (added + added.T),
                         b.rho, b.gravity, b.added_mass_terms)
    except ConfigError as exc:
        raise ConfigError("model.M", f"M − M_RB of the vehicle is not a valid added mass "
                                     f"({exc.reason}); is --vehicle the model's vehicle?"
                          ) from None


def load_model_for(path: str, vehicle: Vehicle) -> tuple[ModelFile, DampingModel, RigidBody]:
    """A model file with its term structure (the vehicle preset's when the file has none and
    the same parameters) and the body it implies (:func:`believed_body`)."""
    mf = load_model(path)
    model = mf.damping
    if model is None:
        if mf.parameter_names != vehicle.damping.parameter_names:
            raise ConfigError("model.terms", f"{path} has no term structure and its "
                              "parameters differ from the vehicle preset's")
        model = vehicle.damping
    return mf, model, believed_body(vehicle, mf)


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
