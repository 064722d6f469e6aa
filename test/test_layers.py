"""Layering rules (docs/architecture.md §2): dampest_ros.core and dampest_ros.io never load rclpy;
no private name is imported from another module. (import-linter checks the layer order.)"""

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# Runs in a fresh interpreter so that nothing imported by pytest or other tests interferes.
PROBE = """
import importlib, pkgutil, sys

def fail(name):
    raise ImportError(name)

imported = []
for top in ("dampest_ros.core", "dampest_ros.io"):
    pkg = importlib.import_module(top)
    imported.append(top)
    for info in pkgutil.walk_packages(pkg.__path__, top + ".", onerror=fail):
        importlib.import_module(info.name)
        imported.append(info.name)
ros = sorted(m for m in sys.modules if m == "rclpy" or m.startswith("rclpy."))
assert not ros, f"rclpy loaded by importing {imported}: {ros[:3]}..."
print(len(imported), "modules imported")
"""


def test_core_and_io_do_not_import_rclpy() -> None:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
    proc = subprocess.run(
        [sys.executable, "-c", PROBE],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_no_private_name_is_imported_across_modules() -> None:
    """A name that starts with _ stays in its module: a shared helper is public."""
    import ast

    crossings = []
    for path in sorted((REPO / "dampest_ros").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("dampest_ros"):
                crossings += [f"{path.relative_to(REPO)}: {node.module}.{a.name}"
                              for a in node.names if a.name.startswith("_")]
    assert not crossings, crossings
