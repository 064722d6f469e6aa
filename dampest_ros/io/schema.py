"""The JSON Schemas of the files users write, and the check that names file, line and fix.

The schemas ship inside the package (``dampest_ros/schemas/<name>.schema.json``, JSON Schema
2020-12), so that editors can check a file as it is typed (README.md, "Schemas") and every
reader checks it the same way: ``vehicle`` (``config/vehicles/*.yaml``), ``column_map``
(``--columns``), ``arm_trajectory`` (``dampest arm design --out``) and ``<node>.params``
(``config/<node>.params.yaml``). jsonschema validates; :func:`check` turns its most relevant
error into one line: an unknown key with the closest valid one (difflib), a missing key, a
value of the wrong type or out of range with what the schema's ``description`` says is
expected.

A mapping that takes extra entries besides its own keys (the model files' ``model:``) says
so with ``"x-refuseNearMisses": true``: an extra key spelt almost like one of its own
(``theta_sdt``, ``identifed``) is refused as the typo it is, not kept as an extra entry.
"""

from __future__ import annotations

import difflib
import json
import re
from collections.abc import Sequence
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

import jsonschema
from jsonschema.exceptions import ValidationError, best_match
from jsonschema.validators import extend

from dampest_ros.io.strict_yaml import InputError, YamlDoc, key_text, load_yaml


@cache
def schema(name: str) -> dict[str, Any]:
    """The shipped schema ``name`` (``vehicle``, ``column_map``, ``estimator_node.params``…)."""
    text = (resources.files("dampest_ros") / "schemas" / f"{name}.schema.json").read_text()
    loaded: dict[str, Any] = json.loads(text)
    return loaded


def schema_path(name: str) -> Path:
    """Where the shipped schema ``name`` is on disk (for an editor's settings)."""
    return Path(str(resources.files("dampest_ros") / "schemas" / f"{name}.schema.json"))


def nearest(word: str, choices: Sequence[str], cutoff: float = 0.6) -> str | None:
    """The valid word nearest ``word`` (difflib, case ignored, at least ``cutoff`` alike),
    or None."""
    lower = {str(c).lower(): str(c) for c in reversed(choices)}
    near = difflib.get_close_matches(str(word).lower(), list(lower), n=1, cutoff=cutoff)
    return lower[near[0]] if near else None


#: How alike an extra key must be to one of the mapping's own to be refused as its typo
#: (``rmse``, an extra of every fit, is 0.67 alike ``terms``).
_TYPO_CUTOFF = 0.8


def _near_misses(validator: Any, enabled: bool, instance: Any, schema_: dict[str, Any]
                 ) -> Any:
    """The ``x-refuseNearMisses`` keyword: an error for each key that is not one of the
    mapping's ``properties`` but spelt almost like one (its message: that one)."""
    if not (enabled and validator.is_type(instance, "object")):
        return
    own = list(schema_.get("properties", {}))
    for key in instance:
        near = None if key in own else nearest(str(key), own, _TYPO_CUTOFF)
        if near is not None:
            yield ValidationError(near, path=[key])


_Validator = extend(jsonschema.Draft202012Validator, {"x-refuseNearMisses": _near_misses})


def closest(word: str, choices: Sequence[str]) -> str:
    """``"; did you mean X?"`` for the valid word nearest ``word``, else the valid words."""
    near = nearest(word, choices)
    return f"; did you mean {near}?" if near else f"; valid: {', '.join(choices)}"


def _unknown_key(error: ValidationError) -> tuple[str, str] | None:
    """(key, suggestion) of the first key an ``additionalProperties: false`` refuses."""
    known = list(error.schema.get("properties", {}))
    patterns = list(error.schema.get("patternProperties", {}))
    for key in error.instance:
        if key not in known and not any(re.search(p, str(key)) for p in patterns):
            return str(key), closest(str(key), known)
    return None


def _expected(error: ValidationError, root: dict[str, Any], data: Any
              ) -> tuple[ValidationError, str]:
    """The error to report and what its schema says is expected: the outermost ``oneOf``
    the error is inside (its alternatives are one value's forms), else the nearest error
    (``error`` or a parent) whose schema has a description."""
    e: ValidationError | None = error
    while e is not None and e.parent is not None:
        if e.parent.validator in ("oneOf", "anyOf"):
            error = e.parent
        e = e.parent
    e = error
    while e is not None:
        if isinstance(e.schema, dict) and "description" in e.schema:
            return e, str(e.schema["description"])
        e = e.parent
    return _array_of(error, root, data)


def _array_of(error: ValidationError, root: dict[str, Any], data: Any
              ) -> tuple[ValidationError, str]:
    """For an item of an array whose items have no description: an error for the whole
    array (the key users write) with the array's description, else ``error`` as it is."""
    schema_path, path = list(error.absolute_schema_path)[:-1], list(error.absolute_path)
    while schema_path[-1:] == ["items"] and path and isinstance(path[-1], int):
        schema_path, path = schema_path[:-1], path[:-1]
    if len(path) == len(error.absolute_path):
        return error, str(error.message)
    node: Any = root
    for key in schema_path:
        node = node[key]
    instance = data
    for key in path:
        instance = instance[key]
    whole = ValidationError(error.message, instance=instance, schema=node, path=path)
    return whole, str(node.get("description", error.message))


def _message(error: ValidationError, root: dict[str, Any], data: Any
             ) -> tuple[list[Any], str]:
    """(key path, reason and fix) for one jsonschema error of ``data`` against ``root``."""
    path = list(error.absolute_path)
    if error.validator == "x-refuseNearMisses":
        return path, (f"unknown key; did you mean {error.message}? rename it (an extra "
                      "entry must not be spelt like one of the file's own keys)")
    if error.validator == "additionalProperties":
        found = _unknown_key(error)
        if found is not None:
            return [*path, found[0]], f"unknown key{found[1]}"
    if error.validator == "required":
        missing = re.match(r"'([^']*)'", error.message)
        key = missing.group(1) if missing else "?"
        wanted = error.schema.get("properties", {}).get(key, {}).get("description", "")
        return [*path, key], f"missing; add it ({wanted})" if wanted else "missing; add it"
    where, expected = _expected(error, root, data)
    got = f"got {json.dumps(where.instance, default=str)}"
    words = [w for alt in (where.schema, *where.schema.get("anyOf", ()),
                           *where.schema.get("oneOf", ())) for w in alt.get("enum", ())]
    near = nearest(where.instance, words) if isinstance(where.instance, str) else None
    if near is not None:
        return list(where.absolute_path), f"{got}; did you mean {near}?"
    return list(where.absolute_path), f"{got}; expected {expected}"


def check(doc: YamlDoc, name: str, skip: int = 0) -> None:
    """Check a parsed file against the shipped schema ``name``.

    Parameters
    ----------
    doc : YamlDoc
    name : str
    skip : int
        Leading keys of a path the message leaves out (2 for a parameters file's
        ``<node>: ros__parameters:``, so that the key reads as the parameter's name).

    Raises
    ------
    InputError
        ``<file>:<line>: <key>: <what>; <fix>`` for the most relevant violation.
    """
    errors = list(_Validator(schema(name)).iter_errors(doc.data))
    typos = [e for e in errors if e.validator == "x-refuseNearMisses"]
    error = typos[0] if typos else best_match(errors)  # a typo explains a missing key
    if error is not None:
        path, reason = _message(error, schema(name), doc.data)
        raise InputError(doc.source, doc.line(path), key_text(path[skip:]), reason)


def load_checked(path: str | Path, name: str) -> YamlDoc:
    """Read a user's YAML file (duplicate keys refused) and check it against schema ``name``.

    Raises
    ------
    InputError
        Not valid YAML, a duplicate key, or a schema violation (file, line, key, fix).
    OSError
        The file cannot be read.
    """
    doc = load_yaml(path, f"a {name.replace('_', ' ')} YAML file")
    check(doc, name)
    return doc
