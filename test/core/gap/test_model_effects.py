"""The added-mass candidates of gap keep the vehicle's zeroed C_A entries."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np

from dampest_ros.core.gap.model_effects import AddedMassScale
from dampest_ros.core.physics.rigid_body import AddedMassTerms


def _data(terms: AddedMassTerms) -> Any:
    """What model_update reads of the gap data: the believed body's switches."""
    return SimpleNamespace(body=SimpleNamespace(added_mass_terms=terms))


def test_coriolis_form_writes_the_vehicles_mask_or_switches_it_off_whole() -> None:
    terms = AddedMassTerms(inertial=False, munk=False, coriolis_zero=((0, 4), (2, 4)))
    scale = AddedMassScale("coriolis")
    kept = scale.model_update(_data(terms), np.array([0.1]))
    assert kept["terms"] == {"coriolis": True, "munk": False, "coriolis_zero": ((0, 4), (2, 4))}
    assert AddedMassTerms(**{"inertial": False, **kept["terms"]}) == terms
    off = scale.model_update(_data(terms), np.array([-0.9]))
    assert off["terms"] == {"coriolis": False, "munk": False, "coriolis_zero": ()}
