"""Vehicle presets and the model file (a ROS 2 parameters file), read and written as YAML.

Vehicle presets (``config/vehicles/<name>.yaml``) are loaded by name or path into a
:class:`dampest_ros.core.physics.vehicle.Vehicle`.

The model file is a valid ROS 2 parameters file, so ``--ros-args --params-file`` loads it as
well as :func:`load_model` does (docs/architecture.md §1, §3)::

    /**:
      ros__parameters:
        model:
          sign_convention: dissipative_positive
          parameter_names: [X_u, Y_v, ..., X_uu, ...]
          theta: [13.7, 0.0, ..., 141.0, ...]
          theta_std: [0.2, 0.1, ..., 1.5, ...]   # .nan allowed only for held coefficients
          identified: [true, true, ..., false, ...]  # did the data determine it (optional)
          held: {names: [Y_vv], reasons: [...]}    # those not identified: θ is the prior
          flown_speeds: {min: [...], max: [...]}   # per DOF, the fit's data (optional)
          M: [...]              # 36 numbers, row-major, M_RB + M_A
          M_A: [...]            # 36 numbers, the added mass inside M (optional)
          added_mass_terms: {inertial: true, coriolis: true, munk: true}   # optional
          version: 1
          identity: {kind: vehicle_damping, name: bluerov2_heavy, hash: ..., parts: {...}}
          terms:                # structure of D(ν), enough to rebuild it (values are theta)
            linear: [X_u, Y_v, Z_w, K_p, M_q, N_r]     # SNAME names (off-diagonal: Y_r, ...)
            quadratic: [X_uu, Y_vv, Z_ww, K_pp, M_qq, N_rr]
            cross: {rows: [1], cols: [1], alphas: ['|r|'], names: [Y_vr]}  # rows X..N = 0..5
            freq: {dofs: [0], rates: [2.0]}            # dofs u..r = 0..5, rates λ (1/s)
            added: true                               # Munk moments added.K_vw, M_uw, N_uv
            coriolis: [coriolis.m_u, coriolis.m_v]     # added-mass corrections (C_A only)
            residual: {modes: [...]}                   # r unit 6-vectors, row-major
          ...                   # extra entries (scalars, homogeneous arrays, namespaces)

ROS parameters allow only scalars and non-empty homogeneous arrays as leaves (nested
mappings are namespaces), so the term structure is stored as parallel arrays, with integer
indices where letters such as ``N`` or ``Y`` would read as booleans. Damping coefficients are
positive when dissipative (force on the left-hand side is +D(ν)ν).

``M_A`` and ``added_mass_terms`` say which effects of the added mass act on the plant the
model describes (:class:`~dampest_ros.core.physics.rigid_body.AddedMassTerms`: ``inertial`` M_A ν̇,
``coriolis`` C_A(ν)ν, ``munk`` its Munk moments); the switches are a namespace of three
booleans, so ``model.added_mass_terms.coriolis`` is a ROS parameter. When single entries of
C_A(ν) are zeroed beyond the switches, ``coriolis_mask`` (36 integers 0/1, row-major, 1 = the
entry acts) carries them (docs/architecture.md §1). Files without them (older
ones) mean all effects act, and C(ν)ν is that of M as a whole.

``identified`` says per coefficient whether the data determined it; one that is ``false``
holds its prior value (never an estimate) and ``held`` gives the reason, as parallel arrays
(parameter names need not be valid ROS parameter names). Files without ``identified`` read as
all identified, except those written by earlier ``dampest identify`` versions, whose
``unidentified`` / ``unidentified_reason`` lists are read as ``held``. Every reader refuses a
non-finite θ, M or σ of an identified coefficient
(:func:`~dampest_ros.core.identification.identified.check_model_numbers`).

Every reader (the file, its text, a node's ``model.*`` parameters) checks the model against
``dampest_ros/schemas/model.schema.json`` first: an unknown key spelt like one of the model's
own (``theta_sdt``), a missing key or a wrong type is refused as
``<file>:<line>: model.<key>: <what>; <fix>``, as are lists of unequal lengths.
"""

from __future__ import annotations

import os
import sys
import tempfile
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from dampest_ros.core.identification.identified import check_model_numbers
from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.alpha import Alpha
from dampest_ros.core.physics.damping import TERM_KINDS, DampingModel
from dampest_ros.core.physics.identity import ARM_KIND, VEHICLE_KIND, Identity, mismatch
from dampest_ros.core.physics.point_drag import FORCES, point_spec
from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES, AddedMassTerms, ConfigError
from dampest_ros.core.physics.vehicle import Vehicle, damping_from_spec
from dampest_ros.core.signals.measurements import FloatArray
from dampest_ros.io.schema import check, load_checked
from dampest_ros.io.strict_yaml import InputError, KeyPath, YamlDoc, load_yaml, loads_yaml

SIGN_CONVENTION = "dissipative_positive"
_REQUIRED = ("sign_convention", "parameter_names", "theta", "theta_std", "M", "version")
_RESERVED = (*_REQUIRED, "terms", "M_A", "added_mass_terms", "identified", "held", "identity")


#: What a model file is, for the message refusing another kind of file given as one.
MODEL_KIND = ("a model file (the ROS 2 parameters YAML that dampest identify --out writes: "
              "<node>: ros__parameters: model: ...)")


def _read_yaml(path: Path, kind: str = "a YAML text file") -> Any:
    """A user's YAML file, duplicate keys refused (:mod:`dampest_ros.io.strict_yaml`);
    ``kind`` says what it should be when it is a directory or binary."""
    return load_yaml(path, kind).data


def read_mapping(source: str) -> dict[str, Any]:
    """A YAML mapping from a file path or from inline text (``"current: [0.2, 0, 0]"``)."""
    path = Path(source)
    if path.is_file():
        data = _read_yaml(path)
    else:
        data = loads_yaml(source, "inline YAML").data
    if not isinstance(data, dict):
        raise ConfigError(source, "must be a YAML mapping (key: value)")
    return data


# --- vehicles ------------------------------------------------------------------------------


def vehicle_dirs() -> list[Path]:
    """Where presets are looked up: the source tree's ``config/vehicles``, then the installed
    ``<prefix>/share/dampest_ros/config/vehicles`` for the prefix this package is installed in
    (a colcon install space: ``<prefix>/lib/python3.X/site-packages/dampest_ros``), the
    prefixes of ``AMENT_PREFIX_PATH`` and ``sys.prefix``."""
    package = Path(__file__).resolve().parents[1]
    share = Path("share") / "dampest_ros" / "config" / "vehicles"
    prefixes = [package.parents[3]] if len(package.parents) > 3 else []
    prefixes += [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(Path(sys.prefix))
    dirs = [package.parent / "config" / "vehicles"]
    for prefix in prefixes:
        if prefix / share not in dirs:
            dirs.append(prefix / share)
    return dirs


def list_vehicles() -> list[str]:
    """Names of the available presets."""
    return sorted({p.stem for d in vehicle_dirs() if d.is_dir() for p in d.glob("*.yaml")})


def vehicle_path(name_or_path: str | Path) -> Path:
    """The YAML file of a preset name (``bluerov2_heavy``) or of a path."""
    text = str(name_or_path)
    if isinstance(name_or_path, Path) or text.endswith((".yaml", ".yml")) or os.sep in text:
        path = Path(name_or_path)
        if not path.is_file():
            raise FileNotFoundError(f"no vehicle file {path}")
        return path
    for d in vehicle_dirs():
        if (d / f"{text}.yaml").is_file():
            return d / f"{text}.yaml"
    raise FileNotFoundError(f"no vehicle preset {text!r}; presets: {list_vehicles()} "
                            f"(searched {[str(d) for d in vehicle_dirs()]})")


def load_vehicle(name_or_path: str | Path) -> Vehicle:
    """Load a vehicle preset by name or path.

    Parameters
    ----------
    name_or_path : str or Path
        A preset name such as ``bluerov2_heavy`` or a path to a YAML file with the sections
        ``vehicle``, ``damping`` and ``thrusters`` (see :mod:`dampest_ros.core.physics.vehicle`).

    Returns
    -------
    Vehicle

    Raises
    ------
    InputError
        A ConfigError naming the file, the line and the key: a duplicate key, a violation of
        the vehicle schema (``dampest_ros/schemas/vehicle.schema.json``: an unknown key with
        the closest valid one, a missing one, a wrong type or range) or of a physics check
        (e.g. an inertia that is not positive definite).
    """
    path = vehicle_path(name_or_path)
    doc = load_checked(path, "vehicle")
    try:
        return replace(Vehicle.from_dict(doc.data), source=str(path))
    except ConfigError as exc:
        raise doc.error(_field_path(doc, exc.field), exc.reason) from None


def _field_path(doc: YamlDoc, field_name: str) -> list[str]:
    """The key path of a physics check's field (``inertia`` is ``vehicle.inertia``)."""
    path = field_name.split(".")
    return path if tuple(path[:1]) in doc.lines else ["vehicle", *path]


# --- damping spec --------------------------------------------------------------------------


def damping_spec(model: DampingModel, theta: FloatArray) -> dict[str, Any]:
    """The ``damping`` mapping of a vehicle preset for a model and its coefficients.

    The inverse of :func:`dampest_ros.core.physics.vehicle.damping_from_spec`: that function
    rebuilds the same parameter names, θ and regressor from the result.

    Parameters
    ----------
    model : DampingModel
        Terms in the order of ``TERM_KINDS`` (as ``damping_from_spec`` builds them).
    theta : ndarray, shape (p,)

    Returns
    -------
    dict
        Sections ``linear``, ``quadratic`` (name → value), ``cross``, ``freq`` (lists of
        mappings), ``added``, ``coriolis`` (name → value), ``residual`` (``modes``,
        ``values``).
    """
    if model.kinds != sorted(model.kinds, key=TERM_KINDS.index):
        raise ValueError(f"terms must be in the order {TERM_KINDS}, got {model.kinds}")
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (model.n_params,):
        raise ValueError(f"theta has shape {theta.shape}, the model {model.n_params} parameters")
    spec: dict[str, Any] = {}
    for term in model.terms:
        values = [float(v) for v in theta[model.slice(term.kind)]]
        named = dict(zip(term.parameter_names, values, strict=True))
        if term.kind in ("linear", "quadratic", "added", "coriolis"):
            spec[term.kind] = named
        elif term.kind == "cross":
            spec["cross"] = []
            for b, v in zip(term.bases, values, strict=True):
                (row, col), = np.argwhere(b.B != 0)
                if Alpha.parse(b.alpha.label()) != b.alpha:
                    raise ValueError(f"cross term {b.name}: α {b.alpha} has no text form")
                spec["cross"].append({"row": FORCE_NAMES[row], "col": DOF_NAMES[col],
                                      "alpha": b.alpha.label(), "name": b.name, "value": v})
        elif term.kind == "freq":
            spec["freq"] = [{"dof": DOF_NAMES[int(d)], "rate": float(lam), "c": v}
                            for d, lam, v in zip(term.state_dofs, term.rates, values,
                                                 strict=True)]
        elif term.kind == "point":
            spec["point"] = [{**point_spec(b).to_dict(), "value": v}
                             for b, v in zip(term.bases, values, strict=True)]
        elif term.kind == "residual":
            spec["residual"] = {"modes": [list(map(float, b.alpha.w)) for b in term.bases],
                                "values": values}
    return spec


def _terms_params(spec: Mapping[str, Any]) -> dict[str, Any]:
    """The structure of a damping spec as ROS parameters (no values, no empty arrays)."""
    out: dict[str, Any] = {}
    for kind in ("linear", "quadratic", "coriolis"):
        if spec.get(kind):
            out[kind] = list(spec[kind])
    if spec.get("cross"):
        c = spec["cross"]
        out["cross"] = {"rows": [FORCE_NAMES.index(x["row"]) for x in c],
                        "cols": [DOF_NAMES.index(x["col"]) for x in c],
                        "alphas": [x["alpha"] for x in c], "names": [x["name"] for x in c]}
    if spec.get("freq"):
        out["freq"] = {"dofs": [DOF_NAMES.index(x["dof"]) for x in spec["freq"]],
                       "rates": [float(x["rate"]) for x in spec["freq"]]}
    if "added" in spec:
        out["added"] = True
    if spec.get("point"):
        p = spec["point"]
        # a drag's axis and speed; an area drag's or lift's axis and "area" or "lift"; a Magnus
        # force's −1 and "magnus"; an axis off the body axes is 3, its direction in directions
        out["point"] = {"positions": [float(x) for e in p for x in e["position"]],
                        "axes": [DOF_NAMES.index(a) if isinstance(a, str) else -1 if a is None
                                 else 3 for a in (e.get("axis") for e in p)],
                        "speeds": [e["speed"] if "speed" in e else e["force"] for e in p]}
        if directions := [float(x) for e in p if isinstance(e.get("axis"), list)
                          for x in e["axis"]]:
            out["point"]["directions"] = directions
    if spec.get("residual"):
        out["residual"] = {"modes": [float(v) for m in spec["residual"]["modes"] for v in m]}
    return out


def _spec_from_params(terms: Mapping[str, Any]) -> dict[str, Any]:
    """A damping spec (all values zero) from :func:`_terms_params` output."""
    spec: dict[str, Any] = {}
    for kind in ("linear", "quadratic", "coriolis"):
        if kind in terms:
            spec[kind] = {str(n): 0.0 for n in terms[kind]}
    if "cross" in terms:
        c = terms["cross"]
        spec["cross"] = [{"row": int(r), "col": int(k), "alpha": str(a), "name": str(n)}
                         for r, k, a, n in zip(c["rows"], c["cols"], c["alphas"], c["names"],
                                               strict=True)]
    if "freq" in terms:
        spec["freq"] = [{"dof": DOF_NAMES[int(d)], "rate": float(r)}
                        for d, r in zip(terms["freq"]["dofs"], terms["freq"]["rates"],
                                        strict=True)]
    if terms.get("added"):
        spec["added"] = {}
    if "point" in terms:
        p = terms["point"]
        # the directions of the axes 3, in order
        directions = iter(np.reshape(p.get("directions", []), (-1, 3)).tolist())
        spec["point"] = [{"position": list(r),
                          **({"axis": DOF_NAMES[int(a)]} if 0 <= int(a) < 3 else
                             {"axis": next(directions)} if int(a) == 3 else {}),
                          **({"force": str(s)} if s in FORCES[1:] else {"speed": str(s)})}
                         for r, a, s in zip(np.reshape(p["positions"], (-1, 3)).tolist(),
                                            p["axes"], p["speeds"], strict=True)]
    if "residual" in terms:
        spec["residual"] = {"modes": np.reshape(terms["residual"]["modes"], (-1, 6)).tolist()}
    return spec


# --- the model file ------------------------------------------------------------------------


def _param_value(key: str, value: Any) -> Any:
    """``value`` as a ROS parameter (scalar, homogeneous non-empty array or namespace)."""
    if isinstance(value, np.ndarray | np.generic):
        value = value.tolist()
    if isinstance(value, Mapping):
        return {str(k): _param_value(f"{key}.{k}", v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        items = [_param_value(key, v) for v in value]
        if items and all(isinstance(v, int | float) and not isinstance(v, bool) for v in items):
            return items if all(isinstance(v, int) for v in items) else list(map(float, items))
        if items and any(all(isinstance(v, t) for v in items) for t in (bool, str)):
            return items
        raise ValueError(f"model.{key}: a ROS parameter array must be non-empty and of one "
                         f"type (bool, number or string), got {value!r}")
    if isinstance(value, bool | int | float | str):
        return value
    raise ValueError(f"model.{key}: {type(value).__name__} is not a ROS parameter type")


class _Dumper(yaml.SafeDumper):  # type: ignore[misc]
    """Quotes y/Y/n/N, which the ROS parameter parser reads as booleans."""


_Dumper.add_representer(str, lambda d, s: d.represent_scalar(
    "tag:yaml.org,2002:str", s, style="'" if s in ("y", "Y", "n", "N") else None))


def atomic_write(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically: a temporary file in the same directory
    (``.<name>.*.tmp``), synced, then renamed over ``path``."""
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:
        raise _cannot_write(path, exc) from None
    try:
        with os.fdopen(fd, "w") as f:
            os.fchmod(f.fileno(), 0o644)
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise _cannot_write(path, exc) from None
        raise


def _cannot_write(path: Path, exc: OSError) -> OSError:
    """``exc`` of an atomic write, naming ``path`` (not its temporary file)."""
    return type(exc)(exc.errno, f"cannot write {path}: {exc.strerror}")


def save_model(path: str | Path, model: Model) -> Path:
    """Write the model file atomically (temporary file in the same directory + rename).

    Parameters
    ----------
    path : str or Path
    model : Model
        Written as ``model.*``: names, θ, σ, M, version, ``identified`` and ``held``,
        ``M_A`` and ``added_mass_terms`` when it has them, its term structure as
        ``model.terms`` (so that :func:`load_model` rebuilds it) and its ``extra`` entries
        (scalars, homogeneous arrays, nested namespaces).

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        An ``extra`` entry that is not a ROS parameter value or uses a reserved key.
    """
    path = Path(path)
    atomic_write(path, model_text(model))
    return path


def model_text(model: Model) -> str:
    """The model file's text (what :func:`save_model` writes and ``dampest/model`` carries)."""
    return ("# dampest_ros model: a ROS 2 parameters file (--ros-args --params-file).\n"
            "# Damping coefficients are positive when dissipative; M is row-major, FRD.\n"
            + yaml.dump({"/**": {"ros__parameters": {"model": _model_mapping(model)}}},
                        Dumper=_Dumper, sort_keys=False, default_flow_style=None, width=100))


def model_parameters(model: Model) -> dict[str, Any]:
    """The model as the ROS parameters a node declares from the model file (its ``extra``
    entries left out).

    Returns
    -------
    dict
        Dotted parameter name → value (``model.theta``: list of p floats, ``model.M``: 36
        floats, ``model.identified``: list of p bool, ``model.terms.cross.rows``: list of
        int, ``model.added_mass_terms.munk``: bool, …), the names and values
        ``--params-file`` gives for the file :func:`save_model` writes.
    """
    flat: dict[str, Any] = {}

    def walk(prefix: str, value: Any) -> None:
        if isinstance(value, Mapping):
            for k, v in value.items():
                walk(f"{prefix}.{k}", v)
        else:
            flat[prefix] = value

    walk("model", _model_mapping(replace(model, extra={})))
    return flat


def _model_mapping(m: Model) -> dict[str, Any]:
    """The ``model`` mapping of the file."""
    model: dict[str, Any] = {
        "sign_convention": SIGN_CONVENTION, "parameter_names": m.parameter_names,
        "theta": m.theta.tolist(), "theta_std": m.theta_std.tolist(),
        "identified": m.identified.tolist(), "M": m.M.reshape(36).tolist(),
        "version": m.version}
    if m.held:
        model["held"] = {"names": list(m.held), "reasons": list(m.held.values())}
    if m.M_A is not None:
        model["M_A"] = m.M_A.reshape(36).tolist()
    if m.added_mass_terms is not None:
        model["added_mass_terms"] = m.added_mass_terms.as_parameters()
    if m.damping is not None:
        model["terms"] = _terms_params(damping_spec(m.damping, m.theta))
    if m.identity is not None:
        model["identity"] = m.identity.as_dict()
    for key, value in m.extra.items():
        if key in _RESERVED:
            raise ValueError(f"extra key {key!r} is reserved")
        model[str(key)] = _param_value(str(key), value)
    return model


def model_section(doc: YamlDoc) -> tuple[KeyPath, dict[str, Any]]:
    """The key path and mapping of ``<node>: ros__parameters: model`` of a parameters file
    (the first node that has it; a vehicle's or an arm's model file).

    Raises
    ------
    InputError
        The file has no such mapping.
    """
    for key, node in (doc.data.items() if isinstance(doc.data, dict) else ()):
        params = node.get("ros__parameters") if isinstance(node, dict) else None
        if isinstance(params, dict) and isinstance(params.get("model"), dict):
            return (str(key), "ros__parameters", "model"), params["model"]
    raise doc.error([], "no <node>: ros__parameters: model: mapping; a model file starts "
                        "'/**: ros__parameters: model:' (dampest identify --out and the "
                        "estimator's ~/save write one)")


def load_model(path: str | Path) -> Model:
    """Read a model file written by :func:`save_model` (or by the estimator's ``~/save``).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Model

    Raises
    ------
    InputError
        A ConfigError naming the file, the line and the ``model.*`` entry with the fix: a
        duplicate key, a violation of the model schema (``dampest_ros/schemas/
        model.schema.json``: an unknown or misspelt key, a missing one, a wrong type), lists
        of unequal lengths, non-finite numbers, an arm's model file.
    OSError
        The file cannot be read.
    """
    return _model_from_doc(load_yaml(path, MODEL_KIND))


def loads_model(text: str) -> Model:
    """:func:`load_model` for the text of a model file (e.g. a ``dampest/model`` message)."""
    return _model_from_doc(loads_yaml(text, "<text>"))


def _plain(value: Any) -> Any:
    """A parameter value as YAML gives it: arrays (``array.array``, numpy) as lists."""
    return value.tolist() if hasattr(value, "tolist") else value


def model_from_parameters(values: Mapping[str, Any]) -> Model:
    """:func:`load_model` for the ``model.*`` parameters of a node.

    Parameters
    ----------
    values : mapping
        Dotted parameter name → value (as :func:`model_parameters` gives them); at least
        ``model.parameter_names``, ``theta``, ``theta_std``, ``M`` and ``version``.
        ``model.sign_convention`` defaults to the one the parameter contract states;
        without ``model.terms.*`` the structure is left to the caller (``damping`` None).

    Returns
    -------
    Model

    Raises
    ------
    InputError
        As :func:`load_model`, the source named ``<parameters>``.
    """
    model = {"sign_convention": SIGN_CONVENTION, **model_mapping(values)}
    return _model_from_doc(YamlDoc({"/**": {"ros__parameters": {"model": model}}},
                                   "<parameters>"))


def model_mapping(values: Mapping[str, Any]) -> dict[str, Any]:
    """The ``model`` mapping of a model file from dotted ``model.*`` parameters
    (``model.identity.name`` → ``{"identity": {"name": ...}}``; arrays as lists, other names
    left out)."""
    model: dict[str, Any] = {}
    for name, value in values.items():
        head, _, rest = name.partition(".")
        if head != "model" or not rest:
            continue
        *path, leaf = rest.split(".")
        node = model
        for key in path:
            node = node.setdefault(key, {})
        node[leaf] = _plain(value)
    return model


def _model_from_doc(doc: YamlDoc) -> Model:
    """The Model of a parsed parameters file, checked against the model schema."""
    where, model = model_section(doc)
    if model.get("kind") == _ARM_FILE_KIND:
        raise located(doc, where, ConfigError(
            "model.kind", f"{_ARM_FILE_KIND}: an arm's model file, not a vehicle's damping "
                          "model; give the vehicle's model file (dampest identify --out, "
                          "estimator ~/save)"))
    check(doc, "model", skip=2)
    try:
        return _model_from_mapping(model)
    except ConfigError as exc:
        raise located(doc, where, exc) from None


def located(doc: YamlDoc, where: KeyPath, exc: ConfigError) -> InputError:
    """A check's error on ``model.<field>`` of the model mapping at ``where`` (as
    :func:`model_section` gives it) with the file and the line of the entry."""
    path = [*where[:2], *exc.field.split(".")]
    return InputError(doc.source, doc.line(path), exc.field, exc.reason)


def _entry(model: Mapping[str, Any], key: str) -> Any:
    """The entry of ``model`` at the dotted ``key`` (``terms.cross.rows``), or None."""
    node: Any = model
    for part in key.split("."):
        node = node.get(part) if isinstance(node, Mapping) else None
    return node


def _same_length(model: Mapping[str, Any], keys: tuple[str, ...], n: int, what: str) -> None:
    """Refuse a list of ``model`` (dotted key) whose length is not ``n``."""
    for key in keys:
        node = _entry(model, key)
        if node is not None and len(node) != n:
            raise ConfigError(f"model.{key}", f"has {len(node)} entries for {n} {what}; give "
                                              f"one per entry of {what}")


def _model_from_mapping(model: Mapping[str, Any]) -> Model:
    """The Model of a ``model`` mapping that passed the model schema."""
    names = [str(n) for n in model["parameter_names"]]
    _same_length(model, ("theta", "theta_std", "identified"), len(names), "parameter_names")
    for first, others in (("terms.cross.rows", ("cols", "alphas", "names")),
                          ("terms.freq.dofs", ("rates",)), ("terms.point.axes", ("speeds",)),
                          ("held.names", ("reasons",))):
        group = first.rpartition(".")[0]
        found = _entry(model, first)
        if found is not None:
            _same_length(model, tuple(f"{group}.{k}" for k in others), len(found), first)
    axes = _entry(model, "terms.point.axes")
    if axes is not None:
        _same_length(model, ("terms.point.positions",), 3 * len(axes), "3 × terms.point.axes")
        turned = 3 * list(axes).count(3)
        if turned and _entry(model, "terms.point.directions") is None:
            raise ConfigError("model.terms.point.directions", f"missing: give {turned} numbers, "
                                                              "3 per terms.point.axes 3")
        _same_length(model, ("terms.point.directions",), turned, "3 × the terms.point.axes 3")
    modes = _entry(model, "terms.residual.modes")
    if modes is not None and len(modes) % 6:
        raise ConfigError("model.terms.residual.modes", f"has {len(modes)} numbers; give 6 "
                                                        "per mode (row-major)")
    arrays = {k: np.asarray(model[k], dtype=float) for k in ("theta", "theta_std", "M")}
    damping = None
    if "terms" in model:
        damping, _ = damping_from_spec(_spec_from_params(model["terms"]))
        if damping.parameter_names != names:
            raise ConfigError("model.terms", f"the terms give parameters "
                                             f"{damping.parameter_names}, not {names}; "
                                             "make parameter_names and terms agree")
    M_A, terms = _added_mass_entries(model)
    held = _held_entries(model, names)
    identity = Identity.from_dict(model["identity"]) if "identity" in model else None
    check_model_numbers(names, arrays["theta"], arrays["theta_std"], arrays["M"], held)
    return Model(names, arrays["theta"], arrays["theta_std"], arrays["M"].reshape(6, 6),
                 int(model["version"]), damping,
                 {k: v for k, v in model.items() if k not in _RESERVED}, M_A=M_A,
                 added_mass_terms=terms, held=held, identity=identity)


def _held_entries(model: Mapping[str, Any], names: list[str]) -> dict[str, str]:
    """The coefficients a model mapping marks as held at the prior, with the reason
    (``model.identified`` and ``model.held``; the ``unidentified`` lists of files written by
    earlier ``dampest identify`` versions; none without either)."""
    if "identified" not in model:
        old = [str(n) for n in model.get("unidentified", [])]
        if not old or old == ["none"]:
            return {}
        why = [str(r) for r in model.get("unidentified_reason", [])]
        if len(why) != len(old):
            why = ["not identified"] * len(old)
        return dict(zip(old, why, strict=True))
    given = model.get("held", {"names": [], "reasons": []})
    reasons = dict(zip(given["names"], given["reasons"], strict=True))
    held = {n: reasons.get(n, "held at the prior (the file gives no reason)")
            for n, ok in zip(names, model["identified"], strict=True) if not ok}
    extra = sorted(set(reasons) - set(held))
    if extra:
        raise ConfigError("model.held", f"{extra} are identified (model.identified) or not "
                                        "parameters of the model; delete them from held")
    return held


def _added_mass_entries(model: Mapping[str, Any]
                        ) -> tuple[FloatArray | None, AddedMassTerms | None]:
    """``model.M_A`` (6, 6) and ``model.added_mass_terms`` of a model mapping (checked)."""
    M_A = None
    if "M_A" in model:
        M_A = np.asarray(model["M_A"], dtype=float)
        if not np.all(np.isfinite(M_A)):
            raise ConfigError("model.M_A", "not finite; give 36 finite numbers")
        M_A = M_A.reshape(6, 6)
    terms = None
    if "added_mass_terms" in model:
        terms = AddedMassTerms.from_dict(model["added_mass_terms"])
        if not terms.all and M_A is None:
            raise ConfigError("model.M_A", f"missing: added_mass_terms {terms.as_dict()} turn "
                                           "effects off and need M_A to split M; add M_A")
    return M_A, terms


#: ``model.kind`` of an arm's model file (:mod:`dampest_ros.io.arm`); a vehicle's has none.
_ARM_FILE_KIND = "arm_base_parameters"


def foreign_model(path: str | Path, expected: Identity) -> str | None:
    """Why the file at ``path`` must not be replaced by a model of ``expected``: it holds a
    model of another vehicle or arm, or is not a model file (None: no file, one of
    ``expected``'s, or one without an identity of the same kind, which cannot be checked).

    Used by the nodes' ``~/save`` before they write; the reason names both owners and the fix.
    """
    path = Path(path)
    if not path.exists():
        return None
    try:
        _, model = model_section(load_yaml(path, MODEL_KIND))
        found = (Identity.from_dict(model["identity"], f" ({path})") if "identity" in model
                 else None)
    except (ConfigError, OSError) as exc:
        return f"{path} is not a model file ({exc}): move it away or set save_path elsewhere"
    if found is None:
        kind = ARM_KIND if model.get("kind") == _ARM_FILE_KIND else VEHICLE_KIND
        if kind == expected.kind:
            return None
        return (f"{path} holds a {kind} model, not one of {expected.kind} "
                f"{expected.label()}: set save_path to another file")
    why = mismatch(found, expected, str(path))
    return None if why is None else f"{why}; set save_path to another file"
