"""HTML report (dampest_ros.report) of a short simulated identification."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np

from dampest_ros.core import frames
from dampest_ros.core.batch import fit
from dampest_ros.core.excitation import make_excitation
from dampest_ros.core.samples import Samples
from dampest_ros.core.simulate import run
from dampest_ros.io.yaml_io import load_vehicle
from dampest_ros.report import write_report

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def test_report_files_names_and_pngs(tmp_path: Path) -> None:
    vehicle = load_vehicle("bluerov2_heavy")
    traj = run(vehicle, make_excitation("B", vehicle, 60.0, seed=2))
    euler = frames.euler_from_matrix(frames.quat_to_matrix(traj.quaternion))
    samples = Samples(traj.t, traj.nu, traj.nu_dot, traj.tau, euler, traj.position[:, 2],
                      np.zeros(len(traj), dtype=np.int64))
    prior = 1.2 * vehicle.theta
    result = fit(samples, vehicle.damping, vehicle.body, prior=prior)
    # one parameter held at its prior: shown with its reason, not as a number
    held = np.array([n == "K_pp" for n in result.names])
    result = dataclasses.replace(result, flags={"K_pp": "low speed only: test reason"},
                                 held=held)
    truth = dict(zip(vehicle.damping.parameter_names, vehicle.theta, strict=True))

    out = tmp_path / "report"
    index = write_report(out, samples, vehicle.damping, vehicle.body, result, prior=prior,
                         truth=truth, title="BlueROV2 Heavy <test>", source="sim/b60.csv",
                         tau_hold="zero")

    assert index == out / "index.html" and index.is_file()
    text = index.read_text(encoding="utf-8")
    for name in vehicle.damping.parameter_names:
        assert f"<td>{name}</td>" in text, name
    assert "BlueROV2 Heavy &lt;test&gt;" in text and "sim/b60.csv" in text
    assert re.search(r"generated \d{4}-\d\d-\d\d \d\d:\d\d:\d\d UTC", text)
    row = next(r for r in text.split("<tr") if "<td>K_pp</td>" in r)
    assert "held at prior" in row and "test reason" in row
    pngs = re.findall(r'<img src="([^"]+)"', text)
    assert len(pngs) == 6
    for name in pngs:
        path = out / name
        assert path.parent == out and path.is_file(), name  # relative links
        data = path.read_bytes()
        assert len(data) > 1000 and data[:8] == PNG_MAGIC, name
