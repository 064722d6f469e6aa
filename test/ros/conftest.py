"""What the in-process node tests share."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from typing import Any

import pytest

#: ``spin_until(executor, done, timeout)``: whether ``done()`` came true within ``timeout``
#: seconds of spinning ``executor``.
SpinUntil = Callable[[Any, Callable[[], bool], float], bool]


def _spin_until(ex: Any, done: Callable[[], bool], timeout: float) -> bool:
    end = time.monotonic() + timeout
    while not done():
        if time.monotonic() > end:
            return False
        ex.spin_once(timeout_sec=0.02)
    return True


@pytest.fixture(scope="session")
def spin_until() -> SpinUntil:
    """Spin an executor until a condition holds or a timeout passes (:data:`SpinUntil`)."""
    return _spin_until


class DomainNode:
    """An rclpy context of its own on ROS_DOMAIN_ID ``domain`` (localhost only) with one
    node ``name`` in a single-threaded executor, which the test spins (or a thread does)."""

    def __init__(self, domain: str, name: str) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        os.environ.update(ROS_DOMAIN_ID=domain, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def close(self) -> None:
        """Shut the executor down, destroy the node, shut the context down."""
        import rclpy

        self.executor.shutdown(timeout_sec=2.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture(scope="session")
def domain_node() -> type[DomainNode]:
    """:class:`DomainNode` (test modules import no helpers under --import-mode=importlib)."""
    return DomainNode
