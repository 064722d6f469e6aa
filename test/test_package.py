"""colcon builds the package; every console script lands in lib/dampest_ros and answers --help."""

import ast
import configparser
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = "dampest_ros"
# What a user's workspace holds after cloning (pyproject.toml included: colcon must ignore it).
PACKAGE_FILES = [
    "package.xml",
    "setup.py",
    "setup.cfg",
    "pyproject.toml",
    "resource",
    PACKAGE,
    "config",
]


def node_scripts() -> dict[str, str]:
    """NODE_SCRIPTS from setup.py, read with ast (setup.py is not executed)."""
    for node in ast.parse((REPO / "setup.py").read_text()).body:
        if isinstance(node, ast.Assign):
            targets, value = node.targets, node.value
        elif isinstance(node, ast.AnnAssign) and node.value is not None:
            targets, value = [node.target], node.value
        else:
            continue
        if any(isinstance(t, ast.Name) and t.id == "NODE_SCRIPTS" for t in targets):
            scripts = ast.literal_eval(value)
            assert isinstance(scripts, dict)
            return scripts
    raise AssertionError("setup.py defines no NODE_SCRIPTS literal")


def find_colcon() -> Path:
    colcon = Path(sys.executable).parent / "colcon"
    if colcon.exists():
        return colcon
    found = shutil.which("colcon")
    if found is None:
        pytest.skip("colcon not installed")
    return Path(found)


@pytest.fixture(scope="module")
def install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    ws = tmp_path_factory.mktemp("ws")
    src = ws / "src" / PACKAGE
    src.mkdir(parents=True)
    for name in PACKAGE_FILES:
        path = REPO / name
        if path.is_dir():
            ignore = shutil.ignore_patterns("__pycache__", "*.egg-info")
            shutil.copytree(path, src / name, ignore=ignore)
        else:
            shutil.copy2(path, src / name)
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env["COLCON_HOME"] = str(ws / "colcon_home")
    env["COLCON_LOG_PATH"] = str(ws / "log")
    proc = subprocess.run(
        [
            str(find_colcon()),
            "build",
            "--base-paths",
            "src",
            "--build-base",
            "build",
            "--install-base",
            "install",
        ],
        cwd=ws,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return ws / "install" / PACKAGE


@pytest.mark.parametrize("script", ["dampest", *node_scripts()])
def test_script_installed_and_runs(install: Path, script: str) -> None:
    exe = install / "lib" / PACKAGE / script
    assert exe.is_file(), f"{exe} missing"
    site = next(install.glob("lib/python3*/site-packages"))
    # The entry point's module must be in the install space itself (not only in a venv's
    # editable install): catches packages that find_packages() missed.
    entry_points = configparser.ConfigParser(delimiters=("=",))
    entry_points.optionxform = str  # type: ignore[assignment,method-assign]
    entry_points.read(next(site.glob(f"{PACKAGE}-*.egg-info")) / "entry_points.txt")
    module = entry_points["console_scripts"][script].split(":")[0]
    assert (site / (module.replace(".", "/") + ".py")).is_file(), f"{module} not installed"
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(site), env.get("PYTHONPATH")) if p)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(
        p for p in (str(install), env.get("AMENT_PREFIX_PATH")) if p
    )
    proc = subprocess.run(
        [str(exe), "--help"], cwd=install, env=env, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "usage" in proc.stdout.lower(), proc.stdout


def test_share_files_installed(install: Path) -> None:
    share = install / "share" / PACKAGE
    assert (share / "package.xml").is_file()
    index = install / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE
    assert index.is_file()
    vehicles = sorted((REPO / "config" / "vehicles").glob("*.yaml"))
    assert vehicles, "no vehicle presets in config/vehicles"
    for path in (REPO / "config").rglob("*"):
        if path.is_file():
            rel = path.relative_to(REPO)
            assert (share / rel).is_file(), f"{rel} not installed"
