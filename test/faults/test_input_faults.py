"""Input-file faults: a misspelt key, a duplicate key, a wrong type or an out-of-range value in
a file a user writes (vehicle file, CSV column map, node parameters file) is refused in one
line naming the file, the line, the key and the fix, never read as a default or the last
value. Every shipped preset validates.

Node processes run on ROS_DOMAIN_ID 81 (localhost only)."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

import pytest

from dampest_ros.cli.main import main
from dampest_ros.io.csv import load_column_map
from dampest_ros.io.schema import load_checked
from dampest_ros.io.strict_yaml import InputError
from dampest_ros.io.yaml_io import list_vehicles, load_vehicle, vehicle_path

REPO = Path(__file__).resolve().parents[2]
PRESET = (REPO / "config" / "vehicles" / "bluerov2_heavy.yaml").read_text()


def vehicle_file(tmp_path: Path, old: str, new: str) -> Path:
    """The BlueROV2 Heavy preset with ``old`` (once in it) replaced by ``new``."""
    assert PRESET.count(old) == 1
    path = tmp_path / "vehicle.yaml"
    path.write_text(PRESET.replace(old, new))
    return path


def line_of(path: Path, text: str) -> int:
    """The 1-based line of the first line of ``path`` holding ``text``."""
    return next(i for i, t in enumerate(path.read_text().splitlines(), 1) if text in t)


def refused(path: Path, capsys: pytest.CaptureFixture[str], tmp_path: Path) -> str:
    """The one stderr line of ``dampest simulate`` with vehicle ``path`` (status 2)."""
    assert main(["simulate", "--vehicle", str(path), "--duration", "2", "--out",
                 str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "out").exists()
    return err.strip()


def test_misspelt_added_mass_is_refused(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    """``added_mas:`` was read as no added mass at all (M_A = 0)."""
    path = vehicle_file(tmp_path, "  added_mass:", "  added_mas:")
    assert refused(path, capsys, tmp_path) == (
        f"dampest simulate: error: {path}:{line_of(path, 'added_mas')}: vehicle.added_mas: "
        "unknown key; did you mean added_mass?")


def test_misspelt_centre_of_buoyancy_is_refused(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """``r_bb:`` was read as r_b = 0."""
    path = vehicle_file(tmp_path, "  r_b:", "  r_bb:")
    assert refused(path, capsys, tmp_path).endswith(
        f"{path}:13: vehicle.r_bb: unknown key; did you mean r_b?")


def test_unknown_damping_kind_is_refused(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    """``quadratc:`` was ignored: a linear-only model."""
    path = vehicle_file(tmp_path, "  quadratic:", "  quadratc:")
    assert refused(path, capsys, tmp_path).endswith(
        f"{path}:20: damping.quadratc: unknown key; did you mean quadratic?")


def test_duplicate_mass_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A second ``mass:`` won silently."""
    path = vehicle_file(tmp_path, "  mass: 13.5\n", "  mass: 13.5\n  mass: 15.0\n")
    assert refused(path, capsys, tmp_path).endswith(
        f"{path}:11: vehicle.mass: duplicate key (also at line 10): the reader would keep only "
        "the last value silently; delete one of them")


def test_wrong_type_is_refused(tmp_path: Path) -> None:
    path = vehicle_file(tmp_path, "  mass: 13.5", "  mass: 13.5 kg")
    with pytest.raises(InputError) as err:
        load_vehicle(path)
    assert str(err.value) == (f'{path}:10: vehicle.mass: got "13.5 kg"; expected mass m in '
                              "kg, a number > 0")


def test_out_of_range_is_refused(tmp_path: Path) -> None:
    path = vehicle_file(tmp_path, "diameter: 0.076", "diameter: -0.076")
    with pytest.raises(InputError) as err:
        load_vehicle(path)
    assert str(err.value) == (f"{path}:22: thrusters.model.diameter: got -0.076; expected "
                              "propeller diameter D in m, a number > 0")


def test_misspelt_sensor_key_is_refused(tmp_path: Path) -> None:
    path = vehicle_file(tmp_path, "# sensors:\n#   imu:", "sensors:\n  dvl: {positon: [0.3, 0, 0]}"
                        "\n#   imu:")
    with pytest.raises(InputError, match=rf"^{path}:37: sensors\.dvl\.positon: unknown key; "
                                         "did you mean position\\?$"):
        load_vehicle(path)


def test_misspelt_column_map_entry_is_refused(tmp_path: Path) -> None:
    """``tau_x`` is none of our columns: the file's Fx column was dropped silently."""
    path = tmp_path / "map.yaml"
    path.write_text("columns:\n  t: time\n  Fx: tau_x\n")
    with pytest.raises(InputError) as err:
        load_column_map(path)
    assert str(err.value) == f'{path}:3: columns.Fx: got "tau_x"; did you mean tau_X?'


def test_misspelt_params_file_key_ends_the_node(tmp_path: Path, children: Any) -> None:
    """``forgeting_factor:`` was ignored: the node ran on the default 0.999."""
    text = (REPO / "config" / "estimator_node.params.yaml").read_text()
    path = tmp_path / "estimator.yaml"
    path.write_text(text.replace("    forgetting_factor: 0.999", "    forgeting_factor: 0.99"))
    env = {**os.environ, "ROS_DOMAIN_ID": "81", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    run = children.run([sys.executable, "-c", "from dampest_ros.ros.entry import "
                        "estimator_node; estimator_node()", "--ros-args", "--params-file",
                        str(path)], capture_output=True, text=True, timeout=120, env=env)
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in run.stderr
    assert lines[0].endswith(
        f"cannot start: {path}:{line_of(path, 'forgeting_factor')}: forgeting_factor: unknown "
        "parameter of estimator_node; did you mean forgetting_factor? (its parameters: "
        "vehicle, terms, structure, forgetting_factor, forgetting_mode, publish_rate, rate, "
        "cutoff, "
        "chunk, outlier_gate, prior, save_path, resume; `estimator_node --help` describes "
        "them)")


@pytest.mark.parametrize("name", list_vehicles())
def test_every_shipped_preset_validates(name: str) -> None:
    assert load_checked(vehicle_path(name), "vehicle").data["vehicle"]["name"] == name
    assert load_vehicle(name).name == name
