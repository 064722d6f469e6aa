"""dampest export and dampest import: a model to and from simulator formats.

export writes a model file as gz-sim Hydrodynamics plugin tags (gz), a URDF <hydrodynamics>
block (urdf) or the UUV Simulator hydrodynamic plugin block of an SDF (uuv), converting signs
(SNAME, negative when dissipative) and, for gz, the frame (FRD to the link's FLU). import
reads any of the three back into a model file (the format the file holds, or --format),
through the same conversions in reverse. The conventions and where they come from:
dampest_ros/io/export/.

export refuses coefficients that the target would apply non-dissipatively at some speed
(simulators apply linear and |v|v terms at every speed, not only where the vehicle flew): exit
status 2, one line naming the coefficient and the speed where the damping turns, unless
--clamp (the nearest dissipative set, labelled in the file) or --force (as is, labelled NOT
DISSIPATIVE). The file labels every coefficient estimate, constrained (was ...) or held at
prior. Terms a format has no place for (element drags, library products, speed norms) are
written as the coefficients the format has that reproduce their force best over the flown
speeds, labelled as an approximation with the share of their force reproduced per DOF
(--no-refold: left out and listed, as fluid memory always is).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from dampest_ros.cli.common import check_outputs, describe
from dampest_ros.io.export import FORMATS, FRAMES, IMPORT_FORMATS

EXPORT_EXAMPLE = ("examples:\n"
                  "  dampest export model.yaml --format gz --vehicle bluerov2_heavy "
                  "--out hydrodynamics.sdf\n"
                  "  dampest export model.yaml --format uuv --vehicle bluerov2_heavy "
                  "--out uuv_hydrodynamics.sdf\n"
                  "  dampest export box_model.yaml --format urdf --vehicle box_rov "
                  "--no-refold\n"
                  "  dampest export arm_params.yaml --format mjcf --out arm.xml")
IMPORT_EXAMPLE = ("examples:\n  dampest import hydrodynamics.sdf --vehicle bluerov2_heavy "
                  "--out model.yaml\n"
                  "  dampest import uuv_hydrodynamics.sdf --format uuv --link-name "
                  "rexrov/base_link --vehicle bluerov2_heavy --out model.yaml\n"
                  "  dampest import arm.xml --format mjcf --arm ur5 --out arm_model.yaml")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of dampest export."""
    describe(p, __doc__, EXPORT_EXAMPLE)
    p.add_argument("model", metavar="MODEL",
                   help="model file (ROS 2 parameters YAML written by dampest)")
    p.add_argument("--format", required=True, choices=(*FORMATS, "mjcf"),
                   help="gz: Hydrodynamics plugin tags; urdf: <hydrodynamics> block; "
                        "uuv: UUV Simulator <plugin> with its <hydrodynamic_model> (SDF); "
                        "an arm's model file: mjcf or urdf (joint terms, link inertias)")
    p.add_argument("--arm", metavar="NAME|URDF",
                   help="an arm's model file: the arm it belongs to (default: its model.arm)")
    p.add_argument("--out", metavar="FILE", help="file to write (default: standard output)")
    p.add_argument("--vehicle", metavar="NAME|YAML",
                   help="vehicle preset name or YAML path; its rigid body gives the added "
                        "mass M_A = M - M_RB when the model file has no model.M_A (without "
                        "either: damping only)")
    p.add_argument("--link-name", default="base_link", metavar="LINK",
                   help="gz, uuv: the link the plugin acts on (default: base_link)")
    p.add_argument("--frame", choices=FRAMES, default="flu",
                   help="gz: frame of that link, flu (Gazebo/REP-103, default) or frd")
    folding = p.add_mutually_exclusive_group()
    folding.add_argument("--refold", dest="refold", action="store_const", const=True,
                         default=None,
                         help="write the terms the format cannot carry (element drags, "
                              "library products, speed norms) as the coefficients it can "
                              "that reproduce their force best over the flown speeds (least "
                              "squares); the file says so and gives the share of their force "
                              "reproduced per DOF. The default when the model file records "
                              "its flown speeds; with --refold a file without them is refused")
    folding.add_argument("--no-refold", dest="refold", action="store_const", const=False,
                         help="leave those terms out, listed in the file and on stderr")
    safety = p.add_mutually_exclusive_group()
    safety.add_argument("--clamp", action="store_true",
                        help="when the coefficients would make the target's damping "
                             "non-dissipative at some speed (simulators apply them at every "
                             "speed), write the nearest dissipative set instead; the file "
                             "says what was changed")
    safety.add_argument("--force", action="store_true",
                        help="write such coefficients as they are; the file says NOT "
                             "DISSIPATIVE beyond the speed where the damping turns")


def add_import_arguments(q: argparse.ArgumentParser) -> None:
    """The options of dampest import."""
    describe(q, __doc__, IMPORT_EXAMPLE)
    q.add_argument("file", metavar="FILE",
                   help="SDF/URDF/XML file holding the plugin or the block")
    q.add_argument("--format", choices=(*IMPORT_FORMATS, "mjcf"),
                   help="gz: a Hydrodynamics plugin; urdf: a <hydrodynamics> block; uuv: a "
                        "UUV Simulator <hydrodynamic_model> (default: the one the file "
                        "holds); with --arm: mjcf or urdf, an arm's joint terms and link "
                        "inertias")
    q.add_argument("--arm", metavar="NAME|URDF",
                   help="read an arm (its joints named as this preset's or URDF's) into an "
                        "arm model file")
    q.add_argument("--lock", default="", metavar="JOINT[,JOINT]",
                   help="with --arm: its joints held fixed at 0 (as identify --lock)")
    q.add_argument("--out", required=True, metavar="MODEL",
                   help="model file to write (YAML)")
    q.add_argument("--vehicle", metavar="NAME|YAML",
                   help="vehicle preset name or YAML path for the rigid body M_RB (needed "
                        "when the file has no mass and inertia) and the added mass when the "
                        "file has none")
    q.add_argument("--link-name", metavar="LINK",
                   help="gz: which plugin, uuv: which <link> to read when there are "
                        "several")
    q.add_argument("--frame", choices=FRAMES, default="flu",
                   help="gz: frame of the plugin's link, flu (default) or frd")


def run(args: argparse.Namespace) -> int:
    """Write the model in the format asked for; the warnings on stderr."""
    import warnings

    from dampest_ros.cli import export_arm
    from dampest_ros.cli.inputs import warn_unchecked
    from dampest_ros.io.export.arm import arm_of_model_file
    from dampest_ros.io.export.common import ExportWarning
    from dampest_ros.io.export.convert import export_model
    from dampest_ros.io.yaml_io import load_model, load_vehicle

    check_outputs(args, {"out": "hydrodynamics.sdf"})
    arm = arm_of_model_file(args.model)
    if arm is not None:
        return export_arm.run(args, *arm)
    if args.format == "mjcf" or args.arm:
        raise ValueError(f"{args.model} is not an arm model file: --format mjcf and --arm "
                         "export an arm's (dampest arm identify --out)")
    model = load_model(args.model)
    vehicle = load_vehicle(args.vehicle) if args.vehicle else None
    if vehicle is not None:
        warn_unchecked(model.belongs_to(vehicle.identity, str(args.model)))
    with warnings.catch_warnings():
        # the left-out list is printed below, once
        warnings.simplefilter("ignore", ExportWarning)
        result = export_model(model, args.format, vehicle, link_name=args.link_name,
                              frame=args.frame, source=str(args.model), force=args.force,
                              clamp=args.clamp, refold=args.refold)
    if args.out:
        Path(args.out).write_text(result.text, encoding="utf-8")
        print(f"wrote {args.out} ({args.format})", file=sys.stderr)
    else:
        sys.stdout.write(result.text)
    if vehicle is None and model.M_A is None:
        print("note: no --vehicle and no model.M_A, so no added mass was exported (damping "
              "only)",
              file=sys.stderr)
    for line in result.left_out:
        print(f"warning: left out {line}", file=sys.stderr)
    for line in result.held:
        print(f"warning: not identified, exported at its prior: {line}", file=sys.stderr)
    for line in result.non_dissipative:
        print(f"warning: not dissipative (--force): {line}", file=sys.stderr)
    for name, was in result.constrained.items():
        print(f"warning: constrained (--clamp): {name} = 0 (was {was:.6g})", file=sys.stderr)
    return 0


def run_import(args: argparse.Namespace) -> int:
    """Read the file's hydrodynamics into a model file."""
    import numpy as np

    from dampest_ros.cli import export_arm
    from dampest_ros.core.identification.model import Model
    from dampest_ros.io.export.common import imported_mass_parts
    from dampest_ros.io.export.convert import detect_format, import_model
    from dampest_ros.io.yaml_io import load_vehicle, save_model

    check_outputs(args, {"out": "model.yaml"})
    if args.arm:
        return export_arm.run_import(args)
    if args.format == "mjcf":
        raise ValueError("--format mjcf reads an arm: give the arm with --arm")
    vehicle = load_vehicle(args.vehicle) if args.vehicle else None
    fmt = args.format or detect_format(Path(args.file))
    imp = import_model(Path(args.file), fmt, frame=args.frame, link_name=args.link_name)
    M_RB, M_A, mass_notes = imported_mass_parts(imp, vehicle)
    terms = imp.added_mass_terms
    if vehicle is not None and imp.added_mass is None and (terms is None or terms.all):
        terms = vehicle.body.added_mass_terms  # the vehicle's added mass, with its switches
    damping = imp.damping()
    save_model(args.out, Model(
        imp.names, imp.theta, np.zeros(len(imp.names)), M_RB + M_A, damping=damping,
        extra={"source": f"dampest import {args.file} ({fmt})",
               "import_notes": "; ".join([*imp.notes, *mass_notes])},
        M_A=M_A, added_mass_terms=terms,
        identity=vehicle.identity if vehicle is not None else None))
    print(f"wrote {args.out}: {len(imp.names)} parameters from {args.file} ({fmt}); "
          + "; ".join(mass_notes))
    for note in imp.notes:
        print(f"note: {note}", file=sys.stderr)
    return 0
