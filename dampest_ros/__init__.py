"""dampest_ros: identification of underwater-vehicle hydrodynamic damping for ROS 2.

The library in a few lines::

    import dampest_ros as dr

    vehicle = dr.load_vehicle("bluerov2_heavy")
    samples = dr.preprocess(dr.read_bag("my_bag"), vehicle)
    identified = dr.DampingIdentifier(vehicle).fit(samples)
    print(dict(zip(identified.names_, identified.coef_)))
    dr.save_model("model.yaml", identified.model_)  # the model file every node and tool reads

The names below are imported on first use, so that ``import dampest_ros`` (and the
``dampest`` command's start) loads neither numpy nor scipy.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

#: Public name → the module that defines it.
_HOME = {
    "load_vehicle": "dampest_ros.io.yaml_io",
    "read_bag": "dampest_ros.io.bag",
    "read_csv": "dampest_ros.io.csv",
    "preprocess": "dampest_ros.core.signals.preprocess",
    "DampingIdentifier": "dampest_ros.core.identifier",
    "Model": "dampest_ros.core.identification.model",
    "load_model": "dampest_ros.io.yaml_io",
    "save_model": "dampest_ros.io.yaml_io",
    "find_gap": "dampest_ros.core.gap.search",
    "simulate": "dampest_ros.core.simulation.simulate",
}

__all__ = ["DampingIdentifier", "Model", "find_gap", "load_model", "load_vehicle", "preprocess",
           "read_bag", "read_csv", "save_model", "simulate"]

if TYPE_CHECKING:
    from dampest_ros.core.gap.search import find_gap
    from dampest_ros.core.identification.model import Model
    from dampest_ros.core.identifier import DampingIdentifier
    from dampest_ros.core.signals.preprocess import preprocess
    from dampest_ros.core.simulation.simulate import simulate
    from dampest_ros.io.bag import read_bag
    from dampest_ros.io.csv import read_csv
    from dampest_ros.io.yaml_io import load_model, load_vehicle, save_model


def __getattr__(name: str) -> Any:
    """Import a public name from its module on first use (PEP 562)."""
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module 'dampest_ros' has no attribute {name!r}")
    value = getattr(importlib.import_module(home), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
