"""Which vehicle (or arm) a model belongs to: its kind, its name and a hash of what defines it.

Every model file carries an :class:`Identity` (``model.identity``), so that a tool given a
model and a vehicle can tell whether they belong together even when the names agree (two
files of one name with other masses) or differ only in name.

**The hash rule** (:func:`digest`, the one place it is computed). Each part of the identity is a
mapping of keys to numbers (scalars, arrays, booleans); every number is rounded to 9
significant digits and written ``format(x, ".9g")`` (−0 as ``0``, booleans as ``1``/``0``),
arrays flattened row-major and joined by ``,``; the lines ``key=values`` are sorted by key and
joined by newlines; the part's hash is the first 16 hex digits of the SHA-256 of that UTF-8
text. The identity's hash is :func:`digest` of the kind and the parts' hashes. Rounding to 9
digits makes the hash the same for numbers that went through YAML, float32 or another CPU's
last-digit arithmetic, and different for any physical change.

Parts of a vehicle (:func:`vehicle_identity`): ``rigid_body`` (mass, inertia 3×3, r_g, r_b),
``added_mass`` (M_A 6×6), ``thrusters`` (positions, directions, k_t, diameter, n_max,
time_constant, deadzone; ``none`` without thrusters). The added-mass switches are not part of
it: they say which added-mass effects a plant applies, and a model carries its own. A model
belongs to a vehicle when its hull parts (rigid body, added mass) agree (:func:`mismatch`):
thrusters only turn telemetry into τ, so a hull's model holds whatever propels it (a vehicle
file without thrusters for logs of τ, new thrusters). An arm's
(:func:`arm_identity`): ``joints`` (names, parents, joint frames, axes) and
``base_parameters`` (the names of the base parameters kept).
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dampest_ros.core.physics.rigid_body import ConfigError, RigidBody
from dampest_ros.core.physics.thrusters import Thrusters

#: ``kind`` of a vehicle's damping model and of an arm's base-parameter model.
VEHICLE_KIND = "vehicle_damping"
ARM_KIND = "arm"
#: Parts of a vehicle's identity that do not decide whether a model belongs to it.
NOT_HULL = ("thrusters",)
#: What a file without ``model.identity`` was written before.
BEFORE = "model files carried model.identity (dampest_ros 0.1.0 and earlier)"


def _text(value: Any) -> str:
    """One value of a part as text (the rule of the module docstring)."""
    if isinstance(value, str):
        return value
    flat = np.asarray(value).reshape(-1)
    if flat.dtype.kind in "US":
        return ",".join(str(x) for x in flat)
    return ",".join("0" if float(x) == 0.0 else format(float(x), ".9g") for x in flat)


def digest(values: Mapping[str, Any]) -> str:
    """The 16-hex-digit hash of a mapping of keys to numbers, arrays or strings (see the module
    docstring for the rule)."""
    text = "\n".join(f"{k}={_text(values[k])}" for k in sorted(values))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


@dataclass(frozen=True)
class Identity:
    """The vehicle (or arm) a model belongs to.

    Parameters
    ----------
    kind : str
        :data:`VEHICLE_KIND` or :data:`ARM_KIND`.
    name : str
        The vehicle's (arm's) name.
    parts : tuple of (str, str)
        Part name → its :func:`digest`, in a fixed order.
    """

    kind: str
    name: str
    parts: tuple[tuple[str, str], ...]

    @property
    def hash(self) -> str:
        """:func:`digest` of the kind and the parts' hashes."""
        return digest({"kind": self.kind, **dict(self.parts)})

    def label(self) -> str:
        """``'bluerov2_heavy' (3f2a9c01)``: the name and the hash's first 8 digits."""
        return f"{self.name!r} ({self.hash[:8]})"

    def as_dict(self) -> dict[str, Any]:
        """The ``model.identity`` namespace (strings only, ROS parameters)."""
        return {"kind": self.kind, "name": self.name, "hash": self.hash,
                "parts": dict(self.parts)}

    @classmethod
    def from_dict(cls, d: Any, where: str = "") -> Identity:
        """The inverse of :meth:`as_dict`.

        Raises
        ------
        ConfigError
            Missing entries, or a ``hash`` that is not that of the parts (an edited file).
        """
        try:
            parts = tuple((str(k), str(v)) for k, v in d["parts"].items())
            identity = cls(str(d["kind"]), str(d["name"]), parts)
            given = str(d["hash"])
        except (KeyError, TypeError, AttributeError):
            raise ConfigError("model.identity", f"needs kind, name, hash and parts{where}"
                              ) from None
        if given != identity.hash:
            raise ConfigError("model.identity.hash", f"{given} is not the hash of its parts "
                                                     f"({identity.hash}){where}")
        return identity

    def differs(self, other: Identity) -> list[str]:
        """The parts whose hashes differ (a part one of them lacks counts)."""
        mine, theirs = dict(self.parts), dict(other.parts)
        return [k for k in dict.fromkeys([*mine, *theirs]) if mine.get(k) != theirs.get(k)]


def vehicle_identity(name: str, body: RigidBody, thrusters: Thrusters | None) -> Identity:
    """The identity of a vehicle: its name and the hashes of its rigid body, added mass and
    thrusters."""
    parts = {
        "rigid_body": digest({"mass": body.mass, "inertia": body.inertia, "r_g": body.r_g,
                              "r_b": body.r_b}),
        "added_mass": digest({"M_A": body.added_mass}),
        "thrusters": "none" if thrusters is None else digest({
            "positions": thrusters.positions, "directions": thrusters.directions,
            "k_t": thrusters.k_t, "diameter": thrusters.diameter, "n_max": thrusters.n_max,
            "time_constant": thrusters.time_constant, "deadzone": thrusters.deadzone}),
    }
    return Identity(VEHICLE_KIND, name, tuple(parts.items()))


def arm_identity(name: str, joints: Mapping[str, Any], base_names: Sequence[str]) -> Identity:
    """The identity of an arm: its name, the hash of its joints (``joints``: names, parents,
    frames and axes as arrays) and of the names of its base parameters."""
    return Identity(ARM_KIND, name, (("joints", digest(joints)),
                                     ("base_parameters", digest({"names": list(base_names)}))))


def mismatch(found: Identity | None, expected: Identity, source: str) -> str | None:
    """Why the model at ``source`` does not belong to ``expected`` (None: it does, or the file
    has no identity: see :func:`unchecked`)."""
    if found is None or found.hash == expected.hash:
        return None
    what = "arm" if expected.kind == ARM_KIND else "vehicle"
    differ = [k for k in found.differs(expected) if k not in NOT_HULL]
    if found.kind != expected.kind:
        why = f"it is a {found.kind} model, not a {expected.kind} one"
    elif not differ:
        return None
    else:
        why = f"they differ in {', '.join(differ)}"
    return (f"{source} belongs to {found.kind} {found.label()}, not to the {what} in use "
            f"{expected.label()} ({why}): use the {what} the model was made for, or make a "
            f"model for {expected.name!r} (dampest identify / the node's ~/save to another "
            f"file)")


def unchecked(found: Identity | None, expected: Identity | None, source: str) -> str | None:
    """The warning for a model without an identity (None when it has one)."""
    if found is not None:
        return None
    whose = "vehicle" if expected is None or expected.kind == VEHICLE_KIND else "arm"
    target = f"{whose} {expected.name!r}" if expected is not None else f"the {whose} in use"
    return f"{source}: no {whose} identity: written before {BEFORE}; cannot check it " \
           f"belongs to {target}"
