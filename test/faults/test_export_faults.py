"""An export that a simulator would turn into energy gain: the MuJoCo torpedo's default
identification (structural misfit: negative quadratic roll, sway and yaw damping, which the
fit allows inside the flown envelope) exported for gz-sim, which applies it at every speed."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from dampest_ros.cli.main import main


@pytest.fixture(scope="module")
def torpedo_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """120 s of the MuJoCo torpedo (seed 1) identified with the preset's terms alone
    (--no-select: the default would add library terms where they misfit)."""
    out = tmp_path_factory.mktemp("torpedo")
    assert main(["simulate", "--backend", "mujoco", "--vehicle", "torpedo_auv", "--duration",
                 "120", "--seed", "1", "--out", str(out / "bag")]) == 0
    assert main(["identify", str(out / "bag"), "--vehicle", "torpedo_auv", "--no-select",
                 "--out", str(out / "model.yaml")]) == 0
    return out / "model.yaml"


def gz_tags(path: Path) -> dict[str, float]:
    plugin = ET.fromstring(path.read_text().split("-->", 1)[1])
    return {el.tag: float(el.text or "nan") for el in plugin
            if el.tag != "link_name" and not el.tag.startswith("disable_")}


def test_torpedo_gz_export_is_refused_then_clamped_or_forced(
        torpedo_model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "hydro.sdf"
    capsys.readouterr()
    options = ["export", str(torpedo_model), "--format", "gz", "--vehicle", "torpedo_auv",
               "--out", str(out)]
    assert main(options) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and not out.exists()
    assert "K_pp: the damping turns non-dissipative beyond |nu| = 0.387 along (p +1.00)" \
        in err and "--clamp" in err and "--force" in err
    assert main([*options, "--clamp"]) == 0
    clamped = gz_tags(out)
    assert clamped["kPabsP"] == 0.0 and clamped["nRabsR"] == 0.0
    assert all(v <= 0.0 for k, v in clamped.items() if "Dot" not in k and k[0] == k[1].lower())
    assert "K_pp = 0: constrained (was -89.56" in out.read_text()
    assert main([*options, "--force"]) == 0
    forced = gz_tags(out)
    assert forced["kPabsP"] == pytest.approx(89.56, abs=0.01)
    assert "NOT DISSIPATIVE beyond |nu| = " in out.read_text()
