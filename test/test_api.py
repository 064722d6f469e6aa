"""The public API (dampest_ros/__init__.py): the README's library example on a simulated bag,
every name of __all__, and an import that loads neither numpy nor scipy."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import dampest_ros as dr

REPO = Path(__file__).resolve().parents[1]


def test_the_readme_example_identifies_a_simulated_bag(tmp_path: Path) -> None:
    from dampest_ros.io.bag import write_bag

    truth = dr.load_vehicle("bluerov2_heavy")
    write_bag(tmp_path / "my_bag", dr.simulate(truth, protocol="B", duration=90.0, seed=3))

    # the README's lines
    vehicle = dr.load_vehicle("bluerov2_heavy")
    samples = dr.preprocess(dr.read_bag(tmp_path / "my_bag"), vehicle)
    identified = dr.DampingIdentifier(vehicle).fit(samples)
    path = dr.save_model(tmp_path / "model.yaml", identified.model_)

    # the model file holds what the fit found
    back = dr.load_model(path)
    assert back.parameter_names == identified.names_
    np.testing.assert_array_equal(back.theta, identified.coef_)
    assert back.identified.all() and back.extra["method"] == "wls"
    # the quadratic coefficients the bag was simulated with, to 2 % (X_uu = 141 ... N_rr = 1.5)
    quad = truth.damping.slice("quadratic")
    assert identified.names_[quad] == truth.damping.parameter_names[quad]
    np.testing.assert_allclose(identified.coef_[quad], truth.theta[quad], rtol=0.02)


def test_every_public_name_resolves() -> None:
    assert sorted(dr.__all__) == sorted(set(dr.__all__))
    for name in dr.__all__:
        assert callable(getattr(dr, name)), name
        assert name in dir(dr)
    with pytest.raises(AttributeError, match="no_such_name"):
        _ = dr.no_such_name


def test_importing_the_package_loads_no_numerics() -> None:
    probe = ("import sys, dampest_ros; "
             "print(sorted(m for m in ('numpy', 'scipy') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", probe], cwd=REPO, capture_output=True,
                         text=True, timeout=60, check=True).stdout.strip()
    assert out == "[]"
