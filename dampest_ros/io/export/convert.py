"""The dispatch by format: :func:`export_model`, :func:`import_model` and the format of a file
(:func:`detect_format`)."""

from __future__ import annotations

from pathlib import Path

from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.io.export import FORMATS, IMPORT_FORMATS
from dampest_ros.io.export.common import Exported, Imported, parse_xml
from dampest_ros.io.export.gz import export_gz, import_gz, is_gz_plugin
from dampest_ros.io.export.urdf import export_urdf, import_urdf
from dampest_ros.io.export.uuv import export_uuv, import_uuv

#: What marks each import format in a file, for messages.
_MARKS = {"gz": "a gz-sim Hydrodynamics <plugin>", "urdf": "a <hydrodynamics> block",
          "uuv": "a UUV Simulator <hydrodynamic_model>"}


def export_model(mf: Model, fmt: str, vehicle: Vehicle | None = None, *,
                 link_name: str = "base_link", frame: str = "flu",
                 source: str | None = None, force: bool = False,
                 clamp: bool = False, refold: bool | None = None) -> Exported:
    """Export a model in one of :data:`~dampest_ros.io.export.FORMATS`.

    Parameters
    ----------
    mf : Model
    fmt : {'gz', 'urdf', 'uuv'}
    vehicle : Vehicle, optional
        For the added mass M_A = M − M_RB (and, for ``urdf``, the rigid-body entries; for
        ``uuv``, the volume, centre of buoyancy and water density).
    link_name : str
        ``gz``, ``uuv``: the link the plugin acts on.
    frame : str
        ``gz`` only; see :func:`~dampest_ros.io.export.gz.export_gz`.
    source : str, optional
        Where the model came from, for the header comment.
    force, clamp : bool
        For coefficients the format would apply non-dissipatively at some speed: write them
        as they are, labelled NOT DISSIPATIVE (``force``), or the nearest dissipative set,
        labelled constrained (``clamp``); neither: refused.
    refold : bool, optional
        Write the static terms the format cannot carry as coefficients it can that
        reproduce their force over the flown envelope (labelled): by default when the model
        file records its flown speeds; False leaves them out, listed; True refuses a file
        without flown speeds.

    Returns
    -------
    Exported

    Raises
    ------
    ValueError
        Unknown format or frame.
    NotDissipativeError
        The written coefficients generate energy at some speed and neither ``force`` nor
        ``clamp`` is set.
    """
    if fmt == "gz":
        return export_gz(mf, vehicle, link_name=link_name, frame=frame, source=source,
                         force=force, clamp=clamp, refold=refold)
    if fmt == "urdf":
        return export_urdf(mf, vehicle, source=source, force=force, clamp=clamp,
                           refold=refold)
    if fmt == "uuv":
        return export_uuv(mf, vehicle, link_name=link_name, source=source, force=force,
                          clamp=clamp, refold=refold)
    raise ValueError(f"unknown export format {fmt!r}; use one of {FORMATS}")


def import_model(source: str | Path, fmt: str | None = None, *, frame: str = "flu",
                 link_name: str | None = None) -> Imported:
    """Import a model from one of :data:`~dampest_ros.io.export.IMPORT_FORMATS`.

    Parameters
    ----------
    source : str or Path
        File or XML text.
    fmt : {'gz', 'urdf', 'uuv'}, optional
        The format; None: the one the file holds (:func:`detect_format`).
    frame : str
        ``gz`` only; see :func:`~dampest_ros.io.export.gz.import_gz`.
    link_name : str, optional
        ``gz``, ``uuv``: which plugin (gz) or link (uuv) to read when there are several.

    Returns
    -------
    Imported

    Raises
    ------
    ValueError
        Unknown format.
    ConfigError
        No format given and the file holds none of them, or several.
    """
    if fmt is None:
        fmt = detect_format(source)
    if fmt == "gz":
        return import_gz(source, frame=frame, link_name=link_name)
    if fmt == "urdf":
        return import_urdf(source)
    if fmt == "uuv":
        return import_uuv(source, link_name=link_name)
    raise ValueError(f"unknown import format {fmt!r}; use one of {IMPORT_FORMATS}")


def detect_format(source: str | Path) -> str:
    """The one import format a file or XML text holds.

    Returns
    -------
    str
        One of :data:`~dampest_ros.io.export.IMPORT_FORMATS`.

    Raises
    ------
    ConfigError
        The file holds none of them (naming what each would look like) or several (asking
        for ``--format``).
    """
    root, label = parse_xml(source)
    tags = {el.tag for el in root.iter()}
    found = [fmt for fmt, present in (
        ("gz", any(is_gz_plugin(el) for el in root.iter("plugin"))),
        ("urdf", "hydrodynamics" in tags), ("uuv", "hydrodynamic_model" in tags)) if present]
    if not found:
        raise ConfigError(label, f"holds no hydrodynamics dampest can import: none of "
                                 f"{', '.join(_MARKS.values())}")
    if len(found) > 1:
        raise ConfigError(label, f"holds {' and '.join(_MARKS[f] for f in found)}: choose "
                                 f"one with --format {' or --format '.join(found)}")
    return found[0]
