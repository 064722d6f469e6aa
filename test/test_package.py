"""colcon builds the package (the session's colcon_install, test/conftest.py); every console
script lands in lib/dampest_ros and answers --help, and `dampest` is on PATH after sourcing
the install (bin/)."""

import ast
import configparser
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = "dampest_ros"


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


SCRIPTS = ["dampest", *node_scripts()]


def install_site(install: Path) -> Path:
    return next(install.glob("lib/python3*/site-packages"))


@pytest.fixture(scope="module")
def helps(colcon_install: Path, tmp_path_factory: pytest.TempPathFactory,
          module_children: Any) -> dict[str, tuple[int, str, str]]:
    """``<script> --help`` of every installed console script, started all at once (each is
    mostly the import of rclpy and the package, so together they take a fraction of their
    sum): script → (exit status, stdout, stderr)."""
    out = tmp_path_factory.mktemp("help")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(
        p for p in (str(install_site(colcon_install)), env.get("PYTHONPATH")) if p)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(
        p for p in (str(colcon_install), env.get("AMENT_PREFIX_PATH")) if p
    )
    procs = {}
    for script in SCRIPTS:
        exe = colcon_install / "lib" / PACKAGE / script
        if exe.is_file():
            with (out / f"{script}.out").open("w") as o, (out / f"{script}.err").open("w") as e:
                procs[script] = module_children.start([str(exe), "--help"],
                                                      cwd=colcon_install, env=env, stdout=o,
                                                      stderr=e, text=True)
    return {script: (p.wait(timeout=120), (out / f"{script}.out").read_text(),
                     (out / f"{script}.err").read_text()) for script, p in procs.items()}


@pytest.mark.parametrize("script", SCRIPTS)
def test_script_installed_and_runs(colcon_install: Path, helps: dict[str, tuple[int, str, str]],
                                   script: str) -> None:
    exe = colcon_install / "lib" / PACKAGE / script
    assert exe.is_file(), f"{exe} missing"
    site = install_site(colcon_install)
    # The entry point's module must be in the install space itself (not only in a venv's
    # editable install): catches packages that find_packages() missed.
    entry_points = configparser.ConfigParser(delimiters=("=",))
    entry_points.optionxform = str  # type: ignore[assignment,method-assign]
    entry_points.read(next(site.glob(f"{PACKAGE}-*.egg-info")) / "entry_points.txt")
    module = entry_points["console_scripts"][script].split(":")[0]
    assert (site / (module.replace(".", "/") + ".py")).is_file(), f"{module} not installed"
    status, stdout, stderr = helps[script]
    assert status == 0, stdout + stderr
    assert "usage" in stdout.lower(), stdout


def test_dampest_is_on_path_after_sourcing_the_install(colcon_install: Path,
                                                      children: Any) -> None:
    """``. install/setup.sh`` puts install/dampest_ros/bin first on PATH: ``dampest`` is the
    install's (the same console script as lib/dampest_ros/dampest), not a venv's."""
    exe = colcon_install / "bin" / "dampest"
    assert exe.is_file() and exe.read_bytes() == (colcon_install / "lib" / PACKAGE / "dampest"
                                                  ).read_bytes()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), "/usr/bin", "/bin"])
    proc = children.run(
        ["sh", "-c", '. "$1/setup.sh" && command -v dampest && dampest --help', "sh",
         str(colcon_install.parent)], env=env, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    where, usage = proc.stdout.split("\n", 1)
    assert Path(where) == exe and usage.startswith("usage: dampest"), proc.stdout


def test_share_files_installed(colcon_install: Path) -> None:
    share = colcon_install / "share" / PACKAGE
    assert (share / "package.xml").is_file()
    index = colcon_install / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE
    assert index.is_file()
    vehicles = sorted((REPO / "config" / "vehicles").glob("*.yaml"))
    assert vehicles, "no vehicle presets in config/vehicles"
    for path in (REPO / "config").rglob("*"):
        if path.is_file():
            rel = path.relative_to(REPO)
            assert (share / rel).is_file(), f"{rel} not installed"


#: rosdep key of each third-party top-level import of dampest_ros (a ROS 2 package's key is
#: its own name, the default). Pip keys (-pip) are those of rosdistro's rosdep/python.yaml
#: for packages Ubuntu does not ship; the mcap package comes with mcap-ros2-support.
ROSDEP_KEYS = {
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "matplotlib": "python3-matplotlib",
    "yaml": "python3-yaml",
    "jsonschema": "python3-jsonschema",
    "filterpy": "python3-filterpy-pip",
    "rosbags": "python3-rosbags-pip",
    "mcap": "mcap-ros2-support",
    "mcap_ros2": "mcap-ros2-support",
    "mujoco": "python3-mujoco-pip",
    "pinocchio": "pinocchio",
}
#: Imports with no rosdep key: the pip extra 'pool' of setup.py (README.md names it); the
#: code that needs them says how to install them.
OPTIONAL = {"dask", "distributed", "fsspec"}
#: Every key rosdep resolves on Jazzy (ros/rosdistro, August 2026; a copy kept here).
ROSDEP_JAZZY = REPO / "test" / "data" / "rosdep_keys_jazzy.txt"
#: Imports that are not run dependencies: the peers the arm benchmark compares with
#: (requirements/peers.txt, ``make bench-peers``; dampest_ros.bench.arm imports them only there).
BENCH_PEERS = {"figaroh"}


def third_party_imports() -> dict[str, str]:
    """Top-level name → a file importing it, for every import in dampest_ros/ and launch/
    that is neither the standard library nor dampest_ros (lazy imports inside functions
    included)."""
    found: dict[str, str] = {}
    for path in sorted([*(REPO / PACKAGE).rglob("*.py"), *(REPO / "launch").glob("*.py")]):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split(".")[0]
                if top not in sys.stdlib_module_names and top != PACKAGE:
                    found.setdefault(top, str(path.relative_to(REPO)))
    return found


def test_package_xml_declares_every_third_party_import() -> None:
    """rosdep install on a full ROS 2 install must leave no import failing."""
    root = ET.parse(REPO / "package.xml").getroot()
    run = {e.text for e in root if e.tag in ("exec_depend", "depend") and e.text}
    imports = third_party_imports()
    assert {"numpy", "rclpy", "rosbags", "yaml"} <= set(imports)  # the scan sees imports
    missing = {name: (ROSDEP_KEYS.get(name, name), where) for name, where in imports.items()
               if ROSDEP_KEYS.get(name, name) not in run
               and name not in BENCH_PEERS | OPTIONAL}
    assert not missing, f"package.xml lacks exec_depend for (import: (key, file)) {missing}"
    assert "ament_index_python" in imports and "dask" in imports  # launch/ and pool scanned


def test_every_package_xml_key_resolves_on_jazzy() -> None:
    """rosdep install fails on the first key it cannot resolve: every dependency of
    package.xml is a key of the Jazzy list (ament_python is a build type, not a key)."""
    keys = {line.strip() for line in ROSDEP_JAZZY.read_text().splitlines()
            if line.strip() and not line.startswith("#")}
    assert len(keys) > 4000 and "rclpy" in keys and "ament_python" not in keys
    root = ET.parse(REPO / "package.xml").getroot()
    deps = {e.tag: [] for e in root if e.tag.endswith("depend")}
    for e in root:
        if e.tag.endswith("depend") and e.text:
            deps[e.tag].append(e.text.strip())
    unknown = {tag: [k for k in ks if k not in keys] for tag, ks in deps.items()}
    assert not any(unknown.values()), f"not rosdep keys on Jazzy: {unknown}"


def test_optional_imports_are_the_pool_extra_and_say_how_to_install() -> None:
    """Dask and fsspec: setup.py's 'pool' extra, and a one-line refusal without them."""
    setup_text = (REPO / "setup.py").read_text()
    assert 'POOL_EXTRA = ["dask", "distributed", "fsspec"]' in setup_text
    assert 'extras_require={"pool": POOL_EXTRA}' in setup_text
    code = ("import sys; sys.modules['dask'] = None; sys.modules['dask.distributed'] = None\n"
            "from dampest_ros.cli.pool import need_dask\n"
            "try:\n    need_dask()\nexcept Exception as exc:\n    print(exc)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=REPO, check=True).stdout
    assert "pip install dask distributed fsspec" in out and "'pool' extra" in out, out
