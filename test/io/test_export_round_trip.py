"""Export then import, for every format: a seeded model with linear (diagonal and coupling),
quadratic and cross terms comes back coefficient for coefficient (1e-12); what a format cannot
carry is in the export's left-out list, and the two together are the whole model."""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.vehicle import damping_from_spec
from dampest_ros.io.export.common import ExportWarning, Imported
from dampest_ros.io.export.convert import detect_format, export_model, import_model
from dampest_ros.io.export.uuv import import_uuv
from dampest_ros.io.yaml_io import load_model, save_model

F, V = "XYZKMN", "uvwpqr"


def seeded_spec(seed: int = 3) -> dict[str, Any]:
    """Linear (all six diagonal terms and four couplings), quadratic (six) and cross terms
    (|ν_k| and signed u) drawn from ``seed``: couplings small beside the diagonal, so that
    every format's form stays dissipative at every speed."""
    rng = np.random.default_rng(seed)
    diag = rng.uniform(5.0, 40.0, 6)
    quad = rng.uniform(50.0, 200.0, 6)
    lin = {f"{F[i]}_{V[i]}": float(diag[i]) for i in range(6)}
    lin.update({name: float(rng.uniform(-0.5, 0.5)) for name in ("X_w", "Y_r", "N_v", "K_v")})
    cross = [{"row": row, "col": col, "alpha": alpha, "value": float(rng.uniform(-1.0, 1.0))}
             for row, col, alpha in (("Y", "v", "|r|"), ("X", "u", "|w|"), ("Z", "w", "u"),
                                     ("Y", "r", "u"), ("N", "v", "u"))]
    return {"linear": lin, "quadratic": {f"{F[i]}_{V[i] * 2}": float(quad[i])
                                         for i in range(6)}, "cross": cross}


@pytest.fixture
def seeded(tmp_path: Path) -> Model:
    """The seeded model with a full symmetric added mass (model.M_A), saved and read back."""
    model, theta = damping_from_spec(seeded_spec())
    M_A = np.diag([6.36, 7.12, 18.68, 0.189, 0.135, 0.222])
    M_A[0, 4] = M_A[4, 0] = 0.4
    M_A[1, 5] = M_A[5, 1] = 0.3
    path = save_model(tmp_path / "seeded.yaml", Model(
        model.parameter_names, theta, np.zeros(model.n_params), np.eye(6) * 20.0 + M_A,
        damping=model, M_A=M_A))
    return load_model(path)


def flat_layout(text: str) -> str:
    """The URDF block exported in its nested layout, rewritten in the flat layout of April
    2025 (``<linear_damping>``, ``<quadratic_damping>`` straight in the block)."""
    block = ET.fromstring(text)
    lin, quad = block.find("damping/linear"), block.find("damping/quadratic")
    assert lin is not None and quad is not None
    flat = ET.Element("hydrodynamics")
    ET.SubElement(flat, "linear_damping", lin.attrib)
    ET.SubElement(flat, "quadratic_damping", quad.attrib)
    return f"<robot>{ET.tostring(flat, encoding='unicode')}</robot>"


def export_import(mf: Model, case: str) -> tuple[Imported, tuple[str, ...]]:
    """Export ``mf`` for ``case`` and import the text back; the export's left-out lines."""
    fmt = case.split("-")[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExportWarning)
        out = export_model(mf, fmt, frame="frd" if case == "gz-frd" else "flu")
    text = flat_layout(out.text) if case == "urdf-flat" else out.text
    assert detect_format(text) == fmt
    return import_model(text, frame="frd" if case == "gz-frd" else "flu"), out.left_out


#: Per case, the names of the seeded model a format cannot carry.
LEFT_OUT = {
    "gz-flu": set(), "gz-frd": set(),
    "urdf-nested": {"X_w", "Y_r", "N_v", "K_v", "Y_vr", "X_uw", "Z_wu", "Y_ru", "N_vu"},
    "uuv": {"Y_vr", "X_uw"},
}
LEFT_OUT["urdf-flat"] = LEFT_OUT["urdf-nested"]


@pytest.mark.parametrize("case", ["gz-flu", "gz-frd", "urdf-nested", "urdf-flat", "uuv"])
def test_every_coefficient_comes_back_or_is_listed_as_left_out(seeded: Model,
                                                               case: str) -> None:
    back, left_out = export_import(seeded, case)
    got = dict(zip(back.names, back.theta, strict=True))
    left = {line.split(" =")[0] for line in left_out if " = " in line.split(" (")[0]}
    assert left == LEFT_OUT[case]
    assert set(got) | left == set(seeded.parameter_names) and not set(got) & left
    for name, value in zip(seeded.parameter_names, seeded.theta, strict=True):
        if name not in left:
            assert got[name] == pytest.approx(value, rel=1e-12, abs=1e-12), name
    # the damping force of what came back is the model's, but for the terms left out
    assert seeded.damping is not None
    nu = np.random.default_rng(5).normal(size=(40, 6))
    kept = np.array([0.0 if n in left else v for n, v in
                     zip(seeded.parameter_names, seeded.theta, strict=True)])
    np.testing.assert_allclose(back.damping().force(nu, back.theta),
                               seeded.damping.force(nu, kept), rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("case", ["gz-flu", "gz-frd", "uuv"])
def test_added_mass_comes_back(seeded: Model, case: str) -> None:
    back, _ = export_import(seeded, case)
    assert back.added_mass is not None and seeded.M_A is not None
    np.testing.assert_allclose(back.added_mass, seeded.M_A, rtol=0, atol=1e-12)


def test_urdf_without_the_vehicle_lists_the_added_mass_as_left_out(seeded: Model) -> None:
    back, left_out = export_import(seeded, "urdf-nested")
    assert back.added_mass is None
    assert [x for x in left_out if x.startswith("the added mass model.M_A")]


def test_uuv_centre_of_buoyancy_comes_back_in_frd_and_the_vehicle_values_are_stated(
        seeded: Model) -> None:
    from dampest_ros.io.yaml_io import load_vehicle
    heavy = load_vehicle("bluerov2_heavy")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExportWarning)
        text = export_model(seeded, "uuv", heavy, link_name="rov/base_link").text
    assert "<center_of_buoyancy>0 0 0.01</center_of_buoyancy>" in text   # FLU: up is +z
    back = import_uuv(text, link_name="rov/base_link")
    stated = next(n for n in back.notes if "vehicle's" in n)
    assert "volume 0.0134 m^3" in stated and "r_b = [0, 0, -0.01] m (FRD)" in stated
    assert "fluid density 1000.0 kg/m^3" in stated
    assert back.notes[-1] == "Read from link 'rov/base_link' (HMFossen, FRD)."


UUV_LINK = ('<plugin name="uuv_plugin" filename="libuuv_underwater_object_ros_plugin.so">'
            '<link name="{name}"><hydrodynamic_model>{model}</hydrodynamic_model></link>'
            "</plugin>")
FOSSEN = ("<type>fossen</type><linear_damping>-1 -2 -3 -4 -5 -6</linear_damping>"
          "<quadratic_damping>-10 -20 -30 -40 -50 -60</quadratic_damping>")


def test_uuv_six_numbers_are_the_diagonal_and_other_tags_are_noted() -> None:
    imp = import_uuv(UUV_LINK.format(name="a", model=FOSSEN
                                     + "<scaling_damping>2</scaling_damping>"))
    assert dict(zip(imp.names, imp.theta, strict=True)) == {
        "X_u": 1.0, "Y_v": 2.0, "Z_w": 3.0, "K_p": 4.0, "M_q": 5.0, "N_r": 6.0,
        "X_uu": 10.0, "Y_vv": 20.0, "Z_ww": 30.0, "K_pp": 40.0, "M_qq": 50.0, "N_rr": 60.0}
    assert imp.added_mass is None
    assert any(n.startswith("<scaling_damping> 2 ignored") for n in imp.notes)
    quad = " ".join("-7" if i % 7 == 0 else ("-1" if i == 1 else "0") for i in range(36))
    imp = import_uuv(UUV_LINK.format(name="a", model="<type>fossen</type><quadratic_damping>"
                                     f"{quad}</quadratic_damping>"))
    assert imp.theta.tolist() == [7.0] * 6
    assert any("off-diagonal <quadratic_damping> entries ignored" in n for n in imp.notes)


@pytest.mark.parametrize(("text", "match"), [
    (UUV_LINK.format(name="a", model="<type>fossen</type><linear_damping>1 2 3 4 5"
                                     "</linear_damping>"),
     r"<linear_damping>: needs 6 or 36 numbers \(HMFossen\), got 5"),
    (UUV_LINK.format(name="a", model="<type>fossen</type><added_mass>1 2 3 4 5 6"
                                     "</added_mass><linear_damping>1 2 3 4 5 6"
                                     "</linear_damping>"),
     r"<added_mass>: needs 36 numbers \(HMFossen\), got 6"),
    (UUV_LINK.format(name="a", model="<type>fossen</type><linear_damping>-1 -2 ${z} -4 -5 -6"
                                     "</linear_damping>"),
     r"<linear_damping>: not a number: '\$\{z\}'.*xacro"),
    (UUV_LINK.format(name="a", model="<type>sphere</type><radius>0.3</radius>"),
     r"type 'sphere': only type fossen holds coefficients"),
    (UUV_LINK.format(name="a", model="<type>fossen</type>"), "no damping coefficient found"),
    (UUV_LINK.format(name="a", model=FOSSEN) + UUV_LINK.format(name="b", model=FOSSEN),
     r"2 links with a <hydrodynamic_model> \(\['a', 'b'\]\); choose one with --link-name"),
    ("<sdf><model name='m'/></sdf>", "no UUV Simulator <hydrodynamic_model>"),
])
def test_uuv_malformed_or_foreign_is_refused_naming_what(text: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        import_uuv(f"<sdf>{text}</sdf>" if text.startswith("<plugin") else text)


def test_two_links_are_told_apart_by_name() -> None:
    both = "<sdf>" + UUV_LINK.format(name="a", model=FOSSEN) + UUV_LINK.format(
        name="b", model=FOSSEN.replace("-1 -2", "-9 -2")) + "</sdf>"
    assert import_uuv(both, link_name="b").theta[0] == 9.0
    with pytest.raises(ConfigError, match="for link 'c'"):
        import_uuv(both, link_name="c")


def test_format_detection_refuses_foreign_and_ambiguous_files() -> None:
    with pytest.raises(ConfigError, match="holds no hydrodynamics dampest can import"):
        detect_format("<robot><link name='a'/></robot>")
    both = ("<robot><hydrodynamics><linear_damping Xu='-1'/></hydrodynamics><gazebo>"
            "<plugin filename='gz-sim-hydrodynamics-system' name='h'><link_name>a</link_name>"
            "<xU>-1</xU></plugin></gazebo></robot>")
    with pytest.raises(ConfigError, match="choose one with --format gz or --format urdf"):
        detect_format(both)
    assert import_model(both, "urdf").theta.tolist() == [1.0]
