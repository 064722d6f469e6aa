"""The node parameters files: every shipped config/<node>.params.yaml validates against its
shipped schema, and each schema says exactly what the node declares (names, types, ranges,
choices), so that an editor's check and the node's agree."""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("rclpy")

from dampest_ros.io.schema import load_checked, schema
from dampest_ros.ros.common import Param

REPO = Path(__file__).resolve().parents[2]
#: The nodes that ship a parameters file.
NODES = sorted(p.name.removesuffix(".params.yaml") for p in (REPO / "config").glob("*.params.yaml"))
_TYPES = {bool: "boolean", int: "integer", float: "number", str: "string", list: "array"}


def _property(p: Param) -> dict[str, Any]:
    """The schema of one declared parameter."""
    prop: dict[str, Any] = {"description": p.description, "default": p.default}
    kind = _TYPES[type(p.default)]
    prop["type"] = ["integer", "number"] if kind == "number" else kind
    if kind == "array" and p.default:
        prop["items"] = {"type": _TYPES[type(p.default[0])]}
    if p.choices:
        prop["enum"] = list(p.choices)
    if p.low is not None and kind in ("integer", "number"):
        prop["minimum"] = p.low
    if p.high is not None and kind in ("integer", "number"):
        prop["maximum"] = p.high
    return prop


def node_params(node: str) -> list[Param]:
    """The parameters ``node`` declares (its class's ``PARAMS``)."""
    module = importlib.import_module(f"dampest_ros.ros.{node}")
    cls = next(c for c in vars(module).values() if getattr(c, "NODE_NAME", None) == node)
    return list(cls.PARAMS)


def params_schema(node: str, specs: list[Param]) -> dict[str, Any]:
    """The JSON Schema of ``config/<node>.params.yaml`` from the node's declared specs."""
    props = {p.name: _property(p) for p in specs}
    props["use_sim_time"] = {"description": "use /clock (rclpy's own parameter)",
                             "type": "boolean", "default": False}
    params = {"type": "object", "additionalProperties": False, "properties": props,
              "description": f"the parameters of {node}: {', '.join(props)}"}
    node_section = {"type": "object", "additionalProperties": False,
                    "required": ["ros__parameters"],
                    "properties": {"ros__parameters": params},
                    "description": "a node name (or /**) with its ros__parameters"}
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "$id": f"https://dampest_ros/schemas/{node}.params.schema.json",
            "title": f"dampest_ros {node} parameters file (--ros-args --params-file)",
            "description": "node name (or /**): ros__parameters: parameter: value",
            "type": "object", "additionalProperties": node_section}


@pytest.mark.parametrize("node", NODES)
def test_params_schema_matches_the_node(node: str) -> None:
    assert schema(f"{node}.params") == params_schema(node, node_params(node))


@pytest.mark.parametrize("node", NODES)
def test_shipped_params_file_validates(node: str) -> None:
    doc = load_checked(REPO / "config" / f"{node}.params.yaml", f"{node}.params")
    assert set(doc.data["/**"]["ros__parameters"]) == {p.name for p in node_params(node)}
