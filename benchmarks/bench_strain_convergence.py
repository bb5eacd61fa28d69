"""Mesh convergence of the reported stretches and strains on a nested family of one geometry.

Run ``python benchmarks/bench_strain_convergence.py --mesh BRAIN.npz [--levels 2]
[--element taylor-hood --tolerance 3e-5] [--out ROWS.json]``: the brain mesh (a
``brain.npz`` of ``brainbulge mesh``) is refined uniformly
``levels - 1`` times with every child tet keeping its parent's tissue and side, and the new
surface nodes at their midpoints: every member has exactly the base mesh's geometry and tissue
interfaces, so the continuum problem is the same and only the discretisation changes. Each
member solves the left-flap, both-sided scenario (Js 1 -> 1.1), the load ramped on it (MINI:
PARDISO on the base, GMRES with AMG blocks on the finer members; Taylor-Hood: GMRES with its
two-level cycle, at ``--tolerance`` where it stalls above the default, known-limits.md). Per
member, the table gives the volume percentiles p95 / p99 of the maximum principal strain and of the
radial and tangential stretch over the parenchyma outside the 5 mm rim band, their maximum
there and the value they exceed in 0.1 ml of it (``peak``, as in the summaries), from the raw
element gradient ``Grad u`` and from the recovered gradient (``results.measures.recovery``,
what the summaries report), and the change from the previous member in per cent.

A 2-core machine affords two members from a ~20k-tet base (about 21k and 168k tets); the
next (1.35M) needs ~10 GB and about an hour.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def refined_family_member(bm, times: int):
    """``bm`` refined uniformly ``times`` times, children keep their parents' tissue, side;
    flaps re-tagged on the new surface (which is the old one: midpoints stay)."""
    from brainbulge.geometry.brain.boundaries import boundary_faces
    from brainbulge.geometry.brain.brain_mesh import BrainMesh, refined_on_envelope

    nodes, tets, parent = refined_on_envelope(bm.nodes_mm, bm.tets, bm.envelope, times,
                                              move=False)
    tissue, side = bm.tissue[parent], bm.side[parent]
    faces, face_tet = boundary_faces(tets)
    base = nodes[faces][:, :, 2].mean(axis=1) < bm.base_z_mm
    out = BrainMesh(nodes, tets, tissue, side, faces, face_tet, base, bm.base_z_mm,
                    bm.envelope, voxel_volumes_ml=bm.voxel_volumes_ml,
                    midsagittal=bm.midsagittal)
    for flap in bm.flaps.values():
        out.add_flap(flap)
    return out


FIELDS = {"max_principal_strain": "strain", "lambda_n": "lambda_n", "lambda_t": "lambda_t"}


def percentiles(form, bm, case, recovered: bool) -> dict[str, float]:
    """p95 / p99 of the FIELDS over parenchyma integration points outside the rim band."""
    import re

    from brainbulge.results.measures.fields import output_fields, sample
    from brainbulge.results.measures.quadrature import quadrature_points
    from brainbulge.results.measures.recovery import recovered_gradient
    from brainbulge.results.measures.summary import exceeded_in, weighted_percentiles
    from brainbulge.studies.craniectomy import PARENCHYMA, PEAK_VOLUME_ML

    q = quadrature_points(form.mesh, order=4)
    G = recovered_gradient(form.mesh, form.output_displacement()) if recovered else None
    rx = re.compile(f"^(?:{PARENCHYMA})$")
    mask = form.mesh.MaterialCF({r: 1.0 for r in set(form.mesh.GetMaterials()) if rx.match(r)},
                                default=0.0)
    keep = q(mask) > 0.5
    flap = bm.flaps[case.flap]
    skull = bm.skull(case.flap, edge_radius_mm=case.edge_radius_mm)
    d_cut, _ = flap.cutter_distance(q.X)
    near = np.abs(d_cut) < case.edge_exclusion_mm
    phi, _ = skull.envelope_distance(q.X[near], gradient=False)
    band = np.zeros(len(q.X), dtype=bool)
    band[near] = np.hypot(d_cut[near], phi) < case.edge_exclusion_mm
    keep &= ~band
    out: dict[str, float] = {}
    values = {k: [] for k in FIELDS}
    chunk = 1_000_000
    for a in range(0, len(q.X), chunk):
        f = output_fields(sample(form, q.points[a:a + chunk], gradient=G),
                          bm.envelope.centre_mm())
        for k in FIELDS:
            values[k].append(f[k])
    w = q.weights[keep]
    for k, short in FIELDS.items():
        v = np.concatenate(values[k])[keep]
        p95, p99 = weighted_percentiles(v, w, (95, 99))
        out[f"p95 {short}"], out[f"p99 {short}"] = float(p95), float(p99)
        out[f"max {short}"] = float(v.max())
        out[f"peak {short}"] = exceeded_in(v, w, PEAK_VOLUME_ML * 1e3)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mesh", required=True, help="base brain.npz")
    parser.add_argument("--levels", type=int, default=2)
    parser.add_argument("--steps", type=int, default=4)
    parser.add_argument("--element", choices=("mini", "taylor-hood"), default="mini")
    parser.add_argument("--tolerance", type=float, default=1e-9,
                        help="Newton's tolerance (Taylor-Hood on the brain: 3e-5)")
    parser.add_argument("--out", help="write the rows as JSON here after every member")
    args = parser.parse_args()

    from brainbulge.geometry.brain import load_brain_mesh
    from brainbulge.model.brain import CraniectomyCase, brain_problem
    from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions

    base = load_brain_mesh(Path(args.mesh))
    case = CraniectomyCase(flap="left", swell="both", swelling=1.1, steps=args.steps)
    rows = []
    for level in range(args.levels):
        t0 = time.perf_counter()
        bm = refined_family_member(base, level)
        form = MixedForm(brain_problem(bm, case), element=args.element, compile_energy=True)
        direct = level == 0 and args.element == "mini"
        solver = NewtonSolver(form, SolverOptions(
            steps=case.steps, tolerance=args.tolerance,
            linear_solver="pardiso" if direct else "krylov"))
        sol = solver.solve()
        solver.release_linear_solver()
        del solver
        row = {"tets": len(bm.tets), "converged": sol.converged,
               "solve s": time.perf_counter() - t0}
        for recovered in (False, True):
            tag = "recovered" if recovered else "raw"
            row.update({f"{k} {tag}": v for k, v in
                        percentiles(form, bm, case, recovered).items()})
        rows.append(row)
        if args.out:
            Path(args.out).write_text(json.dumps(rows, indent=1))
        print(f"level {level}: {row['tets']} tets, converged {sol.converged}, "
              f"{row['solve s']:.0f} s", flush=True)
    keys = [k for k in rows[0] if k.split()[0] in ("p95", "p99", "peak", "max")]
    print("\nchange from the previous member: of the value; for stretches also of lambda - 1")
    print("\n| quantity | " + " | ".join(f"{r['tets']:,} tets" for r in rows) + " |")
    print("|---" * (len(rows) + 1) + "|")
    for k in keys:
        cells = [f"{rows[0][k]:.4f}"]
        for prev, r in zip(rows, rows[1:], strict=False):
            change = f"{100 * (r[k] - prev[k]) / abs(prev[k]):+.1f} %"
            if "lambda" in k:
                change += f", {100 * (r[k] - prev[k]) / abs(prev[k] - 1.0):+.1f} % of l-1"
            cells.append(f"{r[k]:.4f} ({change})")
        print(f"| {k} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
