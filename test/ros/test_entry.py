"""The nodes' console-script entry (dampest_ros/ros/entry.py): a signal while the node's
module imports ends it with status 0, also when an extension module's initialisation turns
the signal's KeyboardInterrupt into an ImportError."""

from __future__ import annotations

import importlib
import signal
from collections.abc import Callable, Iterator
from types import ModuleType

import pytest

from dampest_ros.ros import entry


@pytest.fixture(autouse=True)
def handlers(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """No signal received yet; this process's SIGINT and SIGTERM handlers as they were after
    the test (the entry leaves its own in place when it exits during the import)."""
    monkeypatch.setattr(entry, "_received", [])
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    yield
    for s, handler in before.items():
        signal.signal(s, handler)


def interrupted_import(error: BaseException) -> Callable[[str], ModuleType]:
    """An import_module that receives SIGINT while importing (through the handler the entry
    set) and then raises ``error``."""

    def fake(name: str) -> ModuleType:
        try:
            signal.getsignal(signal.SIGINT)(signal.SIGINT, None)  # type: ignore[operator]
        except KeyboardInterrupt:
            raise error from None
        raise AssertionError("the entry's handler did not interrupt")

    return fake


@pytest.mark.parametrize("error", [KeyboardInterrupt(), ImportError("initialization failed")],
                         ids=["KeyboardInterrupt", "ImportError"])
def test_a_signal_during_the_import_exits_0(error: BaseException,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """Was (ImportError): a fresh-clone run printed 'ImportError: initialization failed' from
    scipy.optimize's HiGHS module and the node exited 1 after a Ctrl-C 0.3 s after its
    start."""
    monkeypatch.setattr(importlib, "import_module", interrupted_import(error))
    with pytest.raises(SystemExit) as done:
        entry.run("sim_node")
    assert done.value.code == 0 and entry._received == [signal.SIGINT]


def test_an_import_error_without_a_signal_is_raised(monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(name: str) -> ModuleType:
        raise ImportError("No module named 'numpy'")

    monkeypatch.setattr(importlib, "import_module", broken)
    with pytest.raises(ImportError, match="numpy"):
        entry.run("sim_node")
