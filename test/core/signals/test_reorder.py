"""The stamp-order stage (dampest_ros.core.signals.reorder): any arrival order within the latency
gives the offline (stamp, role) order, so the online preprocessor's samples equal run(rec)'s."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.online.preprocessor import OnlinePreprocessor
from dampest_ros.core.online.sample import DEFAULT_TOPICS, TOPIC_ROLES
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.signals.measurements import Recording
from dampest_ros.core.signals.reorder import StampOrder
from dampest_ros.core.simulation.excitation import make_excitation
from dampest_ros.core.simulation.sensors import SensorConfig, measure
from dampest_ros.core.simulation.simulate import run
from dampest_ros.io.yaml_io import load_vehicle

RATES = {"imu": 200.0, "dvl": 8.0, "pressure": 20.0, "thrusters": 50.0}


def arrivals(stamps: dict[str, np.ndarray], max_delay: float, seed: int
             ) -> list[tuple[str, float]]:
    """(role, stamp) in the order of arrival: each topic in its own order, delayed by a
    random backlog of up to ``max_delay`` s (as a busy executor delays a fast topic)."""
    rng = np.random.default_rng(seed)
    events = []
    for role, t in stamps.items():
        arrive = np.maximum.accumulate(t + rng.uniform(0.0, max_delay, len(t)))
        events += [(a, role, s) for a, s in zip(arrive, t, strict=True)]
    events.sort(key=lambda e: e[0])  # stable: a topic's own order is kept
    return [(role, s) for _, role, s in events]


def grid(seconds: float) -> dict[str, np.ndarray]:
    """Stamps of the four roles; IMU, pressure and thruster stamps coincide every 0.1 s."""
    return {r: np.arange(int(seconds * hz)) / hz + (0.013 if r == "dvl" else 0.0)
            for r, hz in RATES.items()}


def offline_order(stamps: dict[str, np.ndarray]) -> list[tuple[str, float]]:
    rank = {r: k for k, r in enumerate(TOPIC_ROLES)}
    return sorted(((r, float(s)) for r, t in stamps.items() for s in t),
                  key=lambda m: (m[1], rank[m[0]]))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_any_arrival_within_the_latency_gives_the_stamp_order(seed: int) -> None:
    stamps = grid(20.0)
    order = StampOrder(TOPIC_ROLES, latency=0.3)
    out = []
    for role, t in arrivals(stamps, 0.25, seed):
        out += order.push(role, t)
    held = len(order)
    out += order.flush()
    assert [(r, t) for r, t, _ in out] == offline_order(stamps)
    n = sum(len(t) for t in stamps.values())
    assert order.counts == {"received": n, "released": n, "late": 0, "clock_jumps": 0}
    # the watermark releases far sooner than the latency: at the end it holds less than
    # the last DVL period's worth of messages plus the backlog
    assert 0 < held < 0.4 * sum(RATES.values())


def test_watermark_releases_at_once_when_every_topic_has_passed() -> None:
    order = StampOrder(("a", "b"), latency=100.0)
    assert order.push("a", 1.0, "a1") == []
    assert order.push("a", 2.0, "a2") == []
    # b at 1.0: a1 (tie, a first) and b1 are safe; a2 waits for b to pass 2.0
    assert order.push("b", 1.0, "b1") == [("a", 1.0, "a1"), ("b", 1.0, "b1")]
    assert order.push("b", 3.0, "b3") == [("a", 2.0, "a2")]
    assert len(order) == 1


def test_a_message_later_than_the_latency_is_passed_on_and_counted() -> None:
    order = StampOrder(("a", "b"), latency=0.5)
    out = order.push("a", 0.0) + order.push("a", 0.6) + order.push("a", 1.2)
    assert [t for _, t, _ in out] == [0.0, 0.6]  # older than newest − latency
    assert order.push("b", 0.3, "late") == [("b", 0.3, "late")]
    assert order.counts["late"] == 1
    assert order.max_lag == pytest.approx(0.9)  # 1.2 − 0.3: a latency ≥ 0.9 takes it
    assert order.push("b", 0.9) == [("b", 0.9, None)]  # in time, and a has passed it
    assert order.push("b", 1.5) == [("a", 1.2, None)]


def test_clock_jump_releases_what_is_held_and_starts_again() -> None:
    order = StampOrder(("a", "b"), latency=0.5, clock_jump=1.0)
    assert order.push("a", 100.0) == []
    assert order.push("b", 100.1) == [("a", 100.0, None)]
    out = order.push("a", 3.0)  # a looped bag or a restarted simulator
    assert [t for _, t, _ in out] == [100.1]
    assert order.counts["clock_jumps"] == 1 and order.counts["late"] == 0
    out = order.push("b", 2.9) + order.flush()
    assert [(r, t) for r, t, _ in out] == [("b", 2.9), ("a", 3.0)]


def test_invalid_settings_name_the_field() -> None:
    with pytest.raises(ConfigError, match="latency"):
        StampOrder(("a",), latency=-1.0)
    with pytest.raises(ConfigError, match="roles"):
        StampOrder(("a", "a"))


def test_preprocessor_fed_in_arrival_order_equals_the_recording_run() -> None:
    """20 s of protocol B (seed 4) measured with the default sensors; the messages arrive
    with a random backlog of up to 0.3 s per topic, through a StampOrder of 0.5 s: every
    sample equals that of OnlinePreprocessor.run on the recording."""
    v = load_vehicle("bluerov2_heavy")
    traj = run(v, make_excitation("B", v, 20.0, seed=4))
    rec: Recording = measure(traj, v.body.rho, v.body.gravity, SensorConfig(), seed=4)
    offline = OnlinePreprocessor(v.thrusters, v.body.gravity, v.body.rho).run(rec)

    pre = OnlinePreprocessor(v.thrusters, v.body.gravity, v.body.rho)
    series = {r: rec[DEFAULT_TOPICS[r]] for r in TOPIC_ROLES}
    row = {r: {float(t): i for i, t in enumerate(s.stamp)} for r, s in series.items()}
    imu, dvl, pres, thr = (series[r] for r in TOPIC_ROLES)

    def args(role: str, i: int) -> tuple[object, ...]:
        if role == "imu":
            return imu.orientation[i], imu.angular_velocity[i], imu.linear_acceleration[i]
        if role == "dvl":
            return dvl.linear[i], dvl.covariance
        if role == "pressure":
            return (float(pres.fluid_pressure[i]),)
        return thr.names, thr.effort[i]

    order = StampOrder(TOPIC_ROLES, latency=0.5)
    live = []
    for role, t in arrivals({r: s.stamp for r, s in series.items()}, 0.3, seed=5):
        for r, tt, a in order.push(role, t, args(role, row[role][t])):
            live += getattr(pre, r)(tt, *a)
    for r, tt, a in order.flush():
        live += getattr(pre, r)(tt, *a)
    assert order.counts["late"] == 0
    assert len(live) == len(offline) > 900
    for a, b in zip(live, offline, strict=True):
        assert a.t == b.t and a.usable == b.usable
        for f in ("nu", "nu_dot", "tau", "euler"):
            np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
