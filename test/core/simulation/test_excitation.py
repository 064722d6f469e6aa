"""Excitation protocols generated block by block: the same numbers as sampling them at once,
read tick by tick as the simulator does, in memory that does not grow with the duration."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.simulation import excitation
from dampest_ros.core.simulation.excitation import LIVE_PROTOCOLS, protocol
from dampest_ros.core.simulation.simulate import run
from dampest_ros.core.simulation.vehicle_design import design_vehicle
from dampest_ros.io.yaml_io import load_vehicle

FIELDS = ("t", "nu_ref", "attitude_ref", "depth_ref", "tau_ff")


def held_bytes(obj: object, seen: set[int] | None = None) -> int:
    """Total nbytes of the numpy arrays reachable from obj: attributes of objects of the
    excitation module, lists, tuples, dicts, the variables closures hold and the frames of
    suspended generators (the block iterators)."""
    seen = set() if seen is None else seen
    if id(obj) in seen:
        return 0
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        return int(obj.nbytes)
    if isinstance(obj, dict):
        return sum(held_bytes(v, seen) for v in obj.values())
    if isinstance(obj, list | tuple):
        return sum(held_bytes(v, seen) for v in obj)
    frame = getattr(obj, "gi_frame", None)
    if frame is not None:
        return held_bytes(dict(frame.f_locals), seen)
    cells = getattr(obj, "__closure__", None)
    if cells:
        return sum(held_bytes(c.cell_contents, seen) for c in cells)
    if type(obj).__module__ == excitation.__name__ and hasattr(obj, "__dict__"):
        return held_bytes(vars(obj), seen)
    return 0


@pytest.fixture(scope="module")
def vehicle() -> Vehicle:
    return load_vehicle("bluerov2_heavy")


def test_prbs_levels_are_the_draws_of_one_stream() -> None:
    """Two PRBS signals drawn lazily, in chunks, from copies of the stream advanced to where
    each run of draws begins, are the levels of n switch times, n + 1 magnitudes and n + 1
    signs drawn at once, one signal after the other, from one generator (an odd number of
    signs leaves half a draw for the next signal's first sign)."""
    t = np.arange(3001, dtype=float) * 0.02  # 60 s: n = 62 switch times, 63 signs (odd)
    rng = np.random.default_rng(11)
    expected = []
    for amp, lowest in ((0.7, 0.0), (1.3, 0.2)):
        n = int(t[-1] / 1.0) + 2
        switch = np.cumsum(rng.uniform(1.0, 4.0, n))
        level = rng.uniform(lowest, 1.0, n + 1) * rng.choice([-1.0, 1.0], n + 1) * amp
        expected.append(level[np.searchsorted(switch, t)])
    bits = np.random.default_rng(11).bit_generator
    assert isinstance(bits, np.random.PCG64)
    first = excitation._Levels(bits, t[-1], 0.7, (1.0, 4.0))
    second = excitation._Levels(first.after, t[-1], 1.3, (1.0, 4.0), 0.2)
    for lv, want in zip((first, second), expected, strict=True):
        got = np.concatenate([lv(t[i:i + 333]) for i in range(0, len(t), 333)])
        np.testing.assert_array_equal(got, want)
        assert len(np.unique(got)) > 10


@pytest.mark.parametrize("name", ["A", "B", "C", "axes", "fourier"])
def test_blocks_of_any_size_give_the_same_protocol(vehicle: Vehicle, name: str,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """Blocks of 4096 ticks (and chunks of 4096 draws) or of 7 ticks (6 draws) concatenate
    to the same numbers, bit for bit: filters, derivatives and draws continue across them."""
    whole = protocol(name, vehicle, 81.94, seed=3).sample()  # 4098 ticks: 2 blocks
    monkeypatch.setattr(excitation, "BLOCK", 7)
    monkeypatch.setattr(excitation, "_DRAWS", 6)
    small = protocol(name, vehicle, 81.94, seed=3).sample()
    assert len(whole.t) == 4098
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(small, f), getattr(whole, f), err_msg=f)
    assert np.abs(whole.nu_ref).max() + np.abs(whole.tau_ff).max() > 0.1


def test_axes_legs_fly_one_dof_at_a_time_over_its_range(vehicle: Vehicle) -> None:
    """Protocol axes: in each sixth of the run only its DOF's reference moves (but for the
    band-limited tail of the last leg's wave and the sample where a rate's derivative
    straddles two legs), up to the range (translations, yaw) or with the angle's peak rate at
    the range (at most 0.5 Hz); the depth comes back after the heave leg."""
    lim = excitation.speed_limits(vehicle)
    e = protocol("axes", vehicle, 600.0, seed=1).sample()
    rate = np.c_[e.nu_ref[:, [0, 1, 2, 5]], e.nu_ref[:, 3:5]]
    cols = (0, 1, 2, 3, 4, 5)  # u v w r p q in rate's columns
    peaks = np.array([lim[0], lim[1], lim[2], lim[5],
                      min(lim[3], np.deg2rad(25) * np.pi), min(lim[4], np.deg2rad(25) * np.pi)])
    for leg, col in enumerate(cols):
        m = (e.t >= 100 * leg + 5.0) & (e.t < 100 * (leg + 1) - 1.0)
        moving = np.abs(rate[m]).max(axis=0)
        np.testing.assert_allclose(moving[col], peaks[col], rtol=0.02)
        assert np.all(np.delete(moving, col) < 1e-4 * lim.max()), (leg, moving)
    heave_over = np.searchsorted(e.t, 310.0)
    assert e.depth_ref.max() > 5.0 + 0.5 * 100 / 10 * lim[2]  # the last level's dive
    assert abs(e.depth_ref[heave_over] - 5.0) < 1e-3 * lim[2]


def test_tick_reading_is_the_sampled_protocol(vehicle: Vehicle) -> None:
    """command(k) and feedforward(k), read forward across block edges, are the sampled
    protocol's; the offline simulation flies the stream as it flies the samples."""
    stream = protocol("B", vehicle, 100.0, seed=2)
    whole = stream.sample()
    nu = np.array([0.1, -0.2, 0.05, 0.01, -0.02, 0.1])
    for k in (0, 1, 4095, 4096, 4097, 5000):
        np.testing.assert_array_equal(stream.command(k, nu, 0.1, -0.1, 4.0),
                                      whole.command(k, nu, 0.1, -0.1, 4.0))
    np.testing.assert_array_equal(protocol("C", vehicle, 90.0, seed=2).feedforward(4500),
                                  protocol("C", vehicle, 90.0, seed=2).sample().tau_ff[4500])
    a = run(vehicle, protocol("B", vehicle, 3.0, seed=4))
    b = run(vehicle, protocol("B", vehicle, 3.0, seed=4).sample())
    np.testing.assert_array_equal(a.nu, b.nu)


def test_multisine_rms_in_closed_form() -> None:
    """Protocol C's RMS over the run comes from a closed form: the mean of the squared sum
    of sines over the grid equals the sum over the samples to 1e-13."""
    rng = np.random.default_rng(3)
    theta = 2 * np.pi * np.geomspace(0.1, 10.0, 6) * 0.02
    phase = rng.uniform(0, 2 * np.pi, 6)
    k = np.arange(12345)
    x = np.sin(theta[None, :] * k[:, None] + phase).sum(axis=1)
    assert excitation._mean_square(theta, phase, len(k)) == pytest.approx(np.mean(x * x),
                                                                          rel=1e-13)


@pytest.mark.parametrize("name", LIVE_PROTOCOLS)
def test_memory_does_not_grow_with_the_duration(vehicle: Vehicle, name: str,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """Was: the protocol sampled at start, 16 numbers per 20 ms control tick (640 MB at
    1e5 s). Read to tick 6000, a protocol of 1e4 s and one of 1e6 s hold the same arrays
    (the current and next block, the PRBS draws not yet used: as many within 2 %, their
    streams differ), under 2 MB. (Protocol optimal with a design of 2 harmonics and no
    iterations: its size does not depend on the duration either.)"""
    monkeypatch.setattr(excitation, "design_vehicle", functools.partial(
        design_vehicle, harmonics=2, iterations=0, baseline=1))
    held = []
    for duration in (1e4, 1e6):
        stream = protocol(name, vehicle, duration, seed=1)
        nu = np.zeros(6)
        for k in range(6000):
            stream.command(k, nu, 0.0, 0.0, 5.0)
            stream.feedforward(k)
        held.append(held_bytes(stream))
        assert stream.ticks == round(duration * 50) + 1
    assert abs(held[1] - held[0]) < 0.02 * held[0]
    assert 100_000 < held[1] < 2_000_000
