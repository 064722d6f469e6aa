"""Reading and checking the inputs of identify, validate and gap: logs (bag or CSV), model
files, and the options that depend on the log (rate, cutoff, delay, time window, hold-out).

Imported by the commands' run functions only: it pulls in numpy and the core (their
``--help`` does not need it).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from dampest_ros.cli.common import Progress, tau_topic, term_list, topic_roles
from dampest_ros.core.identification.delay import profile_delay, shift_tau
from dampest_ros.core.identification.model import Model
from dampest_ros.core.online.estimator import nominal_of, restrict
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import ConfigError, RigidBody
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.plausibility import frame_notes
from dampest_ros.core.signals.preprocess import DataError, PreprocessConfig, preprocess
from dampest_ros.core.signals.samples import Samples
from dampest_ros.io.bag import (
    BagSource,
    MissingTopicError,
    bag_summary,
    check_role_types,
    is_bag,
)
from dampest_ros.io.csv import is_csv, load_column_map, read_log
from dampest_ros.io.csv_folder import folder_notes, is_csv_folder, resolve_topic
from dampest_ros.io.yaml_io import load_model


def bag_topics(path: Path, vehicle: Vehicle, args: argparse.Namespace) -> dict[str, str]:
    """:func:`topic_roles` of a bag (or CSV folder: its topics that the options name),
    after checking that it holds messages (DataError: an empty recording) and that τ can be
    had: without ``--wrench-topic`` it comes from thruster telemetry, which needs the
    vehicle's thrusters (ConfigError naming both ways)."""
    summary = bag_summary(path)
    if not summary.message_count:
        raise DataError(f"{path} holds no message: was anything published while it was "
                        "recorded, on the recorder's ROS_DOMAIN_ID? (dampest inspect "
                        f"{path} lists its topics)")
    topics = topic_roles(args)
    if is_csv_folder(path):  # a topic option may name a file of the folder
        topics = {role: resolve_topic(path, t) for role, t in topics.items()}
    if "wrench" not in topics:
        vehicle.need_thrusters(f"τ from the thruster telemetry of {path.name} "
                               f"({topics['thrusters']})",
                               "give --wrench-topic TOPIC (a body wrench in the bag)")
    check_role_types(summary, topics)
    return topics


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
        The samples are made at ``--rate`` (a bag): the rate is checked. ``--delay`` shifts
        τ in either case (a CSV's τ columns by :func:`delayed`).
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
    if not (math.isfinite(delay) and (delay == 0 or 0 < delay < span)):  # 0: no shift
        raise ConfigError("--delay", f"{delay:g} s: must be ≥ 0 and shorter than the log "
                                     f"({span:.1f} s); typical thrust delays are 0-0.5 s, or "
                                     "give 'auto'")
    return delay


def load_samples(path: str, vehicle: Vehicle, args: argparse.Namespace,
                 substitutions: list[str] | None = None) -> Samples:
    """Samples from a rosbag2 directory (MCAP or SQLite3), a ROS 1 ``.bag`` file, a folder of
    per-topic CSV files (read as a bag, :mod:`dampest_ros.io.csv_folder`) or a CSV file,
    after :func:`check_options`; what was read how (time units, flavours) on stderr, and each
    signal a bag lacks and what replaced it on stderr and appended to ``substitutions``
    (:mod:`dampest_ros.core.signals.sources`)."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p} does not exist")
    if not args.max_gap >= 0:  # before the preprocessing's own check, which names no option
        raise ConfigError("--max-gap", f"{args.max_gap:g} s: must be ≥ 0 (DVL gaps longer "
                                       "than this split the data); the default is 1")
    if p.is_file() and is_csv(p):
        cmap = load_column_map(args.columns) if getattr(args, "columns", None) else None
        samples, notes = read_log(p, vehicle.thrusters, vehicle.body.gravity, cmap,
                                  max_gap=args.max_gap)
        for note in notes:
            print(f"{p.name}: {note}", file=sys.stderr)
        given = check_options(args, samples.rate, float(samples.t[-1] - samples.t[0]),
                              resample=False)
        return delayed(samples, vehicle, given)
    if not is_bag(p):
        raise DataError(f"{p}: expected a rosbag2 directory, a ROS 1 .bag file, a folder of "
                        "per-topic CSV files or a .csv / .csv.gz file")
    if is_csv_folder(p):
        for note in folder_notes(p):
            print(f"{p.name}: {note}", file=sys.stderr)
    return _bag_samples(p, vehicle, args, substitutions)


def _bag_samples(p: Path, vehicle: Vehicle, args: argparse.Namespace,
                 substitutions: list[str] | None) -> Samples:
    """Samples of a bag (rosbag2, ROS 1 or a CSV folder), after :func:`check_options`; the
    bag is read a window at a time as the preprocessing needs it, so memory stays flat with
    its length."""
    if getattr(args, "columns", None):
        raise ConfigError("--columns", f"renames the columns of a CSV log; {p} is a bag "
                                       "(give its topics with --imu-topic, --dvl-topic, …)")
    topics = bag_topics(p, vehicle, args)
    cfg = PreprocessConfig(max_gap=args.max_gap)
    with BagSource(p, progress=Progress(f"processing {p.name} (s of log)"),
                   together=[topics["imu"], tau_topic(topics)],
                   whole=[topics["dvl"], topics["pressure"]]) as rec:
        given = check_options(args, args.rate, rec.summary.duration, resample=True,
                              min_rate=2 * cfg.cutoff)
        auto = given is None
        cfg = replace(cfg, rate=args.rate, delay=0.0 if given is None else given)
        check_frames(rec, topics, rec.summary.start, vehicle.body.gravity, p.name,
                     getattr(args, "accept_frames", False))
        id_notes: list[str] = []
        subs: list[str] = []
        samples = preprocess(rec, vehicle, cfg, topics, notes=id_notes, substitutions=subs)
        for note in id_notes:  # a frame_id other than the vehicle file's sensors: section
            print(f"{p.name}: warning: {note}", file=sys.stderr)
        for line in subs:
            print(f"{p.name}: {line}", file=sys.stderr)
        if substitutions is not None:
            substitutions.extend(subs)
        if auto:
            delay = estimated_delay(samples, vehicle)
            samples = preprocess(rec, vehicle, replace(cfg, delay=delay), topics)
    return samples


def estimated_delay(samples: Samples, vehicle: Vehicle) -> float:
    """``--delay auto``: the delay (s) of the response after τ that fits best
    (:func:`~dampest_ros.core.identification.delay.profile_delay`), printed with its σ, and
    a warning when it sits at an end of the search."""
    found = profile_delay(samples, vehicle.damping, vehicle.body)
    print(f"estimated delay of the response after the thrust: {found.delay * 1000:.1f} ms ± "
          f"{found.std * 1000:.2g} ms (statistical; up to ±{500 / samples.rate:.0f} ms more if "
          "τ is stamped at the start or end of its sample period)", file=sys.stderr)
    if found.at_bound:
        print(f"warning: the delay found is at the end of the searched "
              f"{found.bounds[0]:g}..{found.bounds[1]:g} s: the true one may lie beyond; give "
              "--delay S", file=sys.stderr)
    return found.delay


def delayed(samples: Samples, vehicle: Vehicle, delay: float | None) -> Samples:
    """Samples of a CSV log with τ delayed by ``--delay`` (None: ``auto``,
    :func:`estimated_delay`); the samples themselves when it is 0."""
    if delay is None:
        delay = estimated_delay(samples, vehicle)
    return shift_tau(samples, delay) if delay else samples


#: Seconds at the start of a log whose messages the frame plausibility checks read.
PLAUSIBILITY_SECONDS = 300.0


def check_frames(source: BagSource, topics: dict[str, str], start: float, gravity: float,
                 name: str, accept: bool) -> None:
    """Check the frames of the first :data:`PLAUSIBILITY_SECONDS` of the used topics
    (:func:`~dampest_ros.core.signals.plausibility.frame_notes`): a never-changing field is a
    warning line; a frame mistake refuses the log (one line with the first, the others as
    warnings), unless ``accept`` (``--accept-frames``), when they are warnings too.

    Raises
    ------
    DataError
        A frame mistake, and ``accept`` is false.
    """
    have = set(source.topics())
    try:
        head = {t: source.series(t, start, start + PLAUSIBILITY_SECONDS)
                for t in dict.fromkeys(topics.values()) if t.lstrip("/") in have}
    except MissingTopicError:  # a topic read with it is missing: the preprocessing says so
        return
    found = frame_notes(head, gravity)
    shown = found.warnings + (found.errors if accept else found.errors[1:])
    for note in shown:
        print(f"{name}: warning: {note}", file=sys.stderr)
    if found.errors and not accept:
        raise DataError(f"{name}: {found.errors[0]}; fix the log's frames, or give "
                        "--accept-frames if they are right")


def structure_of(args: argparse.Namespace, vehicle: Vehicle
                 ) -> tuple[DampingModel, np.ndarray]:
    """The terms to identify and their nominal θ: the model file's of ``--structure`` (the
    vehicle's θ where it has the parameter, else 0), or the preset's (``--terms`` kinds).

    Raises
    ------
    ConfigError
        ``--structure`` with ``--terms`` or ``--select``, or a file without a term structure.
    """
    if not args.structure:
        return restrict(vehicle.damping, vehicle.theta, term_list(args.terms))
    given = [o for o, used in (("--terms", args.terms), ("--select", args.select)) if used]
    if given:
        raise ConfigError("--structure", f"the terms come from {args.structure}; leave out "
                                         f"{' and '.join(given)}")
    mf = load_model(args.structure)
    if mf.damping is None:
        raise ConfigError("--structure", f"{args.structure} holds no term structure "
                                         "(model.terms); give a model file written by "
                                         "dampest identify or an estimator node")
    return mf.damping, nominal_of(mf.damping, vehicle.damping, vehicle.theta)


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


def believed_body(vehicle: Vehicle, mf: Model) -> RigidBody:
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


def warn_unchecked(warning: str | None) -> None:
    """Print the warning of :meth:`Model.belongs_to
    <dampest_ros.core.identification.model.Model.belongs_to>` on stderr, if any."""
    if warning is not None:
        print(f"warning: {warning}", file=sys.stderr)


def load_model_for(path: str, vehicle: Vehicle) -> tuple[Model, DampingModel, RigidBody]:
    """A model file with its term structure (the vehicle preset's when the file has none and
    the same parameters) and the body it implies (:func:`believed_body`); a model of another
    vehicle is refused (ConfigError naming both), one without an identity warned about on
    stderr."""
    mf = load_model(path)
    warn_unchecked(mf.belongs_to(vehicle.identity, path))
    model = mf.damping
    if model is None:
        if mf.parameter_names != vehicle.damping.parameter_names:
            raise ConfigError("model.terms", f"{path} has no term structure and its "
                              "parameters differ from the vehicle preset's")
        model = vehicle.damping
    return mf, model, believed_body(vehicle, mf)


