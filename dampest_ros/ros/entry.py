"""Console-script entries of the nodes (``ros2 run dampest_ros <node>``).

A node's module imports numpy, scipy and rclpy, which takes up to seconds on a loaded machine.
The entry imports it here, with SIGTERM turned into KeyboardInterrupt meanwhile, so that a
Ctrl-C or SIGTERM that arrives while the node is still starting ends it quietly with status 0,
as one during spin does (:func:`dampest_ros.ros.common.main_for`); one that arrives after the
node has closed (further signals are held while it closes) ends it with status 0 too. This
module imports nothing heavy itself.
"""

from __future__ import annotations

import importlib
import signal
import sys
from functools import partial
from types import FrameType

#: The signals received while the node's module was imported.
_received: list[int] = []


def _interrupt(signum: int, frame: FrameType | None) -> None:
    _received.append(signum)
    raise KeyboardInterrupt


def run(module: str) -> None:
    """Import ``dampest_ros.ros.<module>`` and call its ``main()``; interrupted while
    importing or after the node has closed: exit 0."""
    previous = {s: signal.signal(s, _interrupt) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        main = importlib.import_module(f"dampest_ros.ros.{module}").main
    except KeyboardInterrupt:
        sys.exit(0)
    except ImportError:
        if _received:  # the KeyboardInterrupt hit an extension module's initialisation,
            sys.exit(0)  # which reports it as "ImportError: initialization failed"
        raise
    for s, handler in previous.items():
        signal.signal(s, handler)
    if _received:  # its KeyboardInterrupt was swallowed by an import (a bare except)
        sys.exit(0)
    try:
        main()
    except KeyboardInterrupt:  # a Ctrl-C after the node had closed (held while it closed)
        sys.exit(0)
    finally:  # the node has ended: what is left is the interpreter's exit
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, signal.SIG_IGN)


sim_node = partial(run, "sim_node")
preprocess_node = partial(run, "preprocess_node")
estimator_node = partial(run, "estimator_node")
arm_estimator_node = partial(run, "arm_estimator_node")
model_server_node = partial(run, "model_server_node")
controller_node = partial(run, "controller_node")
arm_feedforward_node = partial(run, "arm_feedforward_node")
recorder_node = partial(run, "recorder_node")
replay_node = partial(run, "replay_node")
