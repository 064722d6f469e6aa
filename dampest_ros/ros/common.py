"""Shared pieces of the nodes: QoS profiles, stamps, validated parameters, main()."""

from __future__ import annotations

import argparse
import inspect
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

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
from rclpy.executors import ExternalShutdownException
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

from dampest_ros.core.estimator import wire_stamp
from dampest_ros.core.rigid_body import ConfigError
from dampest_ros.io.yaml_io import load_model

#: Sensor topics: the sensor-data policies (best effort, volatile) with a deeper queue than
#: its 5, for the bursts of a simulator running faster than real time.
SENSOR_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=2000,
                        reliability=qos_profile_sensor_data.reliability,
                        durability=qos_profile_sensor_data.durability)
#: Sample and command topics: reliable, keep last 200 (bursts when faster than real time).
RELIABLE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=200,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)
#: ``dampest/model``: reliable, transient local, keep last 1 (late joiners get the model).
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)


#: Turns of :class:`Drain` per callback (:meth:`ParamNode.create_subscription`): at least
#: what one sim tick publishes per topic.
DRAIN_LIMIT = 500


class _Taken(CallbackGroup):
    """A callback group that executors never wait on or run: its subscriptions are read
    only by the :class:`Drain` group they belong to."""

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


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
        self.passive: CallbackGroup = _Taken()
        self._members: list[tuple[Subscription, Callable[[tuple[Any, Any]], None]]] = []

    def add(self, sub: Subscription) -> None:
        """Make ``sub`` a member: its callback (taking the message, or the message and its
        info, as rclpy decides by the signature) is wrapped."""
        callback = sub.callback
        deliver: Callable[[tuple[Any, Any]], None]
        try:
            inspect.signature(callback).bind(object())
        except TypeError:  # (message, info)
            def deliver(taken: tuple[Any, Any]) -> None:
                callback(*taken)

            def with_info(msg: Any, info: Any) -> None:
                callback(msg, info)
                self.take()

            sub.callback = with_info
        else:
            def deliver(taken: tuple[Any, Any]) -> None:
                callback(taken[0])

            def message_only(msg: Any) -> None:
                callback(msg)
                self.take()

            sub.callback = message_only
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


def to_time(t: float) -> Time:
    """builtin_interfaces/Time from seconds (rounded to the nanosecond)."""
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
    if isinstance(p.default, float):
        # '-p duration:=90' arrives as an integer: accept it (validate() checks the number)
        d.dynamic_typing = True
    return d


def validate(p: Param, value: Any) -> str | None:
    """The reason why ``value`` is invalid for ``p``, or None."""
    if isinstance(p.default, float) and (isinstance(value, bool)
                                         or not isinstance(value, int | float)):
        return f"{p.name} must be a number, got {value!r}"
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


def model_file_check(name: str) -> Callable[[Any], str | None]:
    """A :class:`Param` check for a parameter holding a model file path: '' passes, else the
    reason :func:`~dampest_ros.io.yaml_io.load_model` refuses the file (missing, not a model,
    non-finite numbers, …), prefixed with the parameter's name."""

    def check(value: Any) -> str | None:
        if not str(value).strip():
            return None
        try:
            load_model(str(value))
        except (ConfigError, FileNotFoundError, ValueError, OSError) as exc:
            return f"{name}: {exc}"
        return None

    return check


class ParamNode(Node):
    """A node whose parameters are declared from :class:`Param` specs and validated on set;
    accepted changes go to :meth:`on_parameters` (after they are set)."""

    def __init__(self, name: str, specs: Sequence[Param], **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self._specs = {p.name: p for p in specs}
        for p in specs:
            self.declare_parameter(p.name, p.default, _descriptor(p))
            reason = validate(p, self.get_parameter(p.name).value)
            if reason is not None:
                raise ValueError(f"parameter {reason}")
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

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


def diagnostic_array(node: Node, name: str, values: dict[str, Any], level: int = 0,
                     message: str = "ok", stamp: Time | None = None) -> DiagnosticArray:
    """A DiagnosticArray with one status of key/value pairs."""
    status = DiagnosticStatus(level=bytes([level]), name=name, message=message,
                              hardware_id=node.get_name())
    status.values = [KeyValue(key=str(k), value=_text(v)) for k, v in values.items()]
    arr = DiagnosticArray()
    arr.header.stamp = stamp if stamp is not None else node.get_clock().now().to_msg()
    arr.status = [status]
    return arr


def _text(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def main_for(node_class: Callable[[], Node], doc: str) -> Callable[[list[str] | None], None]:
    """A console-script main(): ``--help`` lists the node's parameters; otherwise init, spin,
    stop on Ctrl-C or external shutdown, destroy the node, shut down (as demo_nodes_py).

    A node that cannot start on its parameters (a ValueError while it is built: an invalid
    parameter, a model file no reader takes) logs one error line and exits with status 2,
    without a traceback."""

    def main(args: list[str] | None = None) -> None:
        argv = sys.argv if args is None else args
        name = getattr(node_class, "NODE_NAME", node_class.__name__)
        parser = argparse.ArgumentParser(
            prog=name, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter,
            epilog="ROS arguments follow --ros-args, e.g. --ros-args -p forgetting_factor:=0.99 "
                   "-r __ns:=/vehicle" + _param_help(node_class))
        parser.parse_args(remove_ros_args(argv)[1:])
        rclpy.init(args=argv)
        node = None
        refused = False
        try:
            node = node_class()
            rclpy.spin(node)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        except ValueError as exc:  # ConfigError included
            if node is not None:
                raise
            rclpy.logging.get_logger(name).error(f"cannot start: {exc}")
            refused = True
        finally:
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
        if refused:
            raise SystemExit(2)

    return main


def _param_help(node_class: Any) -> str:
    specs: Sequence[Param] = getattr(node_class, "PARAMS", ())
    if not specs:
        return ""
    lines = [f"  {p.name} (default {p.default!r}): {p.description}" for p in specs]
    return "\n\nparameters:\n" + "\n".join(lines)
