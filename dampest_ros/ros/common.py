"""Shared pieces of the nodes: QoS profiles, stamps, validated parameters, main()."""

from __future__ import annotations

import argparse
import contextlib
import inspect
import math
import re
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, TypeVar

import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.callback_groups import CallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rclpy.subscription import Subscription
from rclpy.utilities import remove_ros_args
from std_srvs.srv import SetBool, Trigger

from dampest_ros.core.physics.identity import Identity
from dampest_ros.ros.params_files import UnknownParameterError, params_files

#: Sensor topics: the sensor-data policies (best effort, volatile) with a deeper queue than
#: its 5, for the bursts of a simulator running faster than real time.
SENSOR_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=2000,
                        reliability=qos_profile_sensor_data.reliability,
                        durability=qos_profile_sensor_data.durability)
#: Sample and command topics: reliable, keep last 200 (bursts when faster than real time).
RELIABLE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=200,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)
#: Where every node publishes its diagnostic_msgs/DiagnosticArray (absolute: the aggregator
#: listens there whatever the node's namespace).
DIAGNOSTICS_TOPIC = "/diagnostics"
#: Seconds after its start during which a node started by :func:`main_for` looks in the
#: graph for another node of its fully qualified name (and refuses to run if there is one).
DUPLICATE_WINDOW = 3.0
#: ``dampest/model``: reliable, transient local, keep last 1 (late joiners get the model).
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)


#: Turns of :class:`Drain` per callback (:meth:`ParamNode.create_subscription`): at least
#: what one sim tick publishes per topic.
DRAIN_LIMIT = 500


class TakenElsewhere(CallbackGroup):
    """A callback group that executors never wait on or run: its subscriptions are read
    by their owner (the :class:`Drain` group they belong to, or a take thread of their
    own)."""

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


def takes_info(callback: Callable[..., Any]) -> bool:
    """Whether rclpy gives a subscription ``callback`` the message info too: it decides by
    the signature (one argument: the message; two: the message and its info)."""
    try:
        inspect.signature(callback).bind(object())
    except TypeError:
        return True
    return False


def same_arity(callback: Callable[..., Any], run: Callable[..., None]) -> Callable[..., None]:
    """A subscription callback that takes what ``callback`` takes (:func:`takes_info`) and
    passes it to ``run``: for wrapping a callback without changing what rclpy hands it."""
    if takes_info(callback):
        def with_info(msg: Any, info: Any) -> None:
            run(msg, info)

        return with_info

    def message_only(msg: Any) -> None:
        run(msg)

    return message_only


class Drain:
    """Subscriptions whose callbacks, after the message the executor gave them, also take
    the messages already queued on every subscription of the group: one from each in turn,
    for at most ``limit`` turns, deserialised (or bytes, raw) as the executor takes them.

    rclpy's executors take one message per subscription per wait round, and each round
    rebuilds the wait set of every node in Python (~150–200 µs), so a subscription that
    receives bursts falls behind a timer that is ready every round, and topics published
    together (the four dampest/* messages of a sample) cost a round each; taken here they
    cost a fraction of that. Taking in turns keeps the topics of a group in step.

    Members in the callback group :attr:`passive` do not wake the executor at all: their
    messages wait in their queues for the next message of an active member (or
    :meth:`take`), e.g. the topics that a publisher sends before the one that completes a
    sample.
    """

    def __init__(self, limit: int = DRAIN_LIMIT) -> None:
        self.limit = int(limit)
        self.passive: CallbackGroup = TakenElsewhere()
        self._members: list[tuple[Subscription, Callable[[tuple[Any, Any]], None]]] = []

    def add(self, sub: Subscription) -> None:
        """Make ``sub`` a member: its callback (taking the message, or the message and its
        info, as rclpy decides by the signature) is wrapped."""
        callback = sub.callback
        info = takes_info(callback)

        def deliver(taken: tuple[Any, Any]) -> None:
            callback(*(taken if info else taken[:1]))

        def run(*args: Any) -> None:
            callback(*args)
            self.take()

        sub.callback = same_arity(callback, run)
        self._members.append((sub, deliver))

    def take(self) -> None:
        """Hand the queued messages to the callbacks, one per subscription and turn."""
        for _ in range(self.limit):
            took = False
            for sub, deliver in self._members:
                with sub.handle:
                    taken = sub.handle.take_message(sub.msg_type, sub.raw)
                if taken is not None:
                    deliver(taken)
                    took = True
            if not took:
                return


class TransportLosses:
    """Messages lost between a topic's publisher and a subscription (a reader queue that
    overflowed, a best-effort sample the network dropped), counted from the gaps in the
    publication sequence numbers of the messages taken (rmw message info; Fast DDS raises no
    message-lost event for them).

    A gap counts only while the subscription has one matched publisher (several interleave
    their numbers); a number that goes back (a restarted publisher) starts the topic afresh.
    """

    def __init__(self) -> None:
        self.count = 0
        self._last: dict[str, int] = {}

    def seen(self, sub: Subscription, info: dict[str, Any]) -> None:
        """Note a message taken from ``sub`` with its message ``info``."""
        seq = info.get("publication_sequence_number")
        if seq is None:
            return
        last = self._last.get(sub.topic_name)
        self._last[sub.topic_name] = int(seq)
        if last is not None and seq > last + 1 and sub.get_publisher_count() == 1:
            self.count += int(seq) - last - 1


#: Wall-clock seconds without a message after which a node's input counts as quiet.
QUIET_PERIOD = 0.5


class QuietFlush:
    """Calls ``flush()`` once a node's input has gone quiet: messages arrived
    (:meth:`arrived`) since the last flush and none in the last ``period`` seconds.

    The timer runs on the steady (wall) clock, not on the node's: with use_sim_time the
    node's clock stops with /clock, as at the end of a replayed bag, and what the node held
    back (a stamp-order window, samples not yet in a publication) would never be delivered.
    While messages keep coming, it never fires.

    Parameters
    ----------
    node : Node
    flush : callable
        What to do once quiet (called from the executor).
    period : float
        Seconds (wall clock) between looks; quiet means nothing arrived during one.
    """

    def __init__(self, node: Node, flush: Callable[[], None],
                 period: float = QUIET_PERIOD) -> None:
        self.flush = flush
        self._arrived = self._at_look = self._at_flush = 0
        self.timer = node.create_timer(period, self._look,
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))

    def arrived(self) -> None:
        """Note a message."""
        self._arrived += 1

    def _look(self) -> None:
        if self._arrived == self._at_look != self._at_flush:
            self._at_flush = self._arrived
            self.flush()
        self._at_look = self._arrived


def to_time(t: float) -> Time:
    """builtin_interfaces/Time from seconds (rounded to the nanosecond)."""
    from dampest_ros.core.signals.samples import wire_stamp  # (numpy: not at a node's start)

    ns = wire_stamp(t)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_ns(stamp: Time) -> int:
    """Integer nanoseconds of a stamp (exact, for matching)."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def seconds(stamp: Time | int) -> float:
    """Seconds of a stamp (or of its integer nanoseconds): the float nearest to it, as
    dampest_ros.io.cdr.stamps_from_ros gives the stamps of a bag (ns × 1e-9 can differ by
    one unit in the last place)."""
    return (stamp if isinstance(stamp, int) else stamp_ns(stamp)) / 1e9


@dataclass(frozen=True)
class Param:
    """A declared parameter: default, one-line description, range or choices, validator.

    ``check`` returns an error text for an invalid value (None when valid); ranges and
    choices are checked by :func:`declare` as well, so every rejection names its reason.
    """

    name: str
    default: Any
    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()
    check: Callable[[Any], str | None] | None = None
    read_only: bool = False
    type_: Parameter.Type | None = None


def _descriptor(p: Param) -> ParameterDescriptor:
    d = ParameterDescriptor(description=p.description, read_only=p.read_only)
    extra = f" One of: {', '.join(p.choices)}." if p.choices else ""
    d.description = p.description + extra
    if p.low is not None and p.high is not None:
        if isinstance(p.default, bool):
            pass
        elif isinstance(p.default, int):
            d.integer_range = [IntegerRange(from_value=int(p.low), to_value=int(p.high), step=0)]
        else:
            d.floating_point_range = [FloatingPointRange(from_value=float(p.low),
                                                         to_value=float(p.high), step=0.0)]
    if p.type_ is not None:
        d.type = p.type_.value
    return d


def _type_reason(p: Param, value: Any) -> str | None:
    """Why ``value`` has the wrong type for ``p`` (that of its default; an integer is a
    number too), or None."""
    d = p.default
    number = isinstance(value, int | float) and not isinstance(value, bool)
    if isinstance(d, bool):
        ok, what = isinstance(value, bool), "true or false"
    elif isinstance(d, int):
        ok, what = number and isinstance(value, int), "an integer"
    elif isinstance(d, float):
        ok, what = number, "a number"
    elif isinstance(d, str):
        ok, what = isinstance(value, str), "text (quote a number: -p name:=\"'5'\")"
    elif isinstance(d, list):
        ok, what = isinstance(value, list), "a list, e.g. [a, b]"
    else:
        return None
    return None if ok else f"{p.name} must be {what}, got {value!r}"


def validate(p: Param, value: Any) -> str | None:
    """The reason why ``value`` is invalid for ``p`` (type, choices, finiteness, range, its
    check), or None."""
    reason = _type_reason(p, value)
    if reason is not None:
        return reason
    if p.choices and value not in p.choices:
        return f"{p.name} must be one of {list(p.choices)}, got {value!r}"
    if isinstance(value, float) and not math.isfinite(value):
        return f"{p.name} must be finite, got {value!r}"
    if p.low is not None and isinstance(value, int | float) and not isinstance(value, bool) \
            and not p.low <= value <= (p.high if p.high is not None else math.inf):
        return f"{p.name} must be in [{p.low}, {p.high}], got {value!r}"
    if p.check is not None:
        return p.check(value)
    return None


def check_options(specs: Sequence[Param], params: dict[str, Any],
                  options: dict[str, str]) -> None:
    """Check a command's node parameters against the node's ``specs`` before the node starts.

    Parameters
    ----------
    specs : sequence of Param
        The node's declared parameters.
    params : dict
        Parameter name → value, from the command's options.
    options : dict
        Parameter name → the option that sets it (default ``--name-with-dashes``).

    Raises
    ------
    ValueError
        ``OPTION: reason`` for the first value a spec refuses.
    """
    for spec in specs:
        reason = validate(spec, params[spec.name]) if spec.name in params else None
        if reason is not None:
            option = options.get(spec.name, "--" + spec.name.replace("_", "-"))
            raise ValueError(f"{option}: {reason}")


def model_file_check(name: str) -> Callable[[Any], str | None]:
    """A :class:`Param` check for a parameter holding a model file path: '' passes, else the
    reason :func:`~dampest_ros.io.yaml_io.load_model` refuses the file (missing, not a model,
    non-finite numbers, …), prefixed with the parameter's name."""

    def check(value: Any) -> str | None:
        from dampest_ros.core.physics.rigid_body import ConfigError
        from dampest_ros.io.yaml_io import load_model

        if not str(value).strip():
            return None
        try:
            load_model(str(value))
        except (ConfigError, FileNotFoundError, ValueError, OSError) as exc:
            return f"{name}: {exc}"
        return None

    return check


def vehicle_check(value: Any) -> str | None:
    """A :class:`Param` check for a vehicle preset name or YAML path: the reason
    :func:`~dampest_ros.io.yaml_io.load_vehicle` refuses it, or None."""
    from dampest_ros.core.physics.rigid_body import ConfigError
    from dampest_ros.io.yaml_io import load_vehicle

    try:
        load_vehicle(str(value))
    except (ConfigError, FileNotFoundError, ValueError) as exc:
        return f"vehicle: {exc}"
    return None


def arm_problem(arm: str, lock: str) -> str | None:
    """Why arm ``arm`` (preset or URDF path) with the joints of ``lock`` (comma list) held
    fixed cannot be loaded (None: it can), prefixed with the parameter to blame."""
    from dampest_ros.io.arm import ArmDataError, joint_list, load_arm

    try:
        load_arm(str(arm), lock=joint_list(str(lock)))
    except ArmDataError as exc:
        return f"{'lock' if joint_list(str(lock)) else 'arm'}: {exc}"
    return None


def save_path_check(value: Any) -> str | None:
    """A :class:`Param` check for the file a node's ~/save writes: not empty, in an existing
    directory."""
    parent = Path(str(value)).expanduser().resolve().parent
    if not str(value).strip():
        return "save_path must not be empty"
    if not parent.is_dir():
        return f"save_path: directory {parent} does not exist"
    return None


def remove_orphaned_temp(path: Path) -> list[Path]:
    """Remove the temporary files a killed atomic write of ``path`` left next to it
    (``.<name>.*.tmp``, as :func:`dampest_ros.io.yaml_io.save_model` names them) that are
    older than a minute (a write in progress by another process is younger); returns the
    removed paths."""
    now = time.time()
    removed = []
    for tmp in path.parent.glob(f".{path.name}.*.tmp"):
        try:
            if now - tmp.stat().st_mtime > 60.0:
                tmp.unlink()
                removed.append(tmp)
        except FileNotFoundError:  # removed meanwhile by its writer
            continue
    return removed


class ParamNode(Node):
    """A node whose parameters are declared from :class:`Param` specs and validated on set;
    accepted changes go to :meth:`on_parameters` (after they are set). An override for a
    parameter it does not declare (a misspelt key of a params file) is refused with
    :class:`UnknownParameterError`, except under :attr:`OVERRIDE_PREFIXES`."""

    #: The process's exit status once the node has run (:func:`main_for`): a node whose job
    #: failed part-way (a replay cut short by a damaged bag) sets it, 0 otherwise.
    exit_status = 0

    #: Overrides under these prefixes are parameters the node declares later (``model.``).
    OVERRIDE_PREFIXES: tuple[str, ...] = ()

    def __init__(self, name: str, specs: Sequence[Param], **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self._specs = {p.name: p for p in specs}
        for p in specs:
            given = self._parameter_overrides.get(p.name)
            if given is not None:  # refused with our reason before rclpy's type/range checks
                reason = validate(p, given.value)
                if reason is not None:
                    raise ValueError(f"parameter {reason}")
                # '-p duration:=90', '[1, 0, 0]': integers are numbers
                self._parameter_overrides[p.name] = self._as_declared(given)
            self.declare_parameter(p.name, p.default, _descriptor(p))
            reason = validate(p, self.get_parameter(p.name).value)
            if reason is not None:
                raise ValueError(f"parameter {reason}")
        self._refuse_undeclared()
        self.add_pre_set_parameters_callback(
            lambda params: [self._as_declared(prm) for prm in params])
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

    def _refuse_undeclared(self) -> None:
        """Raise :class:`UnknownParameterError` for an override (params file, ``-p``) that
        names no parameter of this node (rclpy would ignore it)."""
        for name in self._parameter_overrides:
            if not self.has_parameter(name) and not name.startswith(self.OVERRIDE_PREFIXES):
                raise UnknownParameterError(name, list(self._specs), self.get_name())

    def _as_declared(self, prm: Parameter) -> Parameter:
        """``prm`` with integers made floats where the parameter is a double (or a list of
        doubles): ``-p rate:=2`` and ``ros2 param set … rate 2`` set 2.0, and the parameter
        stays a double."""
        spec = self._specs.get(prm.name)
        if spec is None or isinstance(prm.value, bool):
            return prm
        if isinstance(spec.default, float) and isinstance(prm.value, int):
            return Parameter(prm.name, Parameter.Type.DOUBLE, float(prm.value))
        if isinstance(spec.default, list) and spec.default and isinstance(
                spec.default[0], float) and isinstance(prm.value, list | tuple) and all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in prm.value):
            return Parameter(prm.name, Parameter.Type.DOUBLE_ARRAY, [float(v) for v in prm.value])
        return prm

    def create_subscription(self, msg_type: Any, topic: str, callback: Callable[..., None],
                            qos_profile: QoSProfile | int, *, drain: int | Drain = DRAIN_LIMIT,
                            **kwargs: Any) -> Subscription:
        """:meth:`rclpy.node.Node.create_subscription` whose callback also takes the messages
        already queued (:class:`Drain`): ``drain`` turns on this subscription alone (0: one
        message per executor round, as plain rclpy), or a group to join."""
        sub = super().create_subscription(msg_type, topic, callback, qos_profile, **kwargs)
        group = Drain(drain) if isinstance(drain, int) else drain
        if group.limit > 0:
            group.add(sub)
        return sub

    def p(self, name: str) -> Any:
        """The value of a parameter (numbers of float parameters as float)."""
        value = self.get_parameter(name).value
        spec = self._specs.get(name)
        if spec is not None and isinstance(spec.default, float):
            return float(value)
        return value

    def _check_parameters(self, params: list[Parameter]) -> SetParametersResult:
        for prm in params:
            spec = self._specs.get(prm.name)
            if spec is None:
                continue
            reason = validate(spec, prm.value)
            if reason is None:
                reason = self.check_parameter(prm.name, prm.value)
            if reason is not None:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params: list[Parameter]) -> None:
        names = [p.name for p in params if p.name in self._specs]
        if names:
            self.on_parameters(names)

    def check_parameter(self, name: str, value: Any) -> str | None:
        """Node-specific validation (override); returns a reason to reject."""
        return None

    def on_parameters(self, names: list[str]) -> None:
        """Apply accepted parameter changes (override)."""


class ModelParamNode(ParamNode):
    """A node that holds the model in the read-only (from outside) model.* parameters
    (a model file given with ``--params-file`` overrides them)."""

    OVERRIDE_PREFIXES = ("model.",)

    def __init__(self, name: str, specs: Any, **kwargs: Any) -> None:
        self._internal = threading.local()
        self._served: dict[str, Any] = {}
        super().__init__(name, specs, **kwargs)

    def serve_model(self, values: dict[str, Any]) -> None:
        """Hold ``values`` in model.* (dotted name → value, as
        :func:`dampest_ros.io.yaml_io.model_parameters` gives them): declare the new names,
        undeclare those gone (the terms' names change with the structure), set the changed
        values."""
        for name in set(self._served) - set(values):
            self.undeclare_parameter(name)
        added = [Parameter(n, value=v) for n, v in values.items() if n not in self._served]
        changed = [Parameter(n, value=v) for n, v in values.items()
                   if n in self._served and self._served[n] != v]
        if added:
            self.declare_model(added)
        if changed:
            self.set_model(changed)
        self._served = values

    def declare_model(self, params: list[Parameter]) -> None:
        """Declare model.* (read-only from outside: see :meth:`_check_parameters`)."""
        self._internal.on = True
        try:
            for prm in params:
                self.declare_parameter(prm.name, prm.value, ParameterDescriptor(
                    description="identified damping model (docs/architecture.md §3); set by "
                                "this node"))
        finally:
            self._internal.on = False

    def set_model(self, params: list[Parameter]) -> None:
        """Set model.* (allowed only from here)."""
        self._internal.on = True
        try:
            result = self.set_parameters_atomically(params)
        finally:
            self._internal.on = False
        if not result.successful:
            self.get_logger().error(f"could not set the model parameters: {result.reason}")

    def _check_parameters(self, params: list[Parameter]) -> SetParametersResult:
        if not getattr(self._internal, "on", False):
            for prm in params:
                if prm.name.startswith("model."):
                    return SetParametersResult(
                        successful=False, reason=f"{prm.name} is read-only: the model is set by "
                        f"{self.get_name()} itself")
        return super()._check_parameters(params)


class _HasVersion(Protocol):
    @property
    def version(self) -> int: ...


#: A saved model of any estimator: it has a version.
Versioned = TypeVar("Versioned", bound=_HasVersion)


class LifeCounts:
    """A node's counters as life totals across restarts of what keeps them.

    A rebuild (a parameter change) or a reset makes a new core object whose counters start at
    0; the node's /diagnostics must not lose what was counted before. :meth:`restart` runs the
    restart and keeps what it zeroed; calling the object raises each counter by that.

    Parameters
    ----------
    current : callable
        The counters as the core object keeps them now (name to count).
    """

    def __init__(self, current: Callable[[], dict[str, int]]) -> None:
        self.current = current
        #: per counter, what restarts zeroed
        self.zeroed: dict[str, int] = {}

    def restart(self, how: Callable[[], None]) -> None:
        """Run ``how`` (a rebuild or a reset) keeping every counter it lowered: counters
        only grow, so a lower value is one the restart zeroed."""
        before = self.current()
        how()
        after = self.current()
        for key, value in before.items():
            if after.get(key, 0) < value:
                self.zeroed[key] = self.zeroed.get(key, 0) + value - after.get(key, 0)

    def __call__(self, values: dict[str, Any]) -> dict[str, Any]:
        """``values`` with each counter raised by what restarts zeroed."""
        return {k: v + self.zeroed[k] if k in self.zeroed else v for k, v in values.items()}


class EstimatorParamNode(ModelParamNode):
    """A :class:`ModelParamNode` around a recursive estimator (``self.estimator``, whose
    ``rls`` forgets and can be frozen): what the vehicle and the arm estimator nodes share.

    :meth:`start_services` creates ``~/reset``, ``~/save`` and ``~/freeze`` and the publish
    timer; :meth:`on_parameters` applies a new forgetting factor in place, a new
    publish_rate to the timer, and restarts the estimator from the prior on any other change
    but save_path. A subclass gives :meth:`_build`, :meth:`_publish`, :meth:`_reset` and
    :meth:`_save`, and holds ``version``.

    The ``count.*`` on /diagnostics are the node's life totals: what a rebuild or ~/reset
    zeroes in the estimator (:meth:`_estimator_counts`) is kept and added back by
    :attr:`life_counts` (:class:`LifeCounts`).
    """

    estimator: Any
    version: int

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        #: the estimator's counts as the node's life totals (rebuilds and ~/reset included)
        self.life_counts = LifeCounts(self._estimator_counts)
        super().__init__(*args, **kwargs)
    #: what happened to the model file at save_path at start (diagnostics ``resume``)
    resumed: str = "off"
    #: saved model files refused at start (another estimator's, unreadable)
    resume_refused: int = 0

    def saved_model(self, load: Callable[[Path], Versioned],
                    mismatch: Callable[[Versioned], str | None]) -> Versioned | None:
        """The model file at save_path when it can be resumed, else None (the reason
        logged and counted in :attr:`resume_refused`); its version becomes this node's.
        ``load`` reads the file (raising ValueError or OSError), ``mismatch`` says why a
        model is not one of this estimator's (None: it is). Temporary files of a killed save
        are removed."""
        path = Path(self.p("save_path")).expanduser()
        log = self.get_logger()
        for tmp in remove_orphaned_temp(path):
            log.info(f"removed {tmp}, left by a save that was killed")
        if not path.exists():
            self.resumed = f"no model file at {path}"
            return None
        try:
            m = load(path)
            reason = mismatch(m)
        except (ValueError, OSError) as exc:
            reason = str(exc)
        if reason is not None:
            self.resume_refused += 1
            self.resumed = f"refused {path}: {reason}"
            log.error(f"not resuming from {path}: {reason}; starting from the prior (~/save "
                      "replaces the file)")
            return None
        self.version = int(m.version)
        self.resumed = f"version {m.version} from {path}"
        log.info(f"resumed from {path}: model version {m.version}")
        return m

    def _build(self) -> None:
        """A new estimator from the prior."""
        raise NotImplementedError

    def _publish(self, force: bool = False) -> None:
        """Publish the model and the diagnostics (``force``: even if nothing changed)."""
        raise NotImplementedError

    def _reset(self) -> None:
        """Back to the prior, keeping the settings."""
        raise NotImplementedError

    def _save(self) -> Path:
        """Write the model file at save_path; its path."""
        raise NotImplementedError

    def _estimator_counts(self) -> dict[str, int]:
        """The ``count.*`` values the estimator keeps itself (those a restart zeroes)."""
        raise NotImplementedError

    def start_services(self) -> None:
        """~/reset, ~/save, ~/freeze and the publish timer (once the estimator exists)."""
        self.create_service(Trigger, "~/reset", self._srv_reset)
        self.create_service(Trigger, "~/save", self._srv_save)
        self.create_service(SetBool, "~/freeze", self._srv_freeze)
        self._timer = self.create_timer(1.0 / self.p("publish_rate"), self._publish)

    def on_parameters(self, names: list[str]) -> None:
        if names == ["forgetting_factor"]:
            self.estimator.rls.set_forgetting_factor(self.p("forgetting_factor"))
            self.get_logger().info(f"forgetting factor {self.p('forgetting_factor')}")
            return
        if "publish_rate" in names:
            self._timer.cancel()
            self._timer = self.create_timer(1.0 / self.p("publish_rate"), self._publish)
        if set(names) - {"publish_rate", "save_path"}:
            self.life_counts.restart(self._build)
            self.get_logger().info(f"estimator restarted from the prior ({', '.join(names)} "
                                   "changed)")
            self._publish(force=True)

    def _srv_reset(self, _: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        self.life_counts.restart(self._reset)
        self._publish(force=True)
        res.success, res.message = True, f"reset to the prior (model version {self.version})"
        return res

    def owner(self) -> Identity:
        """The vehicle or arm this node estimates (its models' identity)."""
        raise NotImplementedError

    def _srv_save(self, _: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        from dampest_ros.io.yaml_io import foreign_model

        why = foreign_model(Path(self.p("save_path")).expanduser(), self.owner())
        if why is not None:
            self.get_logger().error(f"~/save refused: {why}")
            res.success, res.message = False, f"not saved: {why}"
            return res
        try:
            path = self._save()
        except (OSError, ValueError) as exc:
            res.success, res.message = False, f"could not save: {exc}"
            return res
        res.success, res.message = True, f"saved model version {self.version} to {path}"
        return res

    def _srv_freeze(self, req: SetBool.Request, res: SetBool.Response) -> SetBool.Response:
        self.estimator.rls.frozen = bool(req.data)
        res.success = True
        res.message = "frozen: estimate held" if req.data else "updating"
        return res


def diagnostic_array(node: Node, task: str, values: dict[str, Any], level: int = 0,
                     message: str = "ok", stamp: Time | None = None) -> DiagnosticArray:
    """A DiagnosticArray with one status of key/value pairs, named ``<node name>: <task>`` as
    ROS's diagnostic aggregators expect (two vehicles' nodes, namespaced, stay apart by
    hardware_id, the fully qualified node name)."""
    status = DiagnosticStatus(level=bytes([level]), name=f"{node.get_name()}: {task}",
                              message=message, hardware_id=node.get_fully_qualified_name())
    status.values = [KeyValue(key=str(k), value=_text(v)) for k, v in values.items()]
    arr = DiagnosticArray()
    arr.header.stamp = stamp if stamp is not None else node.get_clock().now().to_msg()
    arr.status = [status]
    return arr


class NonFiniteCounter:
    """Messages a node refuses, counted per reason and topic and published on
    ``/diagnostics`` once a second (wall clock) as ``count.<key>``; the first of each key is
    logged. A NaN let through would poison a controller's integrator or a simulation's state
    for good.

    Parameters
    ----------
    node : Node
    task : str
        The diagnostic status's task (``<node name>: <task>``).
    keys : sequence of str
        What is counted (``rejected_nonfinite_cmd_vel``, …).
    """

    def __init__(self, node: Node, task: str, keys: Sequence[str]) -> None:
        self.node, self.task = node, task
        self.counts = dict.fromkeys(keys, 0)
        self.pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, RELIABLE_QOS)
        self.timer = node.create_timer(1.0, self.publish,
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))

    def finite(self, key: str, values: Iterable[float], topic: str) -> bool:
        """True if every value is finite; else the message is counted under ``key``."""
        numbers = [float(v) for v in values]
        if all(math.isfinite(v) for v in numbers):
            return True
        self.reject(key, f"{topic}: a message with a non-finite value {numbers} rejected; "
                         "fix its publisher")
        return False

    def reject(self, key: str, line: str) -> None:
        """Count a refused message under ``key``; log ``line`` (what was refused and how to
        fix it) for the first one of that key."""
        self.counts[key] += 1
        if self.counts[key] == 1:
            self.node.get_logger().error(
                f"{line} (these are counted in /diagnostics count.{key})")

    def publish(self) -> None:
        """The counts on /diagnostics (WARN once any message was rejected)."""
        bad = sum(self.counts.values())
        self.pub.publish(diagnostic_array(
            self.node, self.task, {f"count.{k}": v for k, v in self.counts.items()},
            1 if bad else 0, f"{bad} messages rejected" if bad else "ok"))


def _text(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


class NodeMain(Protocol):
    """A node's console-script ``main(args=None)``."""

    def __call__(self, args: list[str] | None = None) -> None: ...


class DuplicateNodeError(RuntimeError):
    """Another node of the same fully qualified name runs in the graph."""


def watch_duplicates(node: Node, window: float = DUPLICATE_WINDOW) -> None:
    """For ``window`` seconds (wall clock), look in the graph every 0.2 s for another node
    of ``node``'s fully qualified name; raise :class:`DuplicateNodeError` from the executor
    when there is one. The node that started last refuses (the other has stopped looking);
    two started within ``window`` of each other both refuse."""
    t0 = time.monotonic()
    me = (node.get_name(), node.get_namespace())

    def look() -> None:
        if node.get_node_names_and_namespaces().count(me) > 1:
            raise DuplicateNodeError(
                f"another node named {node.get_fully_qualified_name()} is running (two would "
                "both answer its services and parameters); stop it, or give this one another "
                "name or namespace: --ros-args -r __node:=NAME or -r __ns:=/NAMESPACE")
        if time.monotonic() - t0 > window:
            timer.cancel()

    timer = node.create_timer(0.2, look, clock=Clock(clock_type=ClockType.STEADY_TIME))


#: How to write each kind of ROS argument, by the words of rcl's complaint about it (the
#: first that matches).
ROS_ARGUMENT_FIXES = (
    ("trailing -p", "write -p NAME:=VALUE"),
    ("trailing -r", "write -r FROM:=TO"),
    ("trailing --params-file", "write --params-file FILE"),
    ("parameter override", "write -p NAME:=VALUE with a YAML value, e.g. -p rate:=2.0, "
     "-p reference:='[0.5, 0, 0, 0, 0, 0]', -p arm:=ur5"),
    ("remap", "write -r FROM:=TO, e.g. -r joint_states:=/arm/joint_states or "
     "-r __ns:=/vehicle"),
    ("params file", "give an existing ROS 2 parameters file (/**: ros__parameters: NAME: "
     "VALUE; every parameter with its default: config/{node}.params.yaml)"),
    ("log level", "write --log-level LEVEL (debug, info, warn, error or fatal) or "
     "--log-level NAME:=LEVEL"),
)


def ros_arguments_error(exc: Exception, node: str) -> str:
    """One line for rcl's refusal of node ``node``'s ROS arguments
    (``RCLInvalidROSArgsError``): the argument, what is wrong with it and how to write it,
    without rcl's source locations and lexer details."""
    text = re.sub(r",? at \S+\.c:\d+", "", str(exc)).replace("\n", " ")
    text = re.sub(r"\. Error: (error not set|Expected lexeme .*)$", "", text.strip())
    text = text.removeprefix("Failed to parse ROS arguments: ").rstrip(". ")
    fix = next((f for words, f in ROS_ARGUMENT_FIXES if words in text),
               "see the ROS 2 arguments: ros2 run --help")
    return f"invalid ROS argument: {text}; {fix.format(node=node)}"


def main_for(node_class: Callable[[], Node], doc: str) -> NodeMain:
    """A console-script main(): ``--help`` lists the node's parameters; otherwise init, spin,
    stop on SIGINT, SIGTERM or external shutdown (status 0), destroy the node, shut down.

    A node that cannot start logs one error line and exits with status 2, without a
    traceback: a ValueError while it is built (an invalid parameter, a model file no reader
    takes), a value rclpy refuses, or another node of the same fully qualified name in the
    graph within :data:`DUPLICATE_WINDOW` s of the start (:func:`watch_duplicates`). An
    error raised by a callback the shutdown interrupted (e.g. publishing on the context a
    signal has just shut down) ends the node quietly too. So does a ROS argument that rcl
    cannot parse (``-p x:=``, a trailing ``-p``, ``-r a``, a missing or broken
    ``--params-file``): :func:`ros_arguments_error` names it and how to write it."""

    def main(args: list[str] | None = None) -> None:
        argv = sys.argv if args is None else args
        name = getattr(node_class, "NODE_NAME", node_class.__name__)
        parser = argparse.ArgumentParser(
            prog=name, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter,
            epilog="ROS arguments follow --ros-args, e.g. --ros-args -p forgetting_factor:=0.99 "
                   "-r __ns:=/vehicle\nEvery parameter with its default: --params-file "
                   f"config/{name}.params.yaml (installed\nin share/dampest_ros/config). A "
                   "bad parameter, or another node of the same name and namespace\nalready "
                   "running, ends the node with one error line and exit status 2."
                   + _param_help(node_class))
        try:
            parser.parse_args(remove_ros_args(argv)[1:])
            rclpy.init(args=argv)
        except rclpy_implementation.RCLInvalidROSArgsError as exc:
            rclpy.logging.get_logger(name).error(
                f"cannot start: {ros_arguments_error(exc, name)}")
            raise SystemExit(2) from None
        except KeyboardInterrupt:  # SIGINT while starting: a clean stop, as once running
            rclpy.try_shutdown()
            return
        node = None
        refused = False
        status = 0  # a node's own exit_status once it has run (e.g. a replay cut short)
        files: list[Any] = []  # the --params-file files (io.strict_yaml.YamlDoc)
        try:
            files = params_files(argv)
            node = node_class()
            watch_duplicates(node)
            rclpy.spin(node)
            status = int(getattr(node, "exit_status", 0))  # ParamNode.exit_status
        except (KeyboardInterrupt, ExternalShutdownException):
            status = int(getattr(node, "exit_status", 0))
        except (ValueError, ParameterException, DuplicateNodeError) as exc:
            if node is not None and not isinstance(exc, DuplicateNodeError):
                raise
            if isinstance(exc, UnknownParameterError):
                exc = exc.located(files)
            rclpy.logging.get_logger(name).error(f"cannot start: {exc}")
            refused = True
        except Exception:
            if rclpy.ok():  # not a shutdown: a real failure, shown in full
                raise
        finally:
            with signals_held(name):
                if node is not None:
                    node.destroy_node()
                rclpy.try_shutdown()
        if refused:
            raise SystemExit(2)
        if status:
            raise SystemExit(status)

    return main


@contextlib.contextmanager
def signals_held(name: str) -> Iterator[None]:
    """Shield a node's closing from further SIGINT/SIGTERM.

    A second Ctrl-C (or a launch system's repeated SIGTERM) while a node closes would raise
    KeyboardInterrupt in the middle of its close: a bag without its summary or metadata.yaml,
    and a traceback. While the block runs such a signal is only reported once on stderr; the
    previous handlers come back afterwards (outside the main thread, which alone can set
    handlers, the block runs unshielded). SIGKILL still ends the process."""
    told = False

    def hold(signum: int, _frame: Any) -> None:
        nonlocal told
        if not told:
            told = True
            print(f"[WARN] [{name}]: {signal.Signals(signum).name} while closing: finishing the "
                  "close first (SIGKILL aborts it)", file=sys.stderr, flush=True)

    if threading.current_thread() is not threading.main_thread():  # handlers live there only
        yield
        return
    previous = {s: signal.signal(s, hold) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def _param_help(node_class: Any) -> str:
    specs: Sequence[Param] = getattr(node_class, "PARAMS", ())
    if not specs:
        return ""
    lines = [f"  {p.name} (default {p.default!r}): {p.description}" for p in specs]
    return "\n\nparameters:\n" + "\n".join(lines)
