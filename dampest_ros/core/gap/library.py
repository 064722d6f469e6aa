"""The library of candidate effects the gap search screens."""

from __future__ import annotations

from collections.abc import Sequence

from dampest_ros.core.gap.effects import (
    Buoyancy,
    CGOffset,
    Current,
    DeadZone,
    Delay,
    DvlBias,
    Effect,
    GyroBias,
    ThrustGain,
)
from dampest_ros.core.gap.model_effects import (
    ADDED_MASS_FORMS,
    AddedMassDof,
    AddedMassScale,
    Coefficient,
    Cross,
    Memory,
)
from dampest_ros.core.identification.selection import DEFAULT_CROSS
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.terms import CrossSpec


def library(names: Sequence[str] | None = None) -> list[Effect]:
    """The candidate effects, all or those whose key or family is in ``names``.

    Parameters
    ----------
    names : sequence of str, optional
        Keys (``current``, ``linear.X_u``, ``cross.Y_vr``, ``memory.u``…) or families
        (``current``, ``buoyancy``, ``cg_offset``, ``thrusters``, ``added_mass``,
        ``damping``, ``memory``, ``sensor_bias``) or ``all``.

    Returns
    -------
    list of Effect
    """
    effects: list[Effect] = [Current(), Buoyancy(), CGOffset(), ThrustGain(), DeadZone(),
                             Delay()]
    effects += [AddedMassScale(form) for form in ADDED_MASS_FORMS]
    effects += [AddedMassDof(i) for i in range(6)]
    effects += [Coefficient(i, q) for i in range(6) for q in (False, True)]
    effects += [Cross(CrossSpec.from_dict(c)) for c in DEFAULT_CROSS]
    effects += [Memory(i) for i in (0, 1, 2, 5)]
    effects += [GyroBias(), DvlBias()]
    if names is None or "all" in names:
        return effects
    wanted = set(names)
    chosen = [e for e in effects if e.key in wanted or e.family in wanted]
    known = {e.key for e in effects} | {e.family for e in effects}
    unknown = wanted - known
    if unknown:
        raise ConfigError("candidates", f"unknown {sorted(unknown)}; use 'all', a family "
                          f"{sorted({e.family for e in effects})} or a key such as "
                          f"{[e.key for e in effects[:8]]}")
    return chosen
