"""Export to gz-sim / URDF <hydrodynamics> / UUV Simulator and import back (dampest_ros.io.export).

The force laws of the targets are re-implemented here from their sources (gz-sim
HydrodynamicsUtils.hh buildDampingMatrix, RDML hydrodynamics.cpp, UUV Simulator
HydrodynamicModel.cc) and evaluated on the exported numbers, so the tests check the physics of
the conversion (signs and frame), not only that export and import agree with each other.
"""

from __future__ import annotations

import re
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from dampest_ros.cli.main import main
from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.vehicle import Vehicle, damping_from_spec
from dampest_ros.io.export.common import ExportWarning, NotDissipativeError, imported_mass
from dampest_ros.io.export.convert import export_model, import_model
from dampest_ros.io.export.gz import export_gz, import_gz
from dampest_ros.io.export.urdf import export_urdf, import_urdf
from dampest_ros.io.export.uuv import export_uuv
from dampest_ros.io.yaml_io import load_model, load_vehicle, save_model

T6 = np.array([1.0, -1.0, -1.0, 1.0, -1.0, -1.0])  # FRD <-> FLU for a 6-vector
GZ_F, GZ_V = "xyzkmn", "UVWPQR"


def model_file(tmp_path: Path, spec: dict[str, Any], M: np.ndarray | None = None,
               name: str = "model.yaml") -> Model:
    """A model file on disk (with model.terms) from a damping spec, read back."""
    model, theta = damping_from_spec(spec)
    path = save_model(tmp_path / name, Model(model.parameter_names, theta, np.zeros(model.n_params),
                                             np.eye(6) * 20.0 if M is None else M, damping=model))
    return load_model(path)


@pytest.fixture
def heavy() -> Vehicle:
    return load_vehicle("bluerov2_heavy")


@pytest.fixture
def heavy_file(tmp_path: Path, heavy: Vehicle) -> Model:
    path = save_model(tmp_path / "heavy.yaml", Model(heavy.damping.parameter_names, heavy.theta,
                                                     np.zeros(heavy.damping.n_params), heavy.body.M,
                                                     damping=heavy.damping))
    return load_model(path)


#: Every kind of coefficient the gz plugin can hold, with couplings that flip in FLU
#: (X_w, K_v, Y_u) and couplings that do not (Y_r, N_v).
COUPLED: dict[str, Any] = {
    "linear": {"X_u": 13.7, "Y_v": 4.0, "Z_w": 33.0, "K_p": 0.3, "M_q": 0.8, "N_r": 0.5,
               "X_w": 2.0, "Y_r": 1.5, "N_v": -0.7, "K_v": 0.25, "Y_u": 0.4},
    "quadratic": {"X_uu": 141.0, "Y_vv": 217.0, "Z_ww": 190.0, "K_pp": 1.19, "M_qq": 0.47,
                  "N_rr": 1.5},
    "cross": [{"row": "Y", "col": "v", "alpha": "|r|", "value": 3.0},       # Y_vr
              {"row": "N", "col": "v", "alpha": "|r|", "value": -1.25},     # N_vr
              {"row": "X", "col": "u", "alpha": "|w|", "value": 5.5},       # X_uw
              {"row": "Z", "col": "w", "alpha": "u", "value": 7.0},         # Z_wu (signed)
              {"row": "Y", "col": "r", "alpha": "u", "value": -2.5}],       # Y_ru (signed)
}


def tags(text: str) -> dict[str, float]:
    """Coefficient tags of the (only) Hydrodynamics plugin in ``text``."""
    plugin = ET.fromstring(text)        # the header comment precedes the root element
    return {e.tag: float(e.text or "") for e in plugin if e.tag != "link_name"}


def gz_applied(t: dict[str, float], nu: np.ndarray) -> np.ndarray:
    """The damping wrench gz-sim applies to the link for link-frame velocities ``nu``.

    HydrodynamicsUtils.hh: D(i,j) = -(lin[ij] + Σ_k quadAbs[ijk]|ν_k| + quad[ijk] ν_k) and
    Hydrodynamics.cc applies -D ν.
    """
    D = np.zeros((len(nu), 6, 6))
    for tag, value in t.items():
        m = re.fullmatch(r"([xyzkmn])([UVWPQR])(abs)?([UVWPQR])?", tag)
        if m is None:
            continue
        i, j = GZ_F.index(m.group(1)), GZ_V.index(m.group(2))
        if m.group(4) is None:
            D[:, i, j] -= value
        else:
            k = GZ_V.index(m.group(4))
            D[:, i, j] -= value * (np.abs(nu[:, k]) if m.group(3) else nu[:, k])
    return -np.einsum("nij,nj->ni", D, nu)


def random_nu(n: int = 50) -> np.ndarray:
    return np.random.default_rng(7).normal(scale=[1.0, 0.8, 0.6, 0.5, 0.5, 0.7], size=(n, 6))


# --- gz ---------------------------------------------------------------------------------------


def test_gz_bluerov2_heavy_tags_are_sname_negative(heavy_file: Model,
                                                   heavy: Vehicle) -> None:
    out = export_gz(heavy_file, heavy)
    assert out.text.count("<plugin") == 1
    assert '<plugin filename="gz-sim-hydrodynamics-system" ' \
           'name="gz::sim::systems::Hydrodynamics">' in out.text
    assert "<link_name>base_link</link_name>" in out.text
    assert "<xU>-13.7</xU>" in out.text
    t = tags(out.text)
    assert t["xUabsU"] == -141.0
    assert t["yVabsV"] == -217.0 and t["zWabsW"] == -190.0 and t["nRabsR"] == -1.5
    assert t["zW"] == -33.0 and t["mQ"] == -0.8 and t["yV"] == 0.0
    # added mass: X_udot = -M_A (BlueROV2 Heavy, von Benzon et al. 2022)
    assert "<xDotU>-6.36</xDotU>" in out.text
    assert [t[f"{f}Dot{v}"] for f, v in zip(GZ_F, GZ_V, strict=True)] == \
        [-6.36, -7.12, -18.68, -0.189, -0.135, -0.222]
    assert out.left_out == ()


def test_gz_frame_conversion_small_example(tmp_path: Path) -> None:
    # FRD -> FLU negates v, w, q, r (and Y, Z, M, N): X_w couples x with z -> flips;
    # Y_r couples y with the yaw rate r, both negated -> keeps its sign; |r| never flips.
    mf = model_file(tmp_path, {"linear": {"X_u": 1.0, "X_w": 2.0, "Y_r": 1.5, "K_v": 0.25},
                               "cross": [{"row": "Y", "col": "v", "alpha": "|r|",
                                          "value": 3.0},
                                         {"row": "Y", "col": "r", "alpha": "u",
                                          "value": -2.5}]})
    # couplings without the diagonal terms that would make them dissipative: force
    flu = tags(export_gz(mf, force=True).text)
    frd = tags(export_gz(mf, frame="frd", force=True).text)
    assert flu["xU"] == frd["xU"] == -1.0
    assert frd["xW"] == -2.0 and flu["xW"] == 2.0
    assert frd["kV"] == -0.25 and flu["kV"] == 0.25
    assert flu["yR"] == frd["yR"] == -1.5
    assert flu["yVabsR"] == frd["yVabsR"] == -3.0
    # Y += c·r·u: t_Y t_r t_u = (−1)(−1)(+1) → no flip
    assert flu["yRU"] == frd["yRU"] == 2.5


@pytest.mark.parametrize("frame", ["flu", "frd"])
def test_gz_force_law_reproduces_the_model(tmp_path: Path, frame: str) -> None:
    spec = {**COUPLED, "added": {"added.K_vw": 0.3, "added.M_uw": -1.1, "added.N_uv": 0.9}}
    mf = model_file(tmp_path, spec)
    assert mf.damping is not None
    nu = random_nu()
    applied_frd = -mf.damping.force(nu, mf.theta)           # τ side: -D(ν)ν
    t = tags(export_gz(mf, frame=frame).text)
    if frame == "flu":
        np.testing.assert_allclose(gz_applied(t, nu * T6), applied_frd * T6, rtol=1e-12,
                                   atol=1e-12)
    else:
        np.testing.assert_allclose(gz_applied(t, nu), applied_frd, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("frame", ["flu", "frd"])
def test_gz_round_trip_gives_the_same_parameters(tmp_path: Path, frame: str) -> None:
    mf = model_file(tmp_path, COUPLED)
    back = import_gz(export_gz(mf, frame=frame).text, frame=frame)
    got = dict(zip(back.names, back.theta, strict=True))
    # Y_vr (|r|) and the diagonal terms come back under their own names; the signed
    # products under Y_ru / Z_wu (the default labels).
    assert set(got) == set(mf.parameter_names)
    for name, value in zip(mf.parameter_names, mf.theta, strict=True):
        assert got[name] == pytest.approx(value, abs=1e-12, rel=1e-12), name
    model = back.damping()
    nu = random_nu()
    assert mf.damping is not None
    np.testing.assert_allclose(model.force(nu, back.theta), mf.damping.force(nu, mf.theta),
                               rtol=1e-12, atol=1e-12)


def test_gz_added_mass_round_trip_with_couplings(tmp_path: Path, heavy: Vehicle) -> None:
    M_A = np.diag([6.36, 7.12, 18.68, 0.189, 0.135, 0.222])
    M_A[0, 4] = M_A[4, 0] = 0.4     # surge–pitch: flips in FLU
    M_A[1, 5] = M_A[5, 1] = 0.3     # sway–yaw: keeps its sign
    d = yaml.safe_load(Path("config/vehicles/bluerov2_heavy.yaml").read_text())
    d["vehicle"]["added_mass"] = M_A.tolist()
    vehicle = Vehicle.from_dict(d)
    mf = model_file(tmp_path, {"linear": {"X_u": 13.7}}, M=vehicle.body.M)
    with pytest.warns(ExportWarning, match="diagonal of M_A only"):
        out = export_gz(mf, vehicle)
    # gz-sim's C_A(ν)ν uses the diagonal of M_A: the couplings act in M_A ν̇ only
    assert [x for x in out.left_out if "off-diagonal M_A" in x]
    t = tags(out.text)
    assert t["xDotQ"] == 0.4 and t["mDotU"] == 0.4
    assert t["yDotR"] == -0.3 and t["nDotV"] == -0.3
    back = import_gz(out.text)
    assert back.added_mass is not None
    np.testing.assert_allclose(back.added_mass, M_A, atol=1e-12)
    M, _ = imported_mass(back, vehicle)
    np.testing.assert_allclose(M, vehicle.body.M, atol=1e-12)


def test_gz_without_vehicle_exports_damping_only_and_says_so(heavy_file: Model) -> None:
    out = export_gz(heavy_file)
    assert "Dot" not in "".join(tags(out.text))
    assert any("Added mass not exported" in n for n in out.notes)
    assert "Added mass not exported" in out.text
    back = import_gz(out.text)
    assert back.added_mass is None and back.rigid_body is None
    with pytest.raises(ConfigError, match="vehicle"):
        imported_mass(back, None)


def test_gz_import_from_an_sdf_with_a_blue_style_plugin(tmp_path: Path) -> None:
    # the layout of the blue project's gazebo.xacro (after xacro), inside a model
    sdf = tmp_path / "model.sdf"
    sdf.write_text("""<?xml version="1.0"?>
<sdf version="1.9"><model name="bluerov2_heavy">
  <plugin filename="gz-sim-thruster-system" name="gz::sim::systems::Thruster"/>
  <plugin filename="gz-sim-hydrodynamics-system" name="gz::sim::systems::Hydrodynamics">
    <link_name>base_footprint</link_name>
    <xDotU>0</xDotU><yDotV>0</yDotV><zDotW>0</zDotW>
    <kDotP>0</kDotP><mDotQ>0</mDotQ><nDotR>0</nDotR>
    <xU>0</xU><yV>0</yV><zW>0</zW><kP>0</kP><mQ>0</mQ><nR>0</nR>
    <xUabsU>-58.42</xUabsU><yVabsV>-55.137</yVabsV><zWabsW>-124.818</zWabsW>
    <kPabsP>-4.0</kPabsP><mQabsQ>-4.0</mQabsQ><nRabsR>-4.0</nRabsR>
    <water_density>1000</water_density>
  </plugin>
</model></sdf>""")
    imp = import_model(sdf, "gz")
    got = dict(zip(imp.names, imp.theta, strict=True))
    assert got["X_uu"] == 58.42 and got["Z_ww"] == 124.818 and got["N_rr"] == 4.0
    assert got["X_u"] == 0.0 and len(got) == 12
    assert imp.added_mass is not None and not imp.added_mass.any()
    assert "base_footprint" in imp.notes[-1]


def test_gz_import_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="no gz-sim Hydrodynamics"):
        import_gz("<sdf><model/></sdf>")
    with pytest.raises(ConfigError, match=r"<xU>.*not a number.*xacro"):
        import_gz('<plugin filename="gz-sim-hydrodynamics-system" name="x">'
                  "<link_name>a</link_name><xU>${xu}</xU></plugin>")
    two = ('<m><plugin filename="gz-sim-hydrodynamics-system"><link_name>a</link_name>'
           '<xU>-1</xU></plugin><plugin filename="gz-sim-hydrodynamics-system">'
           "<link_name>b</link_name><xU>-2</xU></plugin></m>")
    with pytest.raises(ConfigError, match="2 Hydrodynamics plugins"):
        import_gz(two)
    assert import_gz(two, link_name="b").theta.tolist() == [2.0]
    with pytest.raises(ConfigError, match="not valid XML"):
        import_gz("<plugin>")
    with pytest.raises(FileNotFoundError):
        import_gz(tmp_path / "missing.sdf")
    with pytest.raises(ValueError, match="unknown frame"):
        import_gz(two, frame="enu", link_name="a")


def test_gz_signed_diagonal_product_is_read_as_signed_with_a_note() -> None:
    imp = import_gz('<plugin filename="gz-sim-hydrodynamics-system"><link_name>a</link_name>'
                    "<xUabsU>-10</xUabsU><xUU>-3</xUU></plugin>")
    got = dict(zip(imp.names, imp.theta, strict=True))
    assert got == {"X_uu": 10.0, "X_uu_lin": 3.0}
    assert any("<xUabsU>" in n for n in imp.notes)


# --- urdf -------------------------------------------------------------------------------------


def urdf_block(text: str) -> ET.Element:
    return ET.fromstring(text)


def test_urdf_bluerov2_heavy_block(heavy_file: Model, heavy: Vehicle) -> None:
    out = export_urdf(heavy_file, heavy)
    block = urdf_block(out.text)
    lin, quad = block.find("damping/linear"), block.find("damping/quadratic")
    am = block.find("inertial/added_mass")
    assert lin is not None and quad is not None and am is not None
    assert lin.get("Xu") == "-13.7" and float(lin.get("Zw", "")) == -33.0
    assert float(quad.get("Xuu", "")) == -141.0 and float(quad.get("Nrr", "")) == -1.5
    assert am.get("Xdu") == "-6.36" and am.get("Ndr") == "-0.222"
    mass, weight = block.find("inertial/mass"), block.find("hydrostatics/weight")
    buoyancy = block.find("hydrostatics/buoyancy")
    assert mass is not None and weight is not None and buoyancy is not None
    assert mass.get("value") == "13.5"
    assert float(weight.get("value", "")) == pytest.approx(13.5 * 9.81)
    assert float(buoyancy.get("value", "")) == pytest.approx(1000 * 9.81 * 0.0134)
    assert block.find("linear_damping") is None     # not the flat layout of April 2025
    cob = block.find("hydrostatics/center_of_buoyancy")
    assert cob is not None and cob.get("z") == "-0.01"      # FRD: above the origin
    assert out.left_out == ()


def test_urdf_round_trip_and_force_law(heavy_file: Model, heavy: Vehicle) -> None:
    out = export_urdf(heavy_file, heavy)
    back = import_urdf(out.text)
    assert back.names == heavy_file.parameter_names
    np.testing.assert_allclose(back.theta, heavy_file.theta, rtol=1e-12, atol=1e-12)
    assert back.added_mass is not None and back.rigid_body is not None
    np.testing.assert_allclose(back.added_mass, heavy.body.added_mass, atol=1e-12)
    np.testing.assert_allclose(back.rigid_body, heavy.body.M_RB, atol=1e-12)
    M, _ = imported_mass(back, None)
    np.testing.assert_allclose(M, heavy.body.M, atol=1e-12)
    # hydrodynamics.cpp: D(ν) = -diag(linear) - diag(quadratic ⊙ |ν|), on the left-hand side
    block = urdf_block(out.text)
    lin_el, quad_el = block.find("damping/linear"), block.find("damping/quadratic")
    assert lin_el is not None and quad_el is not None
    lin = np.array([float(lin_el.get(k, "")) for k in ("Xu", "Yv", "Zw", "Kp", "Mq", "Nr")])
    quad = np.array([float(quad_el.get(k, "")) for k in ("Xuu", "Yvv", "Zww", "Kpp", "Mqq",
                                                           "Nrr")])
    nu = random_nu()
    lhs = (-lin - quad * np.abs(nu)) * nu
    assert heavy_file.damping is not None
    np.testing.assert_allclose(lhs, heavy_file.damping.force(nu, heavy_file.theta),
                               rtol=1e-12, atol=1e-12)


def test_urdf_lists_what_the_block_cannot_hold(tmp_path: Path) -> None:
    mf = model_file(tmp_path, {**COUPLED, "freq": [{"dof": "u", "rate": 2.0, "c": 5.0}]})
    with pytest.warns(ExportWarning, match="left out"):
        out = export_urdf(mf)
    left = "\n".join(out.left_out)
    for name in ("X_w", "Y_r", "Y_vr", "N_vr", "Z_wu", "freq.u.c1"):
        assert name in left, name
    assert "LEFT OUT" in out.text and "Y_vr" in out.text.split("-->")[0]
    back = import_urdf(out.text)          # the diagonal terms still round-trip
    got = dict(zip(back.names, back.theta, strict=True))
    for name in ("X_u", "N_r", "X_uu", "N_rr"):
        assert got[name] == pytest.approx(dict(zip(mf.parameter_names, mf.theta,
                                                   strict=True))[name], abs=1e-12)


def test_urdf_import_reads_the_flat_layout_of_april_2025(heavy_file: Model) -> None:
    flat = ("<robot><hydrodynamics><mass>13.5</mass><inertia ixx='0.26' iyy='0.23' izz='0.37'/>"
            "<added_mass Xdu='-6.36' Ydv='-7.12' Zdw='-18.68' Kdp='-0.189' Mdq='-0.135' "
            "Ndr='-0.222'/><linear_damping Xu='-13.7' Yv='0' Zw='-33' Kp='0' Mq='-0.8' "
            "Nr='0'/><quadratic_damping Xuu='-141' Yvv='-217' Zww='-190' Kpp='-1.19' "
            "Mqq='-0.47' Nrr='-1.5'/></hydrodynamics></robot>")
    imp = import_urdf(flat)
    assert imp.names == heavy_file.parameter_names
    np.testing.assert_allclose(imp.theta, heavy_file.theta, atol=1e-12)
    assert imp.rigid_body is not None and imp.rigid_body[0, 0] == 13.5


def test_urdf_import_of_the_nested_auv_controllers_layout_and_of_text() -> None:
    nested = """<robot><hydrodynamics>
      <inertial><mass value="16.61"/><inertia ixx="0.24" iyy="0.2" izz="0.4"/>
        <center_of_gravity x="0.0" y="0.0" z="0.0"/>
        <added_mass Xdu="-12.7" Ydv="-10.5" Zdw="-14.57" Kdp="-0.12" Mdq="-0.12" Ndr="-0.12"/>
      </inertial>
      <damping><linear Xu="-28.23" Yv="-18.29" Zw="-23.51" Kp="-0.31" Mq="-0.31" Nr="-0.31"/>
        <quadratic Xuu="-93.47" Yvv="-74.28" Zww="-168.17" Kpp="-1.55" Mqq="-1.55" Nrr="-1.55"/>
      </damping></hydrodynamics></robot>"""
    imp = import_urdf(nested)
    got = dict(zip(imp.names, imp.theta, strict=True))
    assert got["X_u"] == 28.23 and got["Z_ww"] == 168.17 and got["N_rr"] == 1.55
    assert imp.added_mass is not None and imp.rigid_body is not None
    np.testing.assert_allclose(np.diag(imp.added_mass), [12.7, 10.5, 14.57, 0.12, 0.12, 0.12])
    np.testing.assert_allclose(np.diag(imp.rigid_body), [16.61] * 3 + [0.24, 0.2, 0.4])
    text = ("<hydrodynamics><linear_damping>-4.03 -6.22 -5.18 -0.07 -0.07 -0.07"
            "</linear_damping><quadratic_damping>-18.18 -21.66 -36.99 -1.55 -1.55 -1.55"
            "</quadratic_damping></hydrodynamics>")
    imp = import_urdf(text)
    assert imp.theta.tolist() == [4.03, 6.22, 5.18, 0.07, 0.07, 0.07,
                                  18.18, 21.66, 36.99, 1.55, 1.55, 1.55]
    with pytest.raises(ConfigError, match="6 or 36"):
        import_urdf("<hydrodynamics><linear_damping>1 2 3</linear_damping></hydrodynamics>")
    with pytest.raises(ConfigError, match="no <hydrodynamics>"):
        import_urdf("<robot/>")
    with pytest.raises(ConfigError, match="no damping coefficient"):
        import_urdf("<hydrodynamics><mass>1</mass></hydrodynamics>")


# --- uuv --------------------------------------------------------------------------------------


def uuv_plugin(text: str) -> ET.Element:
    """The exported <plugin> element (after its header comment), as the plugin parses it."""
    return ET.fromstring(text)


def uuv_matrix(hm: ET.Element, tag: str) -> np.ndarray:
    """A HMFossen matrix as HydrodynamicModel.cc reads it: 36 numbers row-major, or 6 for the
    diagonal."""
    values = [float(x) for x in (hm.findtext(tag) or "").split()]
    assert len(values) in (6, 36), (tag, len(values))
    return np.diag(values) if len(values) == 6 else np.array(values).reshape(6, 6)


def test_uuv_sdf_plugin_numbers_and_force_law(tmp_path: Path, heavy: Vehicle) -> None:
    spec = {"linear": COUPLED["linear"], "quadratic": COUPLED["quadratic"],
            "cross": [c for c in COUPLED["cross"] if c["alpha"] == "u"]}
    mf = model_file(tmp_path, spec, M=heavy.body.M)
    out = export_uuv(mf, heavy, link_name="bluerov2/base_link")
    plugin = uuv_plugin(out.text)
    assert plugin.tag == "plugin"
    assert plugin.get("filename") == "libuuv_underwater_object_ros_plugin.so"
    assert float(plugin.findtext("fluid_density") or "nan") == heavy.body.rho
    link = plugin.find("link")
    assert link is not None and link.get("name") == "bluerov2/base_link"
    assert float(link.findtext("volume") or "nan") == heavy.body.volume
    cob = [float(x) for x in (link.findtext("center_of_buoyancy") or "").split()]
    np.testing.assert_allclose(cob, heavy.body.r_b * T6[:3], atol=0)  # FRD -> FLU
    hm = link.find("hydrodynamic_model")
    assert hm is not None and hm.findtext("type") == "fossen"
    DLin, DNon, DFwd, Ma = (uuv_matrix(hm, k) for k in (
        "linear_damping", "quadratic_damping", "linear_damping_forward_speed", "added_mass"))
    assert DLin[0, 0] == -13.7 and DNon[0, 0] == -141.0 and DLin[0, 2] == -2.0  # FRD, as is
    np.testing.assert_allclose(Ma, heavy.body.added_mass, atol=1e-12)          # positive
    # every number is the model's: −(coefficient) at its place
    assert mf.damping is not None
    for name, value in zip(mf.parameter_names, mf.theta, strict=True):
        row = "XYZKMN".index(name[0])
        col = "uvwpqr".index(name[2])
        if len(name) == 3:
            assert DLin[row, col] == -value, name
        elif name[3] == name[2] and row == col:
            assert DNon[row, row] == -value, name
        else:
            assert DFwd[row, col] == -value, name
    # HMFossen: D = -DLin - u DFwd, D_ii += -DNon_ii |ν_i|; applied -D ν
    nu = random_nu()
    D = -DLin - nu[:, 0, None, None] * DFwd
    D[:, range(6), range(6)] -= np.diag(DNon) * np.abs(nu)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", D, nu), mf.damping.force(nu, mf.theta),
                               rtol=1e-12, atol=1e-12)
    assert out.left_out == ()


def test_uuv_leaves_out_cross_quadratic_terms(tmp_path: Path) -> None:
    mf = model_file(tmp_path, COUPLED)
    with pytest.warns(ExportWarning):
        out = export_uuv(mf)
    assert [x.split(" =")[0] for x in out.left_out] == ["Y_vr", "N_vr", "X_uw"]
    link = uuv_plugin(out.text).find("link")
    assert link is not None and link.find("volume") is None  # no vehicle: damping only
    hm = link.find("hydrodynamic_model")
    assert hm is not None and hm.find("added_mass") is None
    assert "LEFT OUT" in out.text and "Y_vr" in out.text


def test_uuv_held_at_prior_is_an_xml_comment(tmp_path: Path, heavy: Vehicle) -> None:
    held = {"Y_vv": "held at prior 217 (no excitation)"}
    with pytest.warns(ExportWarning):
        out = export_uuv(load_model(heavy_with(tmp_path, heavy, {}, held=held, flown=1.0)))
    comment = out.text[out.text.index("<!--"):out.text.index("-->")]
    assert "Y_vv = 217.0: held at prior" in comment and "X_uu = 141.0: estimate" in comment
    hm = uuv_plugin(out.text).find("link/hydrodynamic_model")
    assert hm is not None and uuv_matrix(hm, "quadratic_damping")[1, 1] == -217.0


# --- common -----------------------------------------------------------------------------------


def test_memory_and_residual_are_listed_never_dropped(tmp_path: Path) -> None:
    mf = model_file(tmp_path, {"linear": {"X_u": 1.0},
                               "freq": [{"dof": "u", "rate": 2.0, "c": 5.0}],
                               "residual": {"values": [0.5, 0.25]}})
    for fmt in ("gz", "urdf", "uuv"):
        with pytest.warns(ExportWarning, match="freq.u.c1"):
            out = export_model(mf, fmt)
        names = [x.split(" =")[0] for x in out.left_out]
        assert names == ["freq.u.c1", "residual.s1", "residual.s2"], fmt
        assert "fluid memory" in out.left_out[0]
        for name in names:
            assert name in out.text, (fmt, name)


def test_element_drags_are_listed_as_left_out(tmp_path: Path) -> None:
    """No format has a drag at a point on its own velocity: without flown speeds to refold
    it over, each is listed, with its value, in the file and the result, in every format,
    and the file says why it was not refolded; the rest is written."""
    mf = model_file(tmp_path, {"quadratic": {"X_uu": 40.0},
                               "point": [{"position": [0.3, 0.0, 0.2], "axis": "w",
                                          "value": 12.0}]})
    for fmt in ("gz", "urdf", "uuv"):
        with pytest.warns(ExportWarning, match=r"drag\.w\|U\|@\(0\.3,0,0\.2\)"):
            out = export_model(mf, fmt)
        assert [x.split(" =")[0] for x in out.left_out] == ["drag.w|U|@(0.3,0,0.2)"], fmt
        assert "= 12.0 (the drag of an element at a point" in out.left_out[0]
        assert "drag.w|U|@(0.3,0,0.2)" in out.text, fmt
        assert "Not refolded: the model file records no flown speeds" in out.text, fmt


def test_unknown_format_and_frame(heavy_file: Model) -> None:
    with pytest.raises(ValueError, match=r"unknown export format 'sdf'.*gz.*urdf.*uuv"):
        export_model(heavy_file, "sdf")
    with pytest.raises(ValueError, match="unknown frame"):
        export_gz(heavy_file, frame="enu")
    with pytest.raises(ValueError, match="unknown import format 'sdf'"):
        import_model("<a/>", "sdf")


def test_wrong_vehicle_warns_about_negative_added_mass(heavy_file: Model) -> None:
    with pytest.warns(ExportWarning, match="negative diagonal"):
        out = export_gz(heavy_file, load_vehicle("platform_b"))
    assert any("negative diagonal" in n for n in out.notes)


def test_model_file_without_terms_is_read_from_the_names(tmp_path: Path) -> None:
    path = save_model(tmp_path / "old.yaml", Model(["X_u", "Y_r", "X_uu", "Y_vr"],
                                                   np.array([13.7, 1.5, 141.0, 3.0]), np.zeros(4),
                                                   np.eye(6)))
    mf = load_model(path)
    assert mf.damping is None
    with pytest.warns(ExportWarning, match="Y_vr"):
        out = export_gz(mf, force=True)  # Y_r without Y_v: not dissipative
    t = tags(out.text)
    assert t == {"xU": -13.7, "yR": -1.5, "xUabsU": -141.0}
    assert out.left_out[0].startswith("Y_vr = 3.0 (the model file has no model.terms")


# --- command line -----------------------------------------------------------------------------


def cli(argv: list[str]) -> int:
    """dampest with --debug: a failure raises instead of exiting 2."""
    return main(["--debug", *argv])


def test_cli_export_then_import(tmp_path: Path, heavy_file: Model,
                                capsys: pytest.CaptureFixture[str]) -> None:
    src = tmp_path / "heavy.yaml"
    sdf = tmp_path / "hydro.sdf"
    assert cli(["export", str(src), "--format", "gz", "--vehicle", "bluerov2_heavy",
                "--out", str(sdf)]) == 0
    assert "<xU>-13.7</xU>" in sdf.read_text()
    out = tmp_path / "back.yaml"
    assert cli(["import", str(sdf), "--format", "gz", "--vehicle", "bluerov2_heavy",
                "--out", str(out)]) == 0
    back = load_model(out)
    assert back.parameter_names == heavy_file.parameter_names
    np.testing.assert_allclose(back.theta, heavy_file.theta, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(back.M, heavy_file.M, atol=1e-12)
    assert back.damping is not None and back.extra["source"].startswith("dampest import")
    capsys.readouterr()
    # stdout export, and the left-out list on stderr
    mf_path = tmp_path / "coupled.yaml"
    model_file(tmp_path, {"linear": {"X_u": 1.0}, "freq": [{"dof": "u", "rate": 2.0,
                                                            "c": 5.0}]}, name=mf_path.name)
    assert cli(["export", str(mf_path), "--format", "urdf"]) == 0
    captured = capsys.readouterr()
    assert captured.out.lstrip().startswith("<!--") and "<hydrodynamics>" in captured.out
    assert "warning: left out freq.u.c1" in captured.err
    assert "no --vehicle" in captured.err


def test_cli_import_urdf_without_rigid_body_needs_a_vehicle(tmp_path: Path) -> None:
    f = tmp_path / "block.urdf"
    f.write_text('<robot><hydrodynamics><linear_damping Xu="-1" Yv="-2" Zw="-3" Kp="0" '
                 'Mq="0" Nr="0"/></hydrodynamics></robot>')
    with pytest.raises(ConfigError, match="vehicle"):
        cli(["import", str(f), "--format", "urdf", "--out", str(tmp_path / "m.yaml")])
    assert cli(["import", str(f), "--format", "urdf", "--vehicle", "bluerov2_heavy",
                "--out", str(tmp_path / "m.yaml")]) == 0
    m = load_model(tmp_path / "m.yaml")
    assert m.theta.tolist() == [1.0, 2.0, 3.0, 0.0, 0.0, 0.0]
    np.testing.assert_allclose(m.M, load_vehicle("bluerov2_heavy").body.M)


# --- added-mass switches ----------------------------------------------------------------------


def switched_file(tmp_path: Path, heavy: Vehicle, **switches: Any) -> Path:
    """The heavy's model with model.M_A and the given added-mass switches."""
    from dampest_ros.core.physics.rigid_body import AddedMassTerms
    return save_model(tmp_path / "switched.yaml", Model(heavy.damping.parameter_names, heavy.theta,
                                                        np.zeros(heavy.damping.n_params),
                                                        heavy.body.M, damping=heavy.damping,
                                                        M_A=heavy.body.added_mass,
                                                        added_mass_terms=AddedMassTerms(**switches)))


def plugin_flags(text: str) -> dict[str, str]:
    plugin = ET.fromstring(text)
    return {e.tag: (e.text or "") for e in plugin if e.tag.startswith("disable_")}


@pytest.mark.parametrize(("switches", "flags", "munk_left_out"), [
    ({"inertial": False, "coriolis": True, "munk": True}, {"disable_added_mass": "true"}, False),
    ({"inertial": True, "coriolis": False, "munk": False}, {"disable_coriolis": "true"}, False),
    ({"inertial": False, "coriolis": False, "munk": False},
     {"disable_added_mass": "true", "disable_coriolis": "true"}, False),
    ({"inertial": True, "coriolis": True, "munk": False}, {}, True),
    ({"inertial": True, "coriolis": True, "munk": True}, {}, False),
    ({"inertial": True, "coriolis": True, "munk": True, "coriolis_zero": ((0, 4), (2, 4))}, {},
     True),
])
def test_gz_maps_the_added_mass_switches_and_reads_them_back(
        tmp_path: Path, heavy: Vehicle, switches: dict[str, bool], flags: dict[str, str],
        munk_left_out: bool) -> None:
    """inertial → <disable_added_mass>, coriolis → <disable_coriolis>; Munk moments or other
    single entries of C_A cannot be dropped in gz-sim (listed as left out); M_A comes from
    model.M_A without a vehicle; the import gives the switches and M_A back."""
    mf = load_model(switched_file(tmp_path, heavy, **switches))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExportWarning)
        ex = export_gz(mf)                                # no vehicle: M_A from the file
    assert plugin_flags(ex.text) == flags
    assert any("model.M_A" in n for n in ex.notes)
    assert ET.fromstring(ex.text).findtext("xDotU") == "-6.36"
    assert any("cannot zero entries" in x for x in ex.left_out) == munk_left_out
    assert not [x for x in ex.left_out if "off-diagonal M_A" in x]   # the heavy's is diagonal
    back = import_gz(ex.text)
    assert back.added_mass_terms == load_terms(inertial=switches["inertial"],
                                               coriolis=switches["coriolis"],
                                               munk=switches["coriolis"])
    assert back.added_mass is not None
    np.testing.assert_allclose(back.added_mass, heavy.body.added_mass, atol=1e-12)


def load_terms(**kw: bool) -> Any:
    from dampest_ros.core.physics.rigid_body import AddedMassTerms
    return AddedMassTerms(**kw)


@pytest.mark.parametrize("fmt", ["urdf", "uuv"])
def test_formats_without_switches_list_them_as_left_out(tmp_path: Path, heavy: Vehicle,
                                                        fmt: str) -> None:
    mf = load_model(switched_file(tmp_path, heavy, inertial=False, coriolis=True, munk=True))
    with pytest.warns(ExportWarning, match="added_mass_terms"):
        ex = export_model(mf, fmt, heavy)
    (line,) = [x for x in ex.left_out if x.startswith("added_mass_terms")]
    assert "no inertial effect" in line and "has no switches" in line
    assert "LEFT OUT" in ex.text and "added_mass_terms" in ex.text
    # a partial mask is named entry by entry, never dropped silently
    part = load_model(switched_file(tmp_path, heavy, coriolis_zero=((0, 4), (2, 4))))
    with pytest.warns(ExportWarning, match="added_mass_terms"):
        (line,) = [x for x in export_model(part, fmt, heavy).left_out if "added_mass" in x]
    assert "no C_A entries (X, q) (Z, q) effect" in line
    # all switches on: nothing to say
    on = load_model(switched_file(tmp_path, heavy, inertial=True, coriolis=True, munk=True))
    assert not [x for x in export_model(on, fmt, heavy).left_out if "added_mass_terms" in x]


def test_gz_bad_switch_value_is_refused() -> None:
    text = ('<plugin filename="gz-sim-hydrodynamics-system" name="gz::sim::systems::'
            'Hydrodynamics"><link_name>b</link_name><xU>-1</xU>'
            '<disable_coriolis>maybe</disable_coriolis></plugin>')
    with pytest.raises(ConfigError, match="<disable_coriolis>: must be true or false"):
        import_gz(text)


def test_cli_export_import_round_trip_keeps_m_a_and_switches(tmp_path: Path,
                                                             heavy: Vehicle) -> None:
    src = switched_file(tmp_path, heavy, inertial=False, coriolis=False, munk=False)
    sdf, out = tmp_path / "hydro.sdf", tmp_path / "back.yaml"
    assert cli(["export", str(src), "--format", "gz", "--out", str(sdf)]) == 0
    text = sdf.read_text()
    assert "<disable_added_mass>true</disable_added_mass>" in text
    assert "<disable_coriolis>true</disable_coriolis>" in text
    assert cli(["import", str(sdf), "--format", "gz", "--vehicle", "bluerov2_heavy",
                "--out", str(out)]) == 0
    back, orig = load_model(out), load_model(src)
    assert back.added_mass_terms == orig.added_mass_terms
    assert back.M_A is not None and orig.M_A is not None
    np.testing.assert_allclose(back.M_A, orig.M_A, atol=1e-12)
    np.testing.assert_allclose(back.M, orig.M, atol=1e-12)
    np.testing.assert_allclose(back.theta, orig.theta, rtol=1e-12)


# --- honest exports ----------------------------------------------------------------


def heavy_with(tmp_path: Path, heavy: Vehicle, values: dict[str, float],
               held: dict[str, str] | None = None, flown: float | None = None) -> Path:
    """The heavy's model with some coefficients changed, some held at the prior (σ NaN) and
    flown speeds ±``flown`` × (1, 0.5, 0.8, 1, 1, 1)."""
    theta = heavy.theta.copy()
    names = heavy.damping.parameter_names
    for n, v in values.items():
        theta[names.index(n)] = v
    std = np.array([np.nan if n in (held or {}) else 0.5 for n in names])
    extra = {} if flown is None else {"flown_speeds": {
        "min": (-flown * np.array([1, 0.5, 0.8, 1, 1, 1])).tolist(),
        "max": (flown * np.array([1, 0.5, 0.8, 1, 1, 1])).tolist()}}
    return save_model(tmp_path / "heavy_changed.yaml", Model(names, theta, std, heavy.body.M,
                                                             extra=extra, damping=heavy.damping,
                                                             held=held))


@pytest.mark.parametrize("fmt", ["gz", "urdf", "uuv"])
def test_export_refuses_a_non_dissipative_model_unless_clamped_or_forced(
        tmp_path: Path, heavy: Vehicle, fmt: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Z_ww = −61.25 with Z_w = 33: heave damping vanishes at |w| = 33/61.25 = 0.539 m/s and
    the simulator gains energy beyond. Refused with exit status 2 and one line naming Z_ww,
    the speed and the choices; --clamp writes Z_ww = 0 labelled constrained, --force writes
    it labelled NOT DISSIPATIVE."""
    path = heavy_with(tmp_path, heavy, {"Z_ww": -61.25}, flown=1.0)
    out = tmp_path / f"hydro.{fmt}"
    capsys.readouterr()
    assert main(["export", str(path), "--format", fmt, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert (f"as {fmt} is not dissipative everywhere: Z_ww: the damping turns non-dissipative "
            "beyond |nu| = 0.539 along (w +1.00)") in err
    assert "--clamp" in err and "--force" in err and not out.exists()
    assert main(["export", str(path), "--format", fmt, "--out", str(out), "--clamp"]) == 0
    text = out.read_text()
    assert "CONSTRAINED to the nearest dissipative model" in text
    assert "changed: Z_ww = 0 (was -61.25)" in text and "Z_ww = 0: constrained (was -61.25)" \
        in text and "Z_w = 33.0: estimate" in text
    assert "warning: constrained (--clamp): Z_ww = 0 (was -61.25)" in capsys.readouterr().err
    if fmt == "gz":
        assert tags(text)["zWabsW"] == 0.0 and tags(text)["zW"] == -33.0
    assert main(["export", str(path), "--format", fmt, "--out", str(out), "--force"]) == 0
    text = out.read_text()
    assert "NOT DISSIPATIVE beyond |nu| = 0.539" in text and "Z_ww = -61.25: estimate" in text
    assert "warning: not dissipative (--force)" in capsys.readouterr().err
    if fmt == "gz":
        assert tags(text)["zWabsW"] == 61.25


def test_dissipativity_is_checked_at_every_speed_and_across_couplings(
        tmp_path: Path, heavy: Vehicle) -> None:
    """Dissipative over the flown speeds (|v| ≤ 0.5) is not enough: Y_v = 10, Y_vv = −5
    turns at |v| = 2. A coupling Y_r = N_v = 30 with Y_v = 13.7, N_r = 1.5 makes the linear
    part indefinite: energy near rest. --clamp drops what the check blames."""
    far = load_model(heavy_with(tmp_path, heavy, {"Y_v": 10.0, "Y_vv": -5.0}, flown=1.0))
    with pytest.raises(NotDissipativeError, match=r"Y_vv: the damping turns non-dissipative "
                                                  r"beyond \|nu\| = 2 along \(v \+1\.00\)"):
        export_gz(far)
    coupled = model_file(tmp_path, {"linear": {"Y_v": 13.7, "N_r": 1.5, "Y_r": 30.0,
                                               "N_v": 30.0}})
    with pytest.raises(NotDissipativeError, match=r"non-dissipative near rest along "
                                                  r"\(v [+-]0\.\d\d, r [+-]0\.\d\d\)"):
        export_gz(coupled)
    out = export_gz(coupled, clamp=True)
    assert set(out.constrained) <= {"Y_r", "N_v"} and out.constrained
    fine = load_model(heavy_with(tmp_path, heavy, {}, flown=1.0))
    assert "Dissipative at every speed in this format's form" in export_uuv(fine).text


@pytest.mark.parametrize("fmt", ["gz", "urdf", "uuv"])
def test_export_labels_estimates_constrained_and_held_at_prior(
        tmp_path: Path, heavy: Vehicle, fmt: str, capsys: pytest.CaptureFixture[str]) -> None:
    """A poorly determined coefficient is the data's estimate (the gz file once said HELD AT
    PRIOR for it); one held at its prior is labelled and warned about; one the fit's
    dissipativity constraint set says what it was."""
    held = {"Y_vv": "held at prior 217 (no excitation in v)",
            "X_uu": "poorly determined: 95 % half-width 274 exceeds 50% of its scale",
            "N_rr": "held by dissipativity: unconstrained N_rr = -3.2 ± 1 gives ..."}
    path = heavy_with(tmp_path, heavy, {}, held=held, flown=1.0)
    with pytest.warns(ExportWarning, match=r"holds 1 coefficient\(s\) .*Y_vv = 217\.0"):
        ex = export_model(load_model(path), fmt)
    assert ex.held == (f"Y_vv = 217.0 ({held['Y_vv']})",)
    for line in ("Y_vv = 217.0: held at prior", "X_uu = 141.0: estimate",
                 "N_rr = 1.5: constrained (was -3.2)"):
        assert line in ex.text, line
    assert "HELD AT PRIOR" not in ex.text
    capsys.readouterr()
    assert main(["export", str(path), "--format", fmt, "--out", str(tmp_path / "x")]) == 0
    assert "warning: not identified, exported at its prior: Y_vv = 217.0 (held at prior" \
        in capsys.readouterr().err


def test_refold_writes_element_drags_as_the_formats_coefficients(tmp_path: Path) -> None:
    """--refold: a drag at the origin on its normal speed along u is F_x = −c |u| u, written
    as that diagonal entry (gz xUabsU, URDF's quadratic X, UUV's quadratic_damping[0,0]),
    added to X_uu (one coefficient, checked for dissipativity as the sum the simulator
    applies), labelled refolded, not left out; the header gives each DOF's share.
    refold=False leaves it out; refold=True refuses a file without flown speeds, naming the
    option."""
    spec = {"quadratic": {"X_uu": 40.0},
            "point": [{"position": [0.0, 0.0, 0.0], "axis": "u", "speed": "normal",
                       "value": 12.0}]}
    model, theta = damping_from_spec(spec)
    flown = {"flown_speeds": {"min": [-1.0] * 6, "max": [1.0] * 6}}
    path = save_model(tmp_path / "m.yaml", Model(model.parameter_names, theta,
                                                  np.zeros(model.n_params), np.eye(6) * 20.0,
                                                  extra=flown, damping=model))
    mf = load_model(path)
    for fmt, written in (("gz", r"<xUabsU>(\S+)</xUabsU>"), ("urdf", r'Xuu="(\S+)"'),
                         ("uuv", r"<quadratic_damping>\s*(\S+)")):
        out = export_model(mf, fmt, refold=True)
        assert out.left_out == (), (fmt, out.left_out)
        body = out.text.split("-->", 1)[1]  # the element after the header comment
        found = re.search(written, body)
        assert found is not None, (fmt, body)
        assert float(found.group(1)) == pytest.approx(-52.0, rel=1e-12), fmt  # SNAME sign
        assert "REFOLDED: drag.uu@(0,0,0)" in out.text, fmt
        assert "per DOF X Y Z K M N: 1.0000 - - - - -" in out.text, fmt
        label = re.search(r"X_uu \+ refold:X_u\|u\| = (\S+): estimate \+ refolded",
                          out.text)
        assert label is not None and float(label.group(1)) == pytest.approx(52.0), fmt
        kept = export_model(mf, fmt, refold=False)
        assert [x.split(" =")[0] for x in kept.left_out] == ["drag.uu@(0,0,0)"], fmt
    bare = model_file(tmp_path, spec, name="bare.yaml")
    with pytest.raises(ConfigError, match=r"--refold: the model file records no flown speeds"):
        export_model(bare, "gz", refold=True)
