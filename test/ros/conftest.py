"""What the in-process node tests share."""

from __future__ import annotations

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
