"""Logs named by URL (dampest_ros/io/remote.py)."""

from __future__ import annotations

from pathlib import Path

import fsspec
import pytest

from dampest_ros.io.remote import glob_url, is_url, local_log


def test_paths_are_read_in_place_and_urls_copied_then_removed(tmp_path: Path) -> None:
    fs = fsspec.filesystem("memory")
    fs.pipe({"/remote_test/dive_1/metadata.yaml": b"a", "/remote_test/dive_1/d_0.mcap": b"bc",
             "/remote_test/log.csv": b"t,u\n"})
    assert not is_url(str(tmp_path)) and not is_url("file:///x") and is_url("memory://x")
    with local_log(f"file://{tmp_path}") as p:
        assert p == str(tmp_path)
    with local_log("memory://remote_test/dive_1/") as p:
        copy = Path(p)
        assert copy.name == "dive_1"
        assert {f.name: f.read_bytes() for f in copy.iterdir()} == {
            "metadata.yaml": b"a", "d_0.mcap": b"bc"}
    assert not copy.exists()
    with local_log("memory://remote_test/log.csv") as p:
        assert Path(p).read_bytes() == b"t,u\n"
    assert glob_url("memory://remote_test/d*") == ["memory:///remote_test/dive_1"]
    with pytest.raises(FileNotFoundError, match="memory://remote_test/nothing does not"), \
            local_log("memory://remote_test/nothing"):
        pass
    fs.rm("/remote_test", recursive=True)
