"""Logs named by URL (any filesystem fsspec knows: ``s3://``, ``gs://``, ``sftp://``,
``memory://`` …): expanded like paths, and copied to a local temporary directory to be read,
where the reading runs (a Dask worker reads its own logs).

A plain path, or a ``file://`` URL, is read in place. Other schemes need their fsspec
filesystem package installed where the log is read (e.g. ``s3fs`` for ``s3://``).
"""

from __future__ import annotations

import contextlib
import tempfile
from collections.abc import Iterator
from pathlib import Path, PurePosixPath
from typing import Any

from dampest_ros.core.physics.rigid_body import ConfigError

FILE = "file://"
#: fsspec's in-memory filesystem: its files live in one process only.
MEMORY = "memory://"


def is_url(name: str) -> bool:
    """Whether ``name`` is a URL of a scheme other than ``file://``."""
    return "://" in name and not name.startswith(FILE)


def in_memory(name: str) -> bool:
    """Whether ``name`` is a ``memory://`` URL (a file of this process only)."""
    return name.startswith(MEMORY)


def local_name(name: str) -> str:
    """``name`` without a ``file://`` scheme."""
    return name[len(FILE):] if name.startswith(FILE) else name


def _filesystem(url: str) -> tuple[Any, str]:
    """The fsspec filesystem of ``url`` and the path within it.

    Raises
    ------
    ConfigError
        fsspec does not know the scheme or misses its package (URL, reason, fix).
    """
    try:
        import fsspec
    except ImportError as exc:
        raise ConfigError(url, "logs named by URL are read with fsspec, which is not installed; "
                               "pip install fsspec (dampest_ros's optional 'pool' extra)") from exc
    try:
        return fsspec.core.url_to_fs(url)
    except (ImportError, ValueError) as exc:
        raise ConfigError(url, f"cannot open this URL ({exc}); install the fsspec "
                               "filesystem of its scheme, or copy the log to a path") from exc


def glob_url(pattern: str) -> list[str]:
    """The URLs a URL glob pattern matches, sorted."""
    fs, path = _filesystem(pattern)
    return [str(fs.unstrip_protocol(p)) for p in sorted(fs.glob(path))]


@contextlib.contextmanager
def local_log(name: str) -> Iterator[str]:
    """The log ``name`` as a local path: the path itself, or for a URL a copy of the log (a
    rosbag2 directory or a file) in a temporary directory, removed when the block ends.

    Raises
    ------
    FileNotFoundError
        The URL names nothing.
    ConfigError
        An unknown scheme (:func:`_filesystem`).
    """
    if not is_url(name):
        yield local_name(name)
        return
    fs, path = _filesystem(name)
    path = path.rstrip("/")
    if not fs.exists(path):
        shared = ("" if not in_memory(name) else
                  " in this process (an in-memory filesystem is not shared with other "
                  "processes, e.g. the Dask workers of a --scheduler: use a local path or a "
                  "shared filesystem)")
        raise FileNotFoundError(f"{name} does not exist{shared}")
    with tempfile.TemporaryDirectory(prefix="dampest_log_") as tmp:
        dest = Path(tmp) / (PurePosixPath(path).name or "log")
        if fs.isdir(path):
            # trailing slashes: the directory's contents into dest
            fs.get(path + "/", str(dest) + "/", recursive=True)
        else:
            fs.get(path, str(dest))
        yield str(dest)
