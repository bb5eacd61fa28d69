"""``brainbulge mesh``: a labelled tetrahedral brain mesh from MRI labels (docs/model.md section 6).

Without ``--labels`` the ICBM152 2009a template that nilearn ships is used. Writes
``brain.vtu``, ``brain.xdmf``, ``brain.npz`` (fast reload), ``mesh.json`` (sizes, volumes,
quality, flap areas), ``sections.png`` and ``boundaries.png`` into ``--out``.
"""

from __future__ import annotations

import argparse
from typing import Any

from brainbulge.errors import InputError
from brainbulge.geometry.brain.defaults import VOLUME_OF
from brainbulge.model.brain_case import TETS_FLOOR_TEXT, TETS_RANGE

FLAPS = ("frontal", "left", "right", "custom")
#: the ``[mesh]`` table of the run file: key -> the option it records
CONFIG_OPTIONS = {"labels": "--labels", "label_map": "--label-map", "tets": "--tets",
                  "brain_volume_ml": "--brain-volume", "flap": "--flap",
                  "flap_centre_mm": "--flap-centre", "flap_diameter_mm": "--flap-diameter",
                  "base_z_mm": "--base-z", "csf_layer_mm": "--csf-layer", "refine": "--refine"}


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``mesh`` subcommand."""
    from brainbulge.cli import add_output_options, positive_float, whole_number

    p = subparsers.add_parser(
        "mesh", help="labelled tet mesh of a brain from MRI labels", description=__doc__
    )
    p.add_argument("--labels", help="NIfTI label map (.nii/.nii.gz); default: ICBM152 template")
    p.add_argument(
        "--label-map",
        default=None,
        help="preset (freesurfer, aseg, synthseg, gmwmcsf) or JSON file of --labels "
        '{"gray": [codes], "white": [...], "csf": [...], "cerebellum": [...], '
        '"brainstem": [...]} (default freesurfer)',
    )
    p.add_argument("--tets", type=whole_number("--tets"), default=100_000,
                   help=f"about how many tets (default 1e5; {TETS_FLOOR_TEXT}; at most "
                   f"{TETS_RANGE[1]})")
    p.add_argument("--brain-volume", type=positive_float("--brain-volume"), default=None,
                   metavar="ML", help="scale the head so that the --volume-of volume is this "
                   "[ml] (the paper's brain, gray + white matter: 1108)")
    p.add_argument("--volume-of", choices=VOLUME_OF, default="intracranial",
                   help="what --brain-volume sets: the intracranial volume (incl. CSF, the "
                   "default), the brain (cerebral gray + white matter) or the white matter")
    p.add_argument("--flap", choices=FLAPS, default=None,
                   help="flap tagged in the VTU/XDMF boundary codes (all are in mesh.json)")
    p.add_argument("--flap-centre", type=float, nargs=3, metavar=("X", "Y", "Z"),
                   help="centre of the custom flap on the skull [mm, world RAS]")
    p.add_argument("--flap-diameter", type=positive_float("--flap-diameter"), default=120.0,
                   help="custom flap diameter [mm] (default 120)")
    p.add_argument("--base-z", type=float, default=None,
                   help="cut plane of the fixed base [mm, world z] (default: 12%% of the height)")
    p.add_argument("--csf-layer", type=float, default=1.5,
                   help="CSF layer between brain and skull [mm] (default 1.5)")
    p.add_argument("--refine", type=int, default=0, metavar="K",
                   help="mesh at tets / 8^K, then refine uniformly K times (0-3; default 0)")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    add_output_options(p, "brain-mesh")
    p.set_defaults(func=run)
    return p


def run(args: argparse.Namespace) -> int:
    """Build, save and summarise the mesh; returns the exit code."""
    import math

    from brainbulge.cli import checks, finish_run, start_run
    from brainbulge.geometry.brain import build_brain_mesh, load_tissue_image, save_brain_mesh

    if args.flap == "custom" and args.flap_centre is None:
        raise InputError("--flap custom needs --flap-centre X Y Z (mm on the skull)")
    if args.label_map is not None and args.labels is None:
        raise InputError("--label-map describes the codes of --labels; give --labels too, or "
                         "drop --label-map")
    args.label_map = args.label_map or "freesurfer"
    if not 0 <= args.csf_layer <= 10:
        raise InputError(f"--csf-layer {args.csf_layer} mm must lie in [0, 10] mm")
    if args.base_z is not None and not math.isfinite(args.base_z):
        raise InputError(f"--base-z {args.base_z} must be a finite height [mm, world z]")
    checks.flap_centre(args.flap_centre)
    image = load_tissue_image(args.labels, args.label_map) if args.labels else None
    checks.mesh_tets(args.tets, args.refine, template=args.labels is None,
                     labelled_ml=sum(image.volumes_ml().values()) if image else None)
    config = {"command": "mesh", "mesh": {key: getattr(args, opt[2:].replace("-", "_"))
                                          for key, opt in CONFIG_OPTIONS.items()}}
    if args.labels is None:  # the template's labels are built in
        config["mesh"]["label_map"] = None
    out = start_run(args, config)
    mesh = build_brain_mesh(
        image, target_tets=args.tets, brain_volume_ml=args.brain_volume, volume_of=args.volume_of,
        csf_layer_mm=args.csf_layer, base_z_mm=args.base_z,
        custom_flap_centre_mm=tuple(args.flap_centre) if args.flap_centre else None,
        custom_flap_diameter_mm=args.flap_diameter, refinements=args.refine,
    )
    save_brain_mesh(mesh, out, flap=args.flap, figures=not args.no_figures)
    q = mesh.quality()
    areas = ", ".join(f"{n} {mesh.flap_area_cm2(n):.0f} cm2" for n in mesh.flaps)
    finish_run(out)
    print(f"{q['tets']:,} tets, {q['nodes']:,} nodes, min dihedral {q['min_dihedral_deg']:.1f} "
          f"deg, volume {mesh.tet_volumes_mm3().sum() / 1000:.0f} ml; flaps: {areas}")
    return 0
