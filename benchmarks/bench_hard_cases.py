"""Hard-case benchmark: the contact cases that stall, per case and per contact formulation.

Prints one row per (case, formulation): converged, load reached, Newton iterations, rejected
load steps, wall time of the solve, and the case's headline output (2D: the vertical
displacement's largest vertical component ``max u_y`` [R]; 3D: bulge volume and Monro shift).

2D cases (plane strain, the paper's skull: the arc ``r = R`` outside the opening):
alpha 80 / beta 30 and alpha 60 / beta 30, sliding and no-slip, and the headline alpha 80 /
beta 60. Formulations compared for sliding contact (``--variants``):

- ``production``: the product's path, ``brainbulge hemidisk`` at its defaults: the skull's
  edge rounded inside the bone, one penalty contact on the whole material arc (docs/model.md
  section 10). The variants below are on the paper's sharp edge.
- ``released``: the gap is the signed distance to the skull's region
  ``S = {r >= R, |delta| >= beta/2}`` (the arc and, past its edge, the edge's outward ray),
  so that a point that slides past the edge is released continuously; exact multipliers
  (the product's primal-dual active set), no rezoning.
- ``released-per-solve``: the held arc inside each Newton solve; between solves, points that
  have slid past the edge are released (multiplier set to zero, gap to ``S`` from then on);
  at full load, release and re-solve until no point is held past the edge. No rezoning.
- ``released-opening``: as ``released-per-solve``, and the opening's boundary also in contact
  with ``S`` (tissue may not fold back over the skull's edge).
- ``edge`` / ``edge-smooth``: as ``released-per-solve`` with the released points free (the
  zero-thickness skull ends at its edge), and the skull's two edge points kept outside the tissue by
  segment contact (:mod:`edge_contact`), so that the edge cannot cut into the tissue
  between two nodes; ``edge-smooth`` against the boundary with interpolated vertex normals
  (C1), ``edge-hermite`` against cubic Hermite segments through the vertices (C1
  positions, closest-point projection), ``edge-vertex`` as ``edge-smooth`` with the gap
  near a boundary vertex blended into that vertex's normal gap (``--blend``: the parameter
  distance, default ``VertexEdgeContact.blend``). No rezoning, no hotspot relaxation.
- ``edge-offset`` / ``edge-vertex-offset``: ``edge-smooth`` / ``edge-vertex`` on a mesh
  whose opening break points sit half a corner element inside the opening
  (:func:`offset_mesh`), so that no boundary vertex starts at the skull's edge (the held /
  free split goes by the points' angles, not by the boundary labels, so it is unchanged).

``--tolerance`` sets Newton's tolerance for the variants (default 1e-9, the product's). A
variant's row (``--one``) also gives the edge points' smallest gap at the end, the
parameter ``xi`` of their projections on their segments, and the solution's asymmetry: the
largest difference of ``u_y`` between mirrored vertices, relative to the largest ``|u|``
(``asymmetry_far``: outside the edge-exclusion disks around the edges).

3D rows (:mod:`bench_hard_cases_3d`; with any of them the 2D cases run only if ``--cases``
names some): ``--3d``, the six craniectomy scenarios on the demo's 21k-tet brain;
``--flap``, the planner's 80 mm flap at its one-centre placement on the 111k-tet template;
``--edge-radius``, a 2 mm edge at 111k tets, the load ramped; ``--taylor-hood``, the six
scenarios with Taylor-Hood at 21k tets (``--th-scenarios`` picks some); ``--long``,
Taylor-Hood at 175k tets and the default scenario at 1.40M tets (hours). They print
converged, load, Newton and GMRES iterations, the final scaled residual, solve and run time,
peak memory, bulge volume, Monro shift and (planner) strained volume.

Rerun with ``python benchmarks/bench_hard_cases.py`` (the 2D rows, about 25 min on 2
cores); ``--3d`` about 2 min; ``--flap`` about 9 min; ``--edge-radius`` about 12 min;
``--taylor-hood --th-scenarios left-flap_both-swelling`` over 70 min per scenario,
stalling (``--time-limit S`` stops each run and reports its log) (measured beside other
work, 2-3x the times alone; building the 111k- and 20k-tet meshes adds about 5 min
once: ``--cache DIR`` keeps them; ``--keep DIR`` keeps the runs' outputs). Each
row runs in its own process, with ``OMP_NUM_THREADS=1`` unless set.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import bench_hard_cases_3d as h3

CASES_2D = {
    "a80b30": (80.0, 30.0),
    "a60b30": (60.0, 30.0),
    "a80b60": (80.0, 60.0),
}
#: 3D case (:data:`bench_hard_cases_3d.RUNS`) -> the flag's attribute that selects it
THREE_D_FLAGS = {"study": "three_d", "flap": "flap", "edge-radius": "edge_radius",
                 "taylor-hood": "taylor_hood", "long": "long"}
VARIANTS = ("production", "released", "released-per-solve", "released-opening", "edge",
            "edge-smooth", "edge-hermite", "edge-offset", "edge-vertex", "edge-vertex-offset")
#: how far the ``-offset`` meshes move the opening's break points into the opening, in
#: corner element sizes: half an element, so that the edge point starts mid-segment
OFFSET_CORNERS = 0.5


# --- the skull region S and its signed distance ---------------------------------------
def region_gap(R: float, beta_deg: float, center_deg: float, x: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance ``g`` to ``S = {r >= R, |delta| >= beta/2}`` (positive outside
    ``S``) and its gradient, at points ``x`` (n, 2) [length, -].

    Outside ``S`` on the skull's side, ``g = R - r`` (the arc); in the opening's cone the
    nearest point of ``S`` is on the edge's ray ``{t e, t >= R}``, the corner included;
    inside ``S``, ``-min(r - R, distance to the ray's line)``.
    """
    th = math.radians(center_deg)
    c, s = math.cos(th), math.sin(th)
    xr = x[:, 0] * c + x[:, 1] * s
    yr = -x[:, 0] * s + x[:, 1] * c
    sign = np.where(yr < 0, -1.0, 1.0)
    ya = np.abs(yr)
    r = np.hypot(xr, ya)
    half = math.radians(beta_deg) / 2
    ex, ey = math.cos(half), math.sin(half)
    t = np.maximum(xr * ex + ya * ey, R)
    dx, dy = xr - t * ex, ya - t * ey
    d_ray = np.hypot(dx, dy)
    safe_r, safe_d = np.maximum(r, 1e-300), np.maximum(d_ray, 1e-300)
    arc_nx, arc_ny = -xr / safe_r, -ya / safe_r
    cone = np.arctan2(ya, xr) < half
    g = np.where(cone, d_ray, R - r)
    nx = np.where(cone, dx / safe_d, arc_nx)
    ny = np.where(cone, dy / safe_d, arc_ny)
    ray = ~cone & (r > R) & (t > R) & (d_ray < r - R)
    g = np.where(ray, -d_ray, g)
    nx, ny = np.where(ray, -dx / safe_d, nx), np.where(ray, -dy / safe_d, ny)
    corner = cone & (d_ray < 1e-8 * R)  # at the corner: the arc's normal
    nx, ny = np.where(corner, arc_nx, nx), np.where(corner, arc_ny, ny) * sign
    return g, np.column_stack([nx * c - ny * s, nx * s + ny * c])


def in_cone(R: float, beta_deg: float, center_deg: float, x: np.ndarray,
            margin: float = -1e-9) -> np.ndarray:
    """Whether points ``x`` (n, 2) lie at the opening's angles (widened by ``margin``
    [rad]: positive takes in the material corners at the edges' angles)."""
    th = math.radians(center_deg)
    xr = x[:, 0] * math.cos(th) + x[:, 1] * math.sin(th)
    yr = -x[:, 0] * math.sin(th) + x[:, 1] * math.cos(th)
    return np.abs(np.arctan2(yr, xr)) < math.radians(beta_deg) / 2 + margin


def offset_mesh(case):
    """The case's mesh with the opening's break points (and their refinement) moved into the
    opening by :data:`OFFSET_CORNERS` corner element sizes, so that no boundary vertex lies
    at the skull's edge angle (an ``ngs.Mesh``). The opening's label then starts inside the
    opening; the held/free split of the sliding variants goes by angle, not by label."""
    import dataclasses

    shift = math.degrees(OFFSET_CORNERS * case.corner_h / case.R)
    geo = dataclasses.replace(case.geometry, beta_deg=case.beta - 2 * shift)
    return geo.mesh(case.mesh_size * case.R, case.corner_h, case.rim_h,
                    case.edge_exclusion * case.R)


def edge_points(R: float, beta_deg: float, center_deg: float) -> np.ndarray:
    """The skull's two sharp edges (2, 2) [length]."""
    th = math.radians(center_deg) + np.array([-1.0, 1.0]) * math.radians(beta_deg) / 2
    return R * np.column_stack([np.cos(th), np.sin(th)])


# --- one 2D run -----------------------------------------------------------------------
def run_2d_production(alpha: float, beta: float, contact: str) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "brainbulge", "hemidisk", "--alpha", str(alpha),
                        "--beta", str(beta), "--contact", contact, "--out", tmp,
                        "--overwrite"], capture_output=True)
        wall = time.perf_counter() - t0
        s = json.loads((Path(tmp) / "summary.json").read_text())
    return {"converged": bool(s.get("converged", True)), "load": s["load_reached"],
            "newton": s["newton_iterations"], "rejected": s["rejected_steps"],
            "rezones": s["rezones"], "wall_s": wall, "solve_s": s["wall_time_s"],
            "top_uy": s.get("max_vertical_displacement")}


def run_2d_variant(alpha: float, beta: float, contact: str, variant: str,
                   tolerance: float = 1e-9, blend: float | None = None) -> dict:
    """A formulation of :data:`VARIANTS` other than production, in this process (it
    replaces the point contacts' gap evaluation); ``tolerance``: Newton's, on the scaled
    residual; ``blend``: the ``edge-vertex`` variants' (default
    ``VertexEdgeContact.blend``)."""
    from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem
    from brainbulge.model.problem import Contact
    from brainbulge.solver import ramp
    from brainbulge.solver.contact import points
    from brainbulge.solver.mixed import MixedForm
    from brainbulge.solver.options import SolverOptions
    from brainbulge.solver.ramp import NewtonSolver

    case = HemidiskCase(alpha=alpha, beta=beta, contact=contact, full_domain=True)
    arc = case.skull_arc
    geo = (arc.R, arc.beta_deg, arc.center_deg)
    per_solve = variant != "released"

    def gaps(x: np.ndarray, released: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if not per_solve:
            return region_gap(*geo, x)
        g, n = arc.gap_and_normal(x)
        if released.any():
            if variant.startswith("edge"):
                g[released] = np.inf
            else:
                g[released], n[released] = region_gap(*geo, x[released])
        return g, n

    def update(self, x: np.ndarray) -> None:
        if not hasattr(self, "released"):
            # with the edge points in contact the material corners are theirs: held by
            # both, their two constraints would be one row twice
            self.released = in_cone(*geo, self.X, 1e-9 if variant.startswith("edge") else -1e-9)
        self.x = self.X + (self.P @ x).reshape(self.n_points, self.dim)
        g, self.n = gaps(self.x, self.released)
        self.g = g - self.g0

    def hessian(self, on: np.ndarray) -> np.ndarray:
        x, rel, d = self.x[on], self.released[on], 1e-3 * self.form.h
        H = np.empty((len(x), self.dim, self.dim))
        for k in range(self.dim):
            e = np.zeros(self.dim)
            e[k] = d
            H[:, :, k] = (gaps(x + e, rel)[1] - gaps(x - e, rel)[1]) / (2 * d)
        return 0.5 * (H + H.transpose(0, 2, 1))

    points.PointContact.update = update
    points.PointContact.hessian = hessian
    ramp.check_feasible = lambda solver: None  # the opening's points are off S at rest
    problem = hemidisk_problem(case, offset_mesh(case) if variant.endswith("offset") else None)
    if variant == "released-opening":
        problem.contacts = [Contact("skull|opening", arc)]
    form = MixedForm(problem, element=case.element)
    edges = variant.startswith("edge")
    if edges:
        from edge_contact import EdgeContact, SmoothEdgeContact, VertexEdgeContact
        from hermite_edge_contact import HermiteEdgeContact

        kind = {"edge-smooth": SmoothEdgeContact, "edge-offset": SmoothEdgeContact,
                "edge-vertex": VertexEdgeContact, "edge-vertex-offset": VertexEdgeContact,
                "edge-hermite": HermiteEdgeContact}.get(variant, EdgeContact)
        form.point_contacts.append(kind(form, "skull|opening", edge_points(*geo)))
        if blend is not None and kind is VertexEdgeContact:
            form.point_contacts[-1].blend = blend
    # (no hotspot relaxation with edge points: its local problems know vertex points only)
    solver = NewtonSolver(form, SolverOptions(steps=case.steps, tolerance=tolerance,
                                              hotspot_relaxation=not edges))
    if edges:
        solver.equations.contact.moving[-1][:] = True

    def release(x) -> int:
        n = 0
        for pc in form.point_contacts:
            if not hasattr(pc, "released"):
                continue  # the edge points
            pc.update(x.FV().NumPy())
            new = in_cone(*geo, pc.x) & ~pc.released
            pc.released |= new
            pc.lam[new] = 0.0
            n += int(new.sum())
        return n

    newton = solver.newton
    if per_solve:
        def released_newton(x, *args, **kwargs):
            release(x)
            return newton(x, *args, **kwargs)
        solver.newton = released_newton
    t0 = time.perf_counter()
    sol = solver.solve()
    outer = 0
    while per_solve and sol.converged and outer < 20 and release(form.gfu.vec):
        outer += 1
        ok, its, _ = newton(form.gfu.vec)
        sol.steps[-1].newton_iterations += its
        sol.converged = ok
    wall = time.perf_counter() - t0
    mesh = form.mesh
    X = np.array([v.point for v in mesh.vertices])
    u = np.array([form.u(mesh(*p)) for p in X])
    uy = u[:, 1].max()
    # symmetry about the opening's axis (x = 0 for the centred opening): u_y at mirrored
    # vertices (those a corner element inside the circle, whose mirror images lie in the
    # mesh), relative to the largest |u|
    inner = X[np.hypot(X[:, 0], X[:, 1]) < case.R - case.corner_h]
    du = [abs(form.u(mesh(*p))[1] - form.u(mesh(-p[0], p[1]))[1]) for p in inner]
    asym = float(max(du) / np.linalg.norm(u, axis=1).max())
    asym_at = [float(v) for v in inner[int(np.argmax(du))]]
    far = np.min([np.linalg.norm(inner - e, axis=1) for e in edge_points(*geo)], axis=0)
    asym_far = float(max(np.compress(far > case.edge_exclusion * case.R, du))
                     / np.linalg.norm(u, axis=1).max())
    row = {"converged": sol.converged, "load": sol.load, "newton": sol.newton_iterations,
           "rejected": sol.rejected_steps, "rezones": 0, "wall_s": wall, "solve_s": wall,
           "top_uy": float(uy), "outer": outer, "asymmetry": asym, "asymmetry_far": asym_far,
           "asymmetry_at": asym_at}
    if sol.failure_site is not None:  # where the failed solve's force residual peaks
        row["failure_site"] = [float(v) for v in sol.failure_site]  # deformed [length]
    if edges:  # the edge points' smallest gap to the deformed tissue (< 0: inside it)
        edge = form.point_contacts[-1]
        edge.update(form.gfu.vec.FV().NumPy())
        row["edge_gap"] = float(edge.g.min())
        if hasattr(edge, "_quad"):  # where on its segment each edge point projects
            from edge_contact import _projection

            row["edge_xi"] = [_projection(C, edge.pos[edge._quad(int(s))].ravel())
                              for C, s in zip(edge.C, edge.seg, strict=True)]
    return row


def selected(args: argparse.Namespace) -> tuple[list[str], list[str]]:
    """The 2D cases and the 3D cases (keys of :data:`bench_hard_cases_3d.RUNS`) that the
    flags select: the 2D cases run when asked for (``--cases``) or when no 3D case is."""
    three = [case for case, flag in THREE_D_FLAGS.items() if getattr(args, flag)]
    two = args.cases if args.cases is not None else ([] if three else list(CASES_2D))
    return two, three


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", default=None, choices=list(CASES_2D),
                    help="2D cases (default: all, unless a 3D case is asked for)")
    ap.add_argument("--contacts", nargs="+", default=["sliding", "noslip"])
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    ap.add_argument("--3d", dest="three_d", action="store_true", help="the six 3D scenarios")
    ap.add_argument("--tolerance", type=float, default=1e-9,
                    help="Newton's tolerance on the scaled residual (the variants)")
    ap.add_argument("--blend", type=float, default=None,
                    help="the edge-vertex variants' blend (parameter distance from a vertex)")
    ap.add_argument("--flap", action="store_true", help="the planner's 80 mm flap, 111k tets")
    ap.add_argument("--edge-radius", action="store_true",
                    help="a 2 mm edge at 111k tets, the load ramped")
    ap.add_argument("--taylor-hood", action="store_true",
                    help="the six scenarios with Taylor-Hood at 21k tets")
    ap.add_argument("--th-scenarios", nargs="+", default=list(h3.SCENARIO_NAMES),
                    choices=h3.SCENARIO_NAMES, help="the Taylor-Hood rows' scenarios")
    ap.add_argument("--long", action="store_true",
                    help="Taylor-Hood at 175k and the 1.40M-tet default (hours)")
    ap.add_argument("--cache", type=Path, default=None,
                    help="folder of the 3D rows' meshes, kept (default: a temporary one)")
    ap.add_argument("--keep", type=Path, default=None,
                    help="folder for the 3D runs' outputs, kept (default: temporary)")
    ap.add_argument("--time-limit", type=float, default=None, metavar="S",
                    help="stop each 3D run after S seconds (SIGTERM) and report its log")
    ap.add_argument("--one", nargs=4, help=argparse.SUPPRESS)  # ALPHA BETA CONTACT VARIANT
    return ap


def main() -> None:
    args = parser().parse_args()
    if args.one:
        alpha, beta, contact, variant = args.one
        print(json.dumps(run_2d_variant(float(alpha), float(beta), contact, variant,
                                        args.tolerance, args.blend)))
        return
    cases_2d, cases_3d = selected(args)
    if cases_2d:
        print("| case | contact | formulation | converged | load | Newton | rejected | "
              "rezones | solve s | max u_y |")
        print("|---|---|---|---|---|---|---|---|---|---|")
    for name in cases_2d:
        alpha, beta = CASES_2D[name]
        for contact in args.contacts:
            for variant in args.variants:
                if contact == "noslip" and variant != "production":
                    continue  # the release concerns sliding only
                if variant == "production":
                    row = run_2d_production(alpha, beta, contact)
                else:
                    done = subprocess.run(
                        [sys.executable, __file__, "--one", str(alpha), str(beta), contact,
                         variant, "--tolerance", str(args.tolerance)]
                        + ([] if args.blend is None else ["--blend", str(args.blend)]),
                        capture_output=True, text=True)
                    lines = done.stdout.strip().splitlines()
                    if done.returncode or not lines:
                        print(f"| {name} | {contact} | {variant} | error: "
                              f"{done.stderr.strip().splitlines()[-1:]} |")
                        continue
                    row = json.loads(lines[-1])
                top = row["top_uy"]
                print(f"| {name} | {contact} | {variant} | {row['converged']} | "
                      f"{row['load']:.3f} | {row['newton']} | {row['rejected']} | "
                      f"{row['rezones']} | {row['solve_s']:.1f} | "
                      f"{'-' if top is None else f'{top:.4f}'} |", flush=True)
    if not cases_3d:
        return
    print(f"\n{h3.HEADER}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        cache, keep = args.cache or Path(tmp) / "meshes", args.keep or Path(tmp) / "runs"
        for run in h3.runs_for(cases_3d, args.th_scenarios):
            folder = keep / f"{run.case}_{run.variant}".replace(" ", "-")
            folder.parent.mkdir(parents=True, exist_ok=True)
            cache.mkdir(parents=True, exist_ok=True)
            for r in h3.run_3d(run, folder, cache, args.time_limit):
                print(h3.format_row(r), flush=True)


if __name__ == "__main__":
    main()
