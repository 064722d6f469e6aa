"""Parameter files and launch files: config/<node>.params.yaml holds every
parameter a node declares, with its default and a comment, and loads with --params-file;
launch/*.launch.py (``launch`` itself is not installable here) parse, name executables that
setup.py installs and parameter files that exist, and are installed by setup.py."""

from __future__ import annotations

import ast
import importlib
import importlib.util
from pathlib import Path
from typing import Any

import pytest
import yaml

rclpy = pytest.importorskip("rclpy")

REPO = Path(__file__).resolve().parents[2]
LAUNCH_FILES = sorted((REPO / "launch").glob("*.launch.py"))


def node_scripts() -> dict[str, str]:
    """setup.py's NODE_SCRIPTS (a plain literal)."""
    tree = ast.parse((REPO / "setup.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.AnnAssign) and getattr(node.target, "id", "") == "NODE_SCRIPTS":
            assert node.value is not None
            scripts: dict[str, str] = ast.literal_eval(node.value)
            return scripts
    raise AssertionError("setup.py has no NODE_SCRIPTS")


def node_class(name: str) -> Any:
    """The node class of an executable: its entry runs dampest_ros.ros.<name>.main()."""
    assert node_scripts()[name] == f"dampest_ros.ros.entry:{name}"
    module = importlib.import_module(f"dampest_ros.ros.{name}")
    (cls,) = [c for c in vars(module).values()
              if isinstance(c, type) and getattr(c, "NODE_NAME", None) == name]
    return cls


def params_file(name: str) -> dict[str, Any]:
    doc = yaml.safe_load((REPO / "config" / f"{name}.params.yaml").read_text())
    values: dict[str, Any] = doc["/**"]["ros__parameters"]
    return values


@pytest.mark.parametrize("name", sorted(node_scripts()))
def test_parameter_file_holds_every_parameter_with_its_default_and_meaning(name: str) -> None:
    specs = node_class(name).PARAMS
    assert params_file(name) == {p.name: p.default for p in specs}
    lines = (REPO / "config" / f"{name}.params.yaml").read_text().splitlines()
    for p in specs:  # each entry follows its comment, which starts with the description
        (k,) = [i for i, x in enumerate(lines) if x.startswith(f"    {p.name}: ")]
        j = k
        while lines[j - 1].startswith("    # "):
            j -= 1
        comment = " ".join(x[6:] for x in lines[j:k])
        assert j < k and comment.startswith(p.description.rstrip(".")), (p.name, comment)


def test_parameter_files_load_with_params_file_and_name_every_declared_parameter(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each node started with --params-file config/<node>.params.yaml (plus what it needs,
    given after it) declares exactly the file's parameters (besides rclpy's own and the
    model.* of the model servers)."""
    from dampest_ros.core.identification.model import Model
    from dampest_ros.io.yaml_io import load_vehicle, save_model

    monkeypatch.setenv("ROS_DOMAIN_ID", "81")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    v = load_vehicle("bluerov2_heavy")
    model = save_model(tmp_path / "m.yaml", Model(v.damping.parameter_names, v.theta,
                                                  0.1 * abs(v.theta) + 0.01, v.body.M,
                                                  damping=v.damping))
    bag = tmp_path / "bag"
    from dampest_ros.io.recorder import BagRecorder
    with BagRecorder(bag) as rec:
        rec.write(rec.add_connection("/pressure", "sensor_msgs/msg/FluidPressure"), 1,
                  bytes(4 + 8 + 4 + 8 + 8))
    needs = {"model_server_node": ["-p", f"model_file:={model}"],
             "recorder_node": ["-p", f"output:={tmp_path / 'out'}"],
             "replay_node": ["-p", f"bag:={bag}"],
             "estimator_node": ["-p", f"save_path:={tmp_path / 'est.yaml'}"]}
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        for name in sorted(node_scripts()):
            node = node_class(name)(context=context, cli_args=[
                "--ros-args", "--params-file", str(REPO / "config" / f"{name}.params.yaml"),
                *needs.get(name, [])])
            try:
                declared = {n for n in node._parameters
                            if n not in ("use_sim_time", "start_type_description_service")
                            and not n.startswith("model.")}
                assert declared == set(params_file(name)), name
                # the file was read: each of its entries is an override of this node
                assert set(params_file(name)) <= set(node._parameter_overrides), name
            finally:
                node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def calls(tree: ast.AST, name: str) -> list[ast.Call]:
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call)
            and getattr(n.func, "id", getattr(n.func, "attr", None)) == name]


def keyword(call: ast.Call, key: str) -> ast.expr | None:
    return next((k.value for k in call.keywords if k.arg == key), None)


@pytest.mark.parametrize("path", LAUNCH_FILES, ids=[p.name for p in LAUNCH_FILES])
def test_launch_file_names_installed_executables_and_existing_parameter_files(
        path: Path) -> None:
    tree = ast.parse(path.read_text(), str(path))
    compile(tree, str(path), "exec")
    assert any(isinstance(n, ast.FunctionDef) and n.name == "generate_launch_description"
               for n in tree.body)
    nodes = calls(tree, "Node")
    assert len(nodes) >= 3
    for call in nodes:
        exe, package = keyword(call, "executable"), keyword(call, "package")
        assert isinstance(exe, ast.Constant) and exe.value in node_scripts(), ast.dump(call)
        assert isinstance(package, ast.Constant) and package.value == "dampest_ros"
        files = [n.value for n in ast.walk(call) if isinstance(n, ast.Constant)
                 and isinstance(n.value, str) and n.value.endswith(".params.yaml")]
        assert files == [f"{exe.value}.params.yaml"], files  # its own file, first
        assert (REPO / "config" / files[0]).is_file()
    used = {c.args[0].value for c in calls(tree, "LaunchConfiguration")
            if isinstance(c.args[0], ast.Constant)}
    declared = {c.args[0].value for c in calls(tree, "DeclareLaunchArgument")
                if isinstance(c.args[0], ast.Constant)}
    assert used == declared, (used, declared)


def test_setup_installs_every_launch_file() -> None:
    tree = ast.parse((REPO / "setup.py").read_text())
    installed = [n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
                 and isinstance(n.value, str) and n.value.endswith(".launch.py")]
    assert sorted(installed) == [f"launch/{p.name}" for p in LAUNCH_FILES]
    assert [p.name for p in LAUNCH_FILES] == ["pipeline.launch.py", "replay.launch.py"]


class Recorded:
    """A stand-in for a launch class: keeps its arguments."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.args, self.kwargs = args, kwargs


def launch_description(path: Path, share: Path, monkeypatch: pytest.MonkeyPatch
                       ) -> list[Recorded]:
    """Run ``generate_launch_description()`` of a launch file against minimal stand-ins for
    launch, launch_ros and ament_index_python (none is installable here): its entities."""
    import types

    def module(name: str, **attrs: Any) -> types.ModuleType:
        m = types.ModuleType(name)
        vars(m).update(attrs)
        monkeypatch.setitem(__import__("sys").modules, name, m)
        return m

    module("ament_index_python")
    module("ament_index_python.packages", get_package_share_directory=lambda pkg: str(share))
    module("launch", LaunchDescription=lambda entities: list(entities))
    for name, cls in (("launch.actions", "DeclareLaunchArgument"),
                      ("launch.conditions", "IfCondition"),
                      ("launch.substitutions", "LaunchConfiguration"),
                      ("launch_ros.actions", "Node")):
        module(name, **{cls: type(cls, (Recorded,), {})})
    module("launch_ros")
    spec = importlib.util.spec_from_file_location(path.stem.replace(".", "_"), path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    entities: list[Recorded] = mod.generate_launch_description()
    return entities


@pytest.mark.parametrize("path", LAUNCH_FILES, ids=[p.name for p in LAUNCH_FILES])
def test_launch_description_runs_with_existing_executables_files_and_arguments(
        path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each launch file's description, built: every node an installed executable with its
    own existing parameter file first, every LaunchConfiguration a declared argument."""
    entities = launch_description(path, REPO, monkeypatch)
    args = {e.args[0]: e.kwargs for e in entities if type(e).__name__ == "DeclareLaunchArgument"}
    nodes = [e for e in entities if type(e).__name__ == "Node"]
    assert len(nodes) >= 3
    for node in nodes:
        exe = node.kwargs["executable"]
        assert exe in node_scripts() and node.kwargs["package"] == "dampest_ros"
        first = Path(node.kwargs["parameters"][0])
        assert first == REPO / "config" / f"{exe}.params.yaml" and first.is_file()
        for extra in node.kwargs["parameters"][1:]:
            declared = set(params_file(exe)) | {"use_sim_time"}
            assert set(extra) <= declared, (exe, set(extra) - declared)
            for value in extra.values():
                if type(value).__name__ == "LaunchConfiguration":
                    assert value.args[0] in args, value.args[0]


def test_pipeline_identifies_by_default_and_replay_plays_sensors_only(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The default pipeline starts no controller (the simulated vehicle would follow its
    zero reference instead of the excitation); replay plays the sensor topics, not a
    recording's dampest/* outputs into the running nodes, a second after the match."""
    pipeline = launch_description(REPO / "launch" / "pipeline.launch.py", REPO, monkeypatch)
    args = {e.args[0]: e.kwargs for e in pipeline
            if type(e).__name__ == "DeclareLaunchArgument"}
    assert args["controller"]["default_value"] == "false"
    replay = launch_description(REPO / "launch" / "replay.launch.py", REPO, monkeypatch)
    args = {e.args[0]: e.kwargs for e in replay if type(e).__name__ == "DeclareLaunchArgument"}
    topics = yaml.safe_load(args["topics"]["default_value"])
    assert topics == ["imu/data", "dvl/twist", "pressure", "thrusters/state"]
    (player,) = [e for e in replay if e.kwargs.get("executable") == "replay_node"]
    assert player.kwargs["parameters"][1]["topics"].args[0] == "topics"
    # a second between the publishers' match and play: best effort loses nothing at the start
    assert args["delay"]["default_value"] == "1.0"
    assert player.kwargs["parameters"][1]["delay"].args[0] == "delay"
