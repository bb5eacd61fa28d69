"""``brainbulge hemidisk``: one 2D hemidisk case (docs/model.md sections 4-5)."""

from __future__ import annotations

import argparse
from typing import Any

from brainbulge.cli import add_output_options, finish_run, progress_bar, start_run


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "hemidisk", help="a swelling sector or disk bulging through an opening", description=__doc__
    )
    p.add_argument("--alpha", type=float, default=80.0, help="swelling sector angle [deg]")
    p.add_argument("--beta", type=float, default=60.0, help="opening angle [deg]")
    p.add_argument(
        "--opening-center",
        type=float,
        default=90.0,
        help="angle of the opening's centre [deg] (90 = symmetry axis)",
    )
    p.add_argument(
        "--disk",
        type=float,
        nargs=3,
        metavar=("CX", "CY", "RADIUS"),
        help="a swelling disk instead of a sector (units of R)",
    )
    p.add_argument(
        "--swelling",
        type=float,
        default=None,
        help="target Js (default 1.2 for a sector, 1.3 for a disk)",
    )
    p.add_argument("--contact", choices=("sliding", "noslip"), default="sliding")
    p.add_argument(
        "--skull",
        choices=("paper", "rigid"),
        default="paper",
        help="paper: the paper's zero-thickness skull arc with a sharp edge, the opening "
        "traction-free (default); rigid: a rigid shell of finite thickness with rounded cut "
        "edges, also in contact with the opening (an extension, docs/model.md)",
    )
    p.add_argument("--radius", type=float, default=1.0, help="hemidisk radius R [length]")
    p.add_argument("--mesh-size", type=float, default=0.05, help="element size [units of R]")
    p.add_argument(
        "--corner-mesh-size",
        type=float,
        default=None,
        help="element size at the singular points [units of R] (default h/5)",
    )
    p.add_argument(
        "--rim-mesh-size",
        type=float,
        default=None,
        help="element size on the circles of radius --edge-exclusion around the singular "
        "points, where the max_*/min_* extremes sit [units of R] (default h/10)",
    )
    p.add_argument("--steps", type=int, default=4, help="initial number of load steps")
    p.add_argument("--element", choices=("mini", "taylor-hood"), default="mini",
                   help="MINI (P1 + bubble / P1, the default) or Taylor-Hood (P2/P1)")
    p.add_argument("--material", default="paper", help="tissue preset: paper or paper-pa")
    p.add_argument(
        "--edge-exclusion",
        type=float,
        default=0.05,
        help="radius around singular points left out of max_*/min_* [units of R]",
    )
    p.add_argument(
        "--skull-edge-radius",
        type=float,
        default=0.05,
        help="rounding radius of the rigid skull's cut edge (--skull rigid) [units of R]",
    )
    p.add_argument(
        "--rezone",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="remesh through the deformation when the deformed mesh degenerates or a load "
        "step fails (docs/design.md)",
    )
    add_output_options(p, "hemidisk-out")
    p.set_defaults(func=run_command)


def config_from_args(args: argparse.Namespace) -> dict[str, Any]:
    disk = list(args.disk) if args.disk else None
    swelling = args.swelling if args.swelling is not None else (1.3 if disk else 1.2)
    return {
        "alpha": None if disk else args.alpha,
        "beta": args.beta,
        "opening_center": args.opening_center,
        "disk": disk,
        "swelling": swelling,
        "contact": args.contact,
        "skull": args.skull,
        "R": args.radius,
        "mesh_size": args.mesh_size,
        "corner_mesh_size": args.corner_mesh_size,
        "rim_mesh_size": args.rim_mesh_size,
        "steps": args.steps,
        "element": args.element,
        "material": args.material,
        "edge_exclusion": args.edge_exclusion,
        "skull_edge_radius": args.skull_edge_radius,
        "rezone": args.rezone,
    }


def run_command(args: argparse.Namespace) -> int:
    from brainbulge.cli.checks import hemidisk_case

    return run_case(args, hemidisk_case(config_from_args(args)))  # checked before --out


def run_case(args: argparse.Namespace, case: Any) -> int:
    from brainbulge.model.hemidisk import SOLVER_FIELDS
    from brainbulge.model.problem import case_tables
    from brainbulge.studies.hemidisk import run_hemidisk

    config = {"command": "hemidisk", **case_tables(case, SOLVER_FIELDS)}
    out = start_run(args, config)
    summary = run_hemidisk(case, out, progress=progress_bar())
    finish_run(out)
    print(
        f"max |u| = {summary['max_displacement']:.4g} R, lambda_n in "
        f"[{summary['min_radial_stretch']:.4f}, {summary['max_radial_stretch']:.4f}], "
        f"lambda_t in [{summary['min_tangential_stretch']:.4f}, "
        f"{summary['max_tangential_stretch']:.4f}], penetration "
        f"{summary['max_penetration']:.2g} R"
    )
    return 0
