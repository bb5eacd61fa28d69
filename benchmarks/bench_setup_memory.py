"""Peak memory of a brain run's set-up, stage by stage, up to its first Newton iteration.

Runs the production code of ``brainbulge brain --flap left --swell both --tets N`` (the
case's defaults: from 400,000 tets Netgen at ``N / 8``, refined once, the Krylov solver)
until the load ramp calls Newton for the first time, and stops there. Each stage's peak
resident memory is measured on its own: the kernel's high-water mark (``VmHWM``) is reset
(``/proc/self/clear_refs`` 5) when a stage starts and read when it ends.

    python benchmarks/bench_setup_memory.py [--tets 1300000] [--refine 1] [--trace]
        [--outputs [--state RUN/fields.npz]]

Stages: the label image (the ICBM152 template), the intracranial envelope, Netgen's tets
(in a forked child, whose own memory is not in the table), the tissue tags and the
interfaces' fit (on the Netgen mesh), the uniform refinement, the labelled mesh (sides,
outer faces, base, flaps), the case's flap and skull, the NGSolve mesh, the problem (spaces
and regions), the mixed form, the Newton solver (the closed-form tangent's set-up) and the
ramp's start (feasibility check, the first load step). Columns: peak MB in the stage, RSS
MB at its end, seconds; with ``--trace`` what Python's ``tracemalloc`` sees live (NumPy's
arrays among it, not NGSolve's or Netgen's own memory) at the stage's peak and at its end.
The last lines give what must not change with a memory lever: the mesh's sizes and a hash
of its arrays.

With ``--outputs`` the run's outputs follow (``write_brain_outputs``, as after a converged
solve, the solver's memory released first): the recovered gradient, the fields at the
integration points, the summary (its parts), the vertex fields, the NIfTI maps, the figures
and files. The state is the displacement of a run's ``fields.npz`` (``--state``, at the
vertices: the same mesh, e.g. a run of the same command) or zero; the summary's numbers
are printed (with ``--state``, those of the run up to its bubbles and pressures).
"""

from __future__ import annotations

import argparse
import hashlib
import tempfile
from pathlib import Path

import numpy as np

from bench_newton_memory import PhasePeaks


class FirstNewton(Exception):
    """Raised when the load ramp calls Newton: the set-up is over."""


def mesh_hash(bm) -> str:
    """SHA-1 (12 hex digits) of the brain mesh's arrays: nodes, tets, tags, faces, flaps."""
    h = hashlib.sha1()
    for a in (bm.nodes_mm, bm.tets, bm.tissue, bm.side, bm.faces, bm.face_tet, bm.base,
              *(bm.flap_faces[k] for k in sorted(bm.flap_faces))):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:12]


#: the summary's numbers printed with ``--outputs``
SUMMARY_KEYS = ("max_displacement", "midline_shift_mm", "bulge_volume_ml",
                "max_principal_strain", "p95_principal_strain", "max_penetration_mm")


def outputs(peaks: PhasePeaks, case, bm, skull, form, state: Path | None, out: str) -> dict:
    """The run's outputs (``write_brain_outputs``) on ``form`` at full load, its
    displacement that of ``state`` (a ``fields.npz``) or zero; each part a stage."""
    import brainbulge.studies.craniectomy as craniectomy
    from brainbulge.geometry.ngsolve_arrays import vertex_dofs
    from brainbulge.solver.options import Solution, StepRecord
    from brainbulge.solver.strategy import free_solver_memory

    free_solver_memory()  # as after a solve
    form.set_load(1.0)
    x = form.gfu.components[0].vec.FV().NumPy()
    x[:] = 0.0
    if state is not None:
        x[vertex_dofs(form.fes.components[0], form.mesh)] = np.load(state)["point_u"]
    sol = Solution(form=form, load=1.0, converged=True,
                   steps=[StepRecord(1.0, 1, 0, 0.0, 0.0)], target_swelling=case.swelling)
    for name, label in [("recovered_gradient", "recovered gradient"),
                        ("point_fields", "fields at the integration points"),
                        ("solution_summary", "summary: percentiles, extremes"),
                        ("brain_outputs", "summary: brain measures"),
                        ("bulge_volume_ml", "summary: bulge volume"),
                        ("brain_extreme_sites", "summary: extreme sites"),
                        ("vertex_fields", "vertex fields"),
                        ("write_run_maps", "NIfTI maps"),
                        ("section_figure", "sections figure"),
                        ("write_surface_views", "surface views"),
                        ("atomic_write_json", "summary.json")]:
        peaks.wrap(craniectomy, name, label, "outputs, other")
    peaks.mark("outputs, other")
    run = craniectomy.BrainRun(case, bm, skull, form, sol)
    return craniectomy.write_brain_outputs(run, Path(out))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tets", type=int, default=1_300_000,
                    help="about how many tets (default 1300000, the paper's resolution)")
    ap.add_argument("--refine", type=int, default=None,
                    help="uniform refinements (default: the case's, 1 from 400000 tets)")
    ap.add_argument("--outputs", action="store_true",
                    help="also the outputs of the run, on the state of --state")
    ap.add_argument("--state", type=Path, default=None,
                    help="fields.npz of a run on the same mesh: its displacement")
    args, peaks = PhasePeaks.start(ap, "imports")

    import brainbulge.geometry.brain.brain_mesh as brain_mesh
    import brainbulge.geometry.brain.template as template
    import brainbulge.model.brain as model_brain
    import brainbulge.solver.ramp as ramp
    import brainbulge.solver.strategy as strategy
    import brainbulge.studies.craniectomy as craniectomy
    from brainbulge.cli.checks import brain_case

    config = {"flap": "left", "swell": "both", "tets": args.tets}
    if args.refine is not None:
        config["refine"] = args.refine
    case = brain_case(config)
    peaks.mark("case")
    stages = [  # (module or class, name, stage); each followed by "other"
        (template, "icbm152_tissue_image", "label image"),
        (brain_mesh, "intracranial_envelope", "envelope"),
        (brain_mesh, "mesh_intracranial_volume", "Netgen tets"),
        (brain_mesh, "_tissues", "tissue tags, interface fit"),
        (brain_mesh, "refined_on_envelope", "refinement"),
        (brain_mesh, "_labelled", "labelled mesh (sides, faces, flaps)"),
        (model_brain, "open_case_flap", "case flap"),
        (craniectomy, "case_skull", "skull"),
        (model_brain, "to_ngsolve", "NGSolve mesh"),
        (model_brain, "Problem", "problem"),
        (strategy, "MixedForm", "mixed form"),
        (ramp.NewtonSolver, "__init__", "Newton solver (closed-form set-up)"),
        (ramp, "check_feasible", "feasibility check"),
    ]
    for obj, name, label in stages:
        peaks.wrap(obj, name, label, "other")
    forms = []
    make_form = strategy.MixedForm

    def keep_form(*a, **kw):
        forms.append(make_form(*a, **kw))
        return forms[-1]

    strategy.MixedForm = keep_form

    def first_newton(self, *a, **kw):
        raise FirstNewton

    ramp.NewtonSolver.newton = first_newton
    bms = []
    open_flap = model_brain.open_case_flap

    def keep_mesh(bm, case):
        bms.append(bm)
        return open_flap(bm, case)

    model_brain.open_case_flap = keep_mesh
    skulls = []
    make_skull = craniectomy.case_skull

    def keep_skull(bm, case):
        skulls.append(make_skull(bm, case))
        return skulls[-1]

    craniectomy.case_skull = keep_skull
    with tempfile.TemporaryDirectory() as out:
        try:
            craniectomy.solve_brain(case, out)
        except FirstNewton:
            pass
        peaks.mark("end of set-up")
        summary = None
        if args.outputs:
            summary = outputs(peaks, case, bms[0], skulls[0], forms[0], args.state, out)
        peaks.mark("end")
    bm, form = bms[0], forms[0]
    print(f"{len(bm.tets):,} tets, {len(bm.nodes_mm):,} nodes, {len(bm.faces):,} outer "
          f"faces; {form.mesh.ne:,} NGSolve elements; mesh hash {mesh_hash(bm)}\n")
    rows, peaks.rows = peaks.rows, []
    for row in rows:  # the gaps between the stages, where they add anything
        if not row[0].endswith("other") or row[3] > 0.5 or row[1] > peaks.rows[-1][2] + 1:
            peaks.rows.append(row)
    print(peaks.table())
    if summary is not None:
        print("summary:", {k: summary[k] for k in SUMMARY_KEYS})


if __name__ == "__main__":
    main()
