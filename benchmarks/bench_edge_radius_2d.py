"""The 2D headline on the rounded skull edge: its dependence on the edge radius and the mesh.

For the headline case (alpha 80, beta 60, Js 1.2), each contact condition and each edge
radius ``rho`` (``--radii``, in R) on the product's half domain, and at ``rho = 0.03`` R also
on the mesh ``h/1.5`` and on the full domain (``full_domain``, the check): Newton
iterations, the top-of-bulge displacement ``u_y(0, R)`` [R], the largest crossing into the
rounded skull [R], where the material corner (at rest on the edge at 60 deg) ends [deg from
the axis, R], and the edge-excluded maxima of the radial and tangential stretch. The last
line extrapolates ``u_y`` linearly in ``rho`` to ``rho = 0`` from the two smallest radii.

Rerun: ``python benchmarks/bench_edge_radius_2d.py`` (about 5 min on 2 cores alone).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np


def run(contact: str, rho: float, h: float, element: str, full: bool = False) -> dict:
    from brainbulge.geometry.ngsolve_arrays import vertex_coordinates
    from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem
    from brainbulge.results.measures.summary import solution_summary
    from brainbulge.solver import MixedForm, NewtonSolver
    from brainbulge.studies.hemidisk import skull_crossing

    case = HemidiskCase(contact=contact, skull_edge_radius=rho, mesh_size=h, element=element,
                        full_domain=full)
    start = time.perf_counter()
    form = MixedForm(hemidisk_problem(case), element=element)
    sol = NewtonSolver(form, case.solver_options()).solve()
    wall = time.perf_counter() - start
    mesh = form.mesh
    X = vertex_coordinates(mesh)
    x = X + np.array([form.u(mesh(*p)) for p in X])
    t = math.radians(90 - case.beta / 2)  # on both domains
    corner = int(np.argmin(np.linalg.norm(X - [math.cos(t), math.sin(t)], axis=1)))
    s = solution_summary(sol, np.zeros(2), case.geometry.singular_points(),
                         case.edge_exclusion * case.R)
    return {"contact": contact, "rho": rho, "h": h, "converged": sol.converged,
            "domain": "half" if case.half else "full",
            "newton": sol.newton_iterations, "wall": wall,
            "u_top": float(form.u(mesh(0.0, case.R * (1 - 1e-9)))[1]),
            "crossing": skull_crossing(case, form, x),
            "corner_deg": 90 - math.degrees(math.atan2(x[corner, 1], x[corner, 0])),
            "corner_r": float(np.linalg.norm(x[corner])),
            "lambda_n": s["max_radial_stretch"], "lambda_t": s["max_tangential_stretch"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--radii", type=float, nargs="+", default=[0.05, 0.03, 0.015])
    ap.add_argument("--h", type=float, default=0.05)
    ap.add_argument("--element", default="taylor-hood", choices=("mini", "taylor-hood"))
    a = ap.parse_args()
    rows = []
    for contact in ("sliding", "noslip"):
        for rho in a.radii:
            rows.append(run(contact, rho, a.h, a.element))
        rows.append(run(contact, 0.03, a.h / 1.5, a.element))
        rows.append(run(contact, 0.03, a.h, a.element, full=True))
    print(f"element {a.element}\n")
    print("| contact | domain | rho [R] | h [R] | Newton | u_y top [R] | crossing [R] | corner "
          "[deg, R] | max lambda_n | max lambda_t | wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        state = "" if r["converged"] else " (stopped)"
        print(f"| {r['contact']}{state} | {r['domain']} | {r['rho']:g} | {r['h']:.4g} | "
              f"{r['newton']} | "
              f"{r['u_top']:.5f} | {r['crossing']:.1e} | {r['corner_deg']:.2f}, "
              f"{r['corner_r']:.4f} | {r['lambda_n']:.4f} | {r['lambda_t']:.4f} | "
              f"{r['wall']:.1f} |")
    for contact in ("sliding", "noslip"):
        half = [r for r in rows if r["contact"] == contact and r["domain"] == "half"]
        by = sorted((r["rho"], r["u_top"]) for r in half if r["h"] == a.h)
        (r1, u1), (r2, u2) = by[0], by[1]
        u0 = u1 - r1 * (u2 - u1) / (r2 - r1)
        fine = next(r["u_top"] for r in half if r["h"] != a.h)
        coarse = next(r["u_top"] for r in half if r["h"] == a.h and r["rho"] == 0.03)
        full = next(r["u_top"] for r in rows if r["contact"] == contact
                    and r["domain"] == "full")
        print(f"\n{contact}: u_y extrapolated to rho = 0: {u0:.5f} R; h / (h/1.5) at rho "
              f"0.03: {abs(fine / coarse - 1):.3%}; half / full domain: "
              f"{abs(full / coarse - 1):.3%}")


if __name__ == "__main__":
    main()
