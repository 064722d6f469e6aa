"""dampest identify over several logs (dampest_ros/cli/pool.py): Dask map, pooled fit, drift."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import pytest
import yaml

from dampest_ros.cli.identify_options import add_arguments
from dampest_ros.cli.inputs import load_samples
from dampest_ros.cli.main import main
from dampest_ros.cli.pool import expand_inputs
from dampest_ros.core.identification.batch import FitOptions, fit
from dampest_ros.core.signals.extent import Extent
from dampest_ros.core.signals.samples import Samples
from dampest_ros.core.simulation.excitation import speed_limits
from dampest_ros.io.yaml_io import load_model, load_vehicle

REPO = Path(__file__).resolve().parents[2]


def test_inputs_expand_globs_and_lists_and_refuse_what_they_cannot_read(tmp_path: Path
                                                                         ) -> None:
    for name in ("dive_2", "dive_1", "other"):
        (tmp_path / name).mkdir()
    listing = tmp_path / "logs.txt"
    listing.write_text("# sea day 1\ndive_1\n\n" + str(tmp_path / "other") + "  # absolute\n")
    assert expand_inputs([str(tmp_path / "dive_*"), str(listing), "file:///x/bag"]) == [
        str(tmp_path / "dive_1"), str(tmp_path / "dive_2"), str(tmp_path / "dive_1"),
        str(tmp_path / "other"), "/x/bag"]
    with pytest.raises(ValueError, match="matches no log"):
        expand_inputs([str(tmp_path / "nothing_*")])
    with pytest.raises(ValueError, match="cannot open this URL"):
        expand_inputs(["nosuchscheme://bucket/dive_*"])


def test_logs_named_by_url_are_copied_where_they_are_read(tmp_path: Path) -> None:
    """Two bags on an fsspec filesystem (memory://, shared with an in-process Dask worker)
    named by a URL glob: each is copied where it is read and gives the estimate of its
    local copy; no temporary copy is left behind."""
    import fsspec
    from dask.distributed import LocalCluster

    fs = fsspec.filesystem("memory")
    local = []
    for seed in (1, 2):
        bag = tmp_path / f"dive_{seed}"
        assert main(["simulate", "--vehicle", "bluerov2_heavy", "--protocol", "B",
                     "--duration", "40", "--seed", str(seed), "--out", str(bag)]) == 0
        fs.put(str(bag), f"/dampest_test/dive_{seed}", recursive=True)
        local.append(str(bag))
    before = set(Path(tempfile.gettempdir()).glob("dampest_log_*"))
    with LocalCluster(n_workers=1, processes=False, threads_per_worker=1,
                      dashboard_address=None) as cluster:
        options = ["--vehicle", "bluerov2_heavy", "--scheduler", cluster.scheduler_address]
        assert main(["identify", "memory://dampest_test/dive_*", *options, "--out",
                     str(tmp_path / "url.yaml")]) == 0
        assert main(["identify", *local, *options, "--out", str(tmp_path / "path.yaml")]) == 0
    fs.rm("/dampest_test", recursive=True)
    by_url, by_path = load_model(tmp_path / "url.yaml"), load_model(tmp_path / "path.yaml")
    assert by_url.extra["logs"] == [f"memory:///dampest_test/dive_{k}" for k in (1, 2)]
    np.testing.assert_allclose(by_url.theta, by_path.theta, rtol=1e-12, atol=0)
    assert set(Path(tempfile.gettempdir()).glob("dampest_log_*")) == before


@pytest.mark.parametrize("option,message", [
    (["--method", "rls"], "--method rls: replays one bag"),
    (["--select"], "--select: searches the structure on one log"),
    (["--holdout", "0.3"], "--holdout: takes one log"),
    (["--workers", "0"], "--workers: 0: needs at least 1 worker"),
])
def test_one_log_options_are_refused_with_several(tmp_path: Path, option: list[str],
                                                  message: str,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
    capsys.readouterr()
    assert main(["identify", str(tmp_path / "a"), str(tmp_path / "b"), "--vehicle",
                 "bluerov2_heavy", *option]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"dampest identify: error: {message}") and err.count("\n") == 1


def heavier(tmp_path: Path, factor: float) -> Path:
    """The BlueROV2 Heavy preset with every damping coefficient × ``factor``."""
    spec = yaml.safe_load((REPO / "config/vehicles/bluerov2_heavy.yaml").read_text())
    for kind in ("linear", "quadratic"):
        spec["damping"][kind] = {k: factor * v for k, v in spec["damping"][kind].items()}
    path = tmp_path / "bluerov2_fouled.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


@pytest.mark.slow
def test_five_bags_pool_exactly_skip_a_corrupt_one_and_show_a_20_percent_drift(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Five 60 s protocol-B bags (seeds 1–5); the last two flown with every damping
    coefficient × 1.2 (fouling); a sixth "bag" is garbage. Two Dask workers."""
    fouled = heavier(tmp_path, 1.2)
    bags = []
    for k in range(5):
        bag = tmp_path / f"dive_{k}"
        assert main(["simulate", "--vehicle", str(fouled) if k >= 3 else "bluerov2_heavy",
                     "--protocol", "B", "--duration", "60", "--seed", str(k + 1), "--out",
                     str(bag)]) == 0
        bags.append(str(bag))
    broken = tmp_path / "dive_broken"
    broken.mkdir()
    (broken / "metadata.yaml").write_text("not: a bag\n")
    capsys.readouterr()
    out = tmp_path / "pooled.yaml"
    assert main(["identify", str(tmp_path / "dive_*"), "--vehicle", "bluerov2_heavy",
                 "--workers", "2", "--keep-all", "--out", str(out)]) == 0
    printed = capsys.readouterr()
    assert f"left out: {broken}:" in printed.err and "Traceback" not in printed.err
    assert "note: the logs are pooled on bluerov2_heavy's preset terms" in printed.err
    model = load_model(out)
    assert model.extra["logs"] == bags and model.extra["logs_left_out"] == [str(broken)]
    changed = set(model.extra["drift_changed"])
    assert {"X_uu", "Y_vv", "Z_ww", "K_pp", "M_qq", "N_rr"} <= changed
    for name in ("X_uu", "Z_ww"):
        line = next(x for x in printed.out.splitlines() if x.split()[:1] == [name]
                    and "CHANGED" in x)
        assert "after dive_2:" in line, line
    # the pooled estimate is the fit of the five bags' samples at once
    vehicle = load_vehicle("bluerov2_heavy")
    p = argparse.ArgumentParser()
    add_arguments(p)
    args = p.parse_args([*bags, "--vehicle", "bluerov2_heavy"])
    once = Samples.concatenate([load_samples(b, vehicle, args) for b in bags])
    f = fit(once, vehicle.damping, vehicle.body, FitOptions(cutoff=args.cutoff, speed_range=tuple(
        speed_limits(vehicle, force=Extent.of(once).force))))
    np.testing.assert_allclose(model.theta, f.theta, rtol=1e-10, atol=0)
    np.testing.assert_allclose(model.theta_std, f.std, rtol=1e-10, atol=0)
    # the same damping in every bag: no change reported
    assert main(["identify", *bags[:3], "--vehicle", "bluerov2_heavy", "--workers", "2",
                 "--no-select", "--out", str(out)]) == 0
    assert load_model(out).extra["drift_changed"] == ["none"]
    assert "note:" not in capsys.readouterr().err  # --no-select: the preset is meant


def test_two_local_clusters_at_once_start_without_a_warning() -> None:
    """Two pooled commands at once: the second's scheduler does not warn that the
    dashboard's port 8787 is taken (it used to, in four lines on stderr)."""
    import warnings

    from dampest_ros.cli.pool import local_cluster

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        first = local_cluster(1, processes=False)
        try:
            second = local_cluster(1, processes=False)
            second.close()
        finally:
            first.close()
