"""Progress lines on stderr: silent for a step shorter than their delay (5 s by default),
then drawn until the step ends."""

from __future__ import annotations

import time

import pytest

from dampest_ros.cli.common import PROGRESS_AFTER, Elapsed, Progress


def test_a_quick_loop_or_step_prints_nothing(capsys: pytest.CaptureFixture[str]) -> None:
    assert PROGRESS_AFTER == 5.0
    bar = Progress("reading")
    for k in range(101):
        bar(k, 100)
    with Elapsed("designing"):
        pass
    assert capsys.readouterr().err == ""


def test_a_long_loop_draws_its_bar_from_the_delay_on(
        capsys: pytest.CaptureFixture[str]) -> None:
    bar = Progress("reading", after=0.05)
    bar(10, 100)
    time.sleep(0.1)
    bar(50, 100)
    bar(100, 100)
    assert capsys.readouterr().err == ("\rreading [############.............]  50% 50/100"
                                       "\rreading [#########################] 100% 100/100\n")


def test_a_long_step_shows_its_seconds_and_ends_its_line(
        capsys: pytest.CaptureFixture[str]) -> None:
    with Elapsed("designing", after=0.05):
        time.sleep(0.3)
    err = capsys.readouterr().err
    assert err.startswith("\rdesigning: 0 s") and err.endswith("\rdesigning: done in 0 s\n")
