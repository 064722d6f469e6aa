"""dampest export and import of an arm: an arm model file to MJCF or URDF with its identified
joint terms and link inertias, and such a file back into an arm model file (what each part
of the file is: dampest_ros/io/export/arm.py)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def run(args: argparse.Namespace, arm_name: str, lock: tuple[str, ...]) -> int:
    """Write the arm model file ``args.model`` (of ``arm_name``, or ``--arm``, its joints
    ``lock`` held fixed) as MJCF or URDF."""
    from dampest_ros.io.arm import arm_files, load_arm, load_arm_model
    from dampest_ros.io.export.arm import (
        consistent_full,
        export_mjcf,
        export_urdf,
        exported_arm,
    )

    if args.format not in ("mjcf", "urdf"):
        raise ValueError(f"{args.model} is an arm model file: --format mjcf or urdf, not "
                         f"{args.format}")
    name = args.arm or arm_name
    desc = load_arm(name, lock=lock)
    est = load_arm_model(args.model)
    if est.joint_names != desc.model.names:
        raise ValueError(f"{args.model} holds the joints {list(est.joint_names)}, not those "
                         f"of {name}; give the arm it was identified on with --arm")
    exp = exported_arm(desc, est, consistent_full(args.model, desc.model))
    text = (export_mjcf(exp, Path(name).stem, str(args.model)) if args.format == "mjcf"
            else export_urdf(exp, arm_files(name)[0], str(args.model)))
    if args.out:
        Path(args.out).write_text(text, encoding="utf-8")
        print(f"wrote {args.out} ({args.format})", file=sys.stderr)
    else:
        sys.stdout.write(text)
    for note in exp.notes:
        print(f"note: {note}", file=sys.stderr)
    return 0


def run_import(args: argparse.Namespace) -> int:
    """Read an arm's MJCF or URDF into an arm model file (its base parameters, σ 0, nothing
    marked identified: a description, not a measurement)."""
    from dampest_ros.io.arm import joint_list, load_arm, save_arm_model
    from dampest_ros.io.export.arm import import_arm, imported_estimate

    if args.format not in ("mjcf", "urdf"):
        raise ValueError("--arm reads an arm: give --format mjcf or urdf"
                         + (f", not {args.format}" if args.format else ""))
    lock = joint_list(args.lock)
    desc = load_arm(args.arm, lock=lock)
    arm, dyn = import_arm(args.file, args.format, desc)
    est = imported_estimate(arm, dyn, desc)
    save_arm_model(args.out, est, str(args.arm),
                   {"source": f"dampest import {args.file} ({args.format})",
                    **({"lock": list(lock)} if lock else {})})
    print(f"wrote {args.out}: {len(est.theta)} base parameters of {args.arm} from {args.file} "
          f"({args.format})")
    return 0
