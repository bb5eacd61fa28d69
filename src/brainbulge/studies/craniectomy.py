"""The 3D craniectomy (docs/model.md section 6): one scenario, and the paper's six as a study.

``run_brain(case, out_dir)`` solves one scenario and writes ``summary.json``, ``fields.vtu``
(ParaView: every output of docs/model.md section 3 plus region and contact status), ``fields.npz``,
``maps/`` (NIfTI maps on the grid of the label image the mesh came from,
:mod:`~brainbulge.results.export.nifti`), ``sections.png`` (transverse and sagittal sections
through the flap centre, fixed colour ranges) and ``surface.png`` / ``surface.npz`` (the
deformed surface seen from above and from the flap, :mod:`~brainbulge.results.present.views3d`).
A run that stops early keeps the last
converged state on disk, marked ``"converged": false``, and raises
:class:`~brainbulge.errors.ConvergenceError`. While it runs, ``restart.npz`` holds the state
after the last accepted load step: the same scenario run again into the same directory (after
a kill, or the end of a batch job's time) resumes from there; the file is removed when the
run completes.

Clinical metrics (lengths mm, volumes ml, stresses kPa), named for what they are
(:mod:`brainbulge.results.measures.brain_summary`; every key in docs/outputs.md):

- ``midline_shift_mm``: the lateral displacement of the mid-sagittal parenchyma at the level
  of the foramen of Monro, positive towards the patient's right; the largest at any height
  is ``max_midline_displacement_mm``;
- ``bulge_volume_ml``: tissue volume outside the intact skull surface (through the flap);
- ``swelling_volume_ml``: added volume ``int (Js - 1) dV``; ``white_matter_volume_ml``: the
  reference volume of the swelling white matter; ``brain_volume_ml``;
- ``mean_hydrostatic_stress_kpa``: the volume mean of ``-p`` over the parenchyma (a tissue
  stress, not an intracranial pressure) and its ratio to the shear modulus.

Stretch and strain extremes are taken over the parenchyma (gray and white matter,
cerebellum, brainstem) outside a band of ``edge_exclusion_mm`` around the flap rim, where the
stress is singular; ``raw_*`` over all parenchyma, ``csf_*`` over the CSF filler. The
extremes sit at tissue interfaces (singular too) and grow under refinement; the volume
percentiles ``p95_*``/``p99_*``/``p05_*``/``p01_*`` over the same points are the
mesh-convergent measures, and ``peak_*`` (the value exceeded in ``PEAK_VOLUME_ML`` of that
tissue) the peaks to compare between meshes (docs/outputs.md).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import logging
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from brainbulge.errors import ConvergenceError, InputError
from brainbulge.geometry.brain import BrainMesh
from brainbulge.model.brain import (
    SWELL_SIDES,
    CraniectomyCase,
    brain_mesh_for,
    brain_problem,
    case_skull,
    size_defaults,
)
from brainbulge.model.problem import case_from_config
from brainbulge.results.export.writers import (
    VertexFields,
    add_contact_fields,
    save_vertex_fields,
    vertex_fields,
    write_vtu,
)
from brainbulge.results.measures.brain_metrics import brain_volume_ml, bulge_volume_ml
from brainbulge.results.measures.brain_summary import add_deprecated_aliases, brain_outputs
from brainbulge.results.measures.extreme_sites import brain_extreme_sites
from brainbulge.results.measures.recovery import recovered_gradient
from brainbulge.results.measures.summary import PointFields, point_fields, solution_summary
from brainbulge.results.present.sections import plot_sections, section_centre_mm
from brainbulge.results.present.views3d import write_surface_views
from brainbulge.results.records.run_record import atomic_write_json, atomic_write_text
from brainbulge.solver import MixedForm, Solution, SolverOptions, Strategy, solve

log = logging.getLogger("brainbulge")

#: the parenchyma: where axons are and tissue extremes are taken
PARENCHYMA = "(gray|white|cerebellum|brainstem)_(left|right)"
#: ``peak_*`` of the summaries: the value a stretch or strain exceeds in this much tissue (ml)
PEAK_VOLUME_ML = 0.1
#: fixed colour ranges of the section figures, so that scenarios compare
SECTION_RANGES = {
    "|u|": (0.0, 8.0),
    "max principal strain": (0.0, 0.3),
    "lambda_n": (0.8, 1.2),
    "lambda_t": (0.8, 1.2),
}
#: the folder of a run's NIfTI maps
MAPS_FOLDER = "maps"
SCENARIOS = [
    (flap, swell) for flap in ("left", "frontal") for swell in ("both", "left", "right")
]


def case_from_dict(config: dict[str, Any]) -> CraniectomyCase:
    """A :class:`CraniectomyCase` from a plain dict (TOML table, CLI, study scenario)."""
    return case_from_config(CraniectomyCase, config, "brain")


def run_brain(
    config: dict[str, Any] | CraniectomyCase,
    out_dir: Path,
    progress: bool = False,
    brain_mesh: BrainMesh | None = None,
) -> dict[str, Any]:
    """Solve one 3D scenario; write its files into ``out_dir``; return the summary.

    ``brain_mesh`` is used instead of loading or building the case's mesh."""
    run = solve_brain(config, out_dir, progress, brain_mesh)
    return write_brain_outputs(run, out_dir)


@dataclasses.dataclass
class BrainRun:
    """A solved 3D scenario: its case, mesh, rigid skull (the one of the run, made once),
    form and solution; ``started``: ``True`` when Newton converged from a given start state
    (``solve_brain(start=...)``), ``False`` when it did not and the load was ramped from
    ``Js = 1``, None without a start."""

    case: CraniectomyCase
    bm: BrainMesh
    skull: Any
    form: MixedForm
    sol: Any
    started: bool | None = None


def solve_brain(
    config: dict[str, Any] | CraniectomyCase,
    out_dir: Path,
    progress: bool = False,
    brain_mesh: BrainMesh | None = None,
    start=None,
) -> BrainRun:
    """Solve one 3D scenario (``restart.npz`` in ``out_dir`` while the load ramps).

    ``start(form) -> bool``: set the form's state to a start at full load (e.g. the solution
    of another flap on this mesh) and say whether it did; Newton then converges from there
    (:mod:`brainbulge.solver.warm_start`), and ramps the load from ``Js = 1`` if that fails.
    Not used with a restart file (the ramp goes on); the solver chooses
    (:class:`~brainbulge.solver.strategy.Strategy`)."""
    case = config if isinstance(config, CraniectomyCase) else case_from_dict(dict(config))
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    bm = brain_mesh if brain_mesh is not None else brain_mesh_for(case)
    skull = case_skull(bm, case)
    problem = brain_problem(bm, case, skull)
    restart = out_dir / "restart.npz"
    inputs = {k: v for k, v in dataclasses.asdict(case).items()
              if k != "steps"}
    mesh_hash = hashlib.sha1(np.ascontiguousarray(bm.nodes_mm).tobytes()
                             + np.ascontiguousarray(bm.tets).tobytes()).hexdigest()
    key = json.dumps([inputs, mesh_hash], sort_keys=True, default=str)
    options = SolverOptions(steps=case.steps, tolerance=case.tolerance, progress=progress,
                            linear_solver=case.linear_solver, checkpoint=restart,
                            checkpoint_key=key)

    sol = solve(problem, Strategy.from_problem(
        problem, options, element=case.element, compile_energy=case.compile, start=start))
    if sol.converged:
        restart.unlink(missing_ok=True)
    return BrainRun(case, bm, skull, sol.form, sol, sol.started)


def write_brain_outputs(
    run: BrainRun,
    out_dir: Path,
    extra: dict[str, Any] | None = None,
    measures: Callable[[PointFields], dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """Write the files of a solved scenario into ``out_dir`` (``summary.json`` last, with
    ``extra`` keys added, and those of ``measures`` of the summary's sampled fields, e.g. a
    plan's damage measures); return the summary; raise :class:`ConvergenceError` if it
    stopped before full load."""
    case, bm, form, sol = run.case, run.bm, run.form, run.sol
    out_dir = Path(out_dir)
    fibres = _fibres(case, bm)
    G = recovered_gradient(form.mesh, form.output_displacement())  # one projection for all
    points = point_fields(form, bm.envelope.centre_mm(), fibres, G)
    summary = brain_summary(case, bm, sol, points, run.skull)
    summary.update(extra or {})
    if measures is not None:
        summary.update(measures(points))
    del points  # the outputs' largest arrays, gone before the vertex fields
    from brainbulge.results.export.nifti import map_fields

    vf = vertex_fields(form, bm.envelope.centre_mm(), fibres=fibres, gradient=G,
                       corners=map_fields() if bm.image_grid is not None else ())
    add_contact_fields(vf, form)
    state = "" if sol.converged else f" (stopped at Js = {sol.swelling_reached:.3f})"
    # the field files are compressed (zlib, outside the GIL) while the figures are drawn:
    # at 1.40M tets 9 s of compression, ~10 s of drawing
    with ThreadPoolExecutor(max_workers=1) as files:
        written = [files.submit(write_vtu, out_dir / "fields.vtu", vf),
                   files.submit(save_vertex_fields, out_dir / "fields.npz", vf)]
        write_run_maps(run, vf, out_dir / MAPS_FOLDER)
        section_figure(vf, bm, case, out_dir / "sections.png", title=f"{case.name}{state}")
        write_surface_views(vf, bm, case.flap, out_dir, title=f"{case.name}{state}")
        for file in written:
            file.result()
    atomic_write_json(out_dir / "summary.json", summary)
    if not sol.converged:
        raise ConvergenceError(f"{sol.message}; partial results in {out_dir}")
    return summary


def brain_summary(
    case: CraniectomyCase,
    bm: BrainMesh,
    sol: Solution,
    points: PointFields | None = None,
    skull: Any = None,
) -> dict[str, Any]:
    """``summary.json`` of a 3D scenario (see the module docstring); ``points``: the
    state's fields at the integration points (:func:`~brainbulge.results.measures.summary.
    point_fields`), if the caller has them (default: sampled here, radial axons);
    ``skull``: the run's rigid skull (default: made here, :func:`case_skull`)."""
    form = sol.form
    skull = skull if skull is not None else case_skull(bm, case)
    flap = bm.flaps[case.flap]
    band = case.edge_exclusion_mm

    def near_rim(X: np.ndarray) -> np.ndarray:
        """Within ``band`` of the flap rim: the cutter surface meets the skull surface."""
        d_cut, _ = flap.cutter_distance(X)
        near = np.abs(d_cut) < band  # the skull's spline only there: hypot(d, phi) >= |d|
        phi_env, _ = skull.envelope_distance(X[near], gradient=False)
        out = np.zeros(len(X), dtype=bool)
        out[near] = np.hypot(d_cut[near], phi_env) < band
        return out

    out: dict[str, Any] = {
        "case": case.name,
        "inputs": dataclasses.asdict(case),
        **solution_summary(
            sol, bm.envelope.centre_mm(), [], 0.0, near_singular=near_rim,
            tissue=PARENCHYMA, peak_volume=PEAK_VOLUME_ML * 1000.0, points=points,
        ),
    }
    # the report's name for the CSF strain (None when the mesh has no CSF)
    out["csf_max_principal_strain"] = out.get("max_csf_principal_strain")
    out["edge_exclusion_mm"] = band
    out.pop("edge_exclusion", None)
    out.pop("singular_points", None)
    out["swelling_reached"] = sol.swelling_reached
    # vertex displacements
    u = _vertex_displacements(form, bm)
    out.update(brain_outputs(bm, form, u, PARENCHYMA, SWELL_SIDES[case.swell], skull))

    def outside(x: np.ndarray) -> np.ndarray:
        return np.minimum(skull.envelope_distance(x, gradient=False)[0],
                          -skull.signed_distance(x, gradient=False)[0])

    out["bulge_volume_ml"] = bulge_volume_ml(bm.nodes_mm, bm.tets, u, outside)
    out["brain_volume_ml"] = brain_volume_ml(bm.nodes_mm, bm.tets)
    out["deformed_volume_ml"] = brain_volume_ml(bm.nodes_mm, bm.tets, u)
    out["swelling_volume_ml"] = out.pop("swelling_volume") / 1000.0
    out["flap_nominal_area_cm2"] = bm.flap_area_cm2(case.flap)
    out["flap_area_cm2"] = bm.free_area_cm2(case.flap, skull=skull)
    out["max_hydrostatic_stress_kpa"] = out.pop("max_pressure")
    out["min_hydrostatic_stress_kpa"] = out.pop("min_pressure")
    out["max_penetration_mm"] = out["max_penetration"]
    if points is not None:
        out.update(brain_extreme_sites(bm, case.flap, skull, SWELL_SIDES[case.swell], band,
                                       PARENCHYMA, points, u, PEAK_VOLUME_ML * 1000.0))
    return add_deprecated_aliases(out)


def write_run_maps(run: BrainRun, vf: VertexFields, folder: Path) -> dict[str, Path]:
    """The NIfTI maps of a solved scenario (:mod:`~brainbulge.results.export.nifti`) on the
    grid of the label image its mesh came from; none (with a warning) for a mesh that does
    not know that grid (a ``brain.npz`` written before meshes kept it)."""
    from brainbulge.geometry.brain.labels import TEMPLATE_SOURCE
    from brainbulge.results.export.nifti import write_maps

    grid = run.bm.image_grid
    if grid is None:
        log.warning("no NIfTI maps: the mesh does not record the label image it came from; "
                    "rebuild it with `brainbulge mesh` to get them")
        return {}
    background = None
    if grid.source == TEMPLATE_SOURCE:
        from nilearn import datasets

        background = datasets.load_mni152_template(resolution=1)
    elif Path(grid.source).is_file():
        background = grid.source  # the user's label image
    return write_maps(vf, grid, folder, background=background)


def _fibres(case: CraniectomyCase, bm: BrainMesh):
    """Axon directions of ``case.fibres`` (None: radial from the brain's centre)."""
    if case.fibres is None:
        return None
    from brainbulge.geometry.brain.fibres import FibreField

    return FibreField(case.fibres, bm.envelope.centre_mm())


def _vertex_displacements(form: MixedForm, bm: BrainMesh) -> np.ndarray:
    """``u`` at the brain mesh nodes (mm): the P1 vertex values (NGSolve keeps the order)."""
    from brainbulge.geometry.ngsolve_arrays import vertex_dofs

    x = form.gfu.components[0].vec.FV().NumPy()
    return x[vertex_dofs(form.fes.components[0], form.mesh)]


def section_figure(
    vf: VertexFields, bm: BrainMesh, case: CraniectomyCase, path: Path, title: str = ""
) -> Path:
    """Transverse and sagittal sections through the flap centre, in colour ranges fixed
    across runs (:data:`SECTION_RANGES`, stretches centred on 1) so that sections of
    different runs compare; the figure's title states them."""
    pd = vf.point_data
    fields = {
        "|u|": pd["u_magnitude"],
        "max principal strain": pd["max_principal_strain"],
        "lambda_n": pd["lambda_n"],
        "lambda_t": pd["lambda_t"],
    }
    fixed = ", ".join(f"{name} {lo:g}-{hi:g}" for name, (lo, hi) in SECTION_RANGES.items())
    note = f"colour ranges fixed across runs: {fixed}"
    return plot_sections(
        vf.points, vf.cells, pd["u"], fields, section_centre_mm(bm, case.flap), path,
        ranges=SECTION_RANGES, title=f"{title}\n({note})" if title else note
    )


# --- study ------------------------------------------------------------------------------
def craniectomy_scenarios(**common: Any) -> list[dict[str, Any]]:
    """The six scenarios {left unilateral, frontal} x {both, left, right}."""
    return [
        {"name": f"{flap}-flap_{swell}-swelling", **common, "flap": flap, "swell": swell}
        for flap, swell in SCENARIOS
    ]


def study_task(scenario: dict[str, Any], scenario_dir: Path) -> dict[str, Any]:
    """Runner task: one 3D scenario (``name`` is the folder, the rest the case). The
    scenarios of a study share their meshes: a worker reads each ``brain.npz`` once."""
    config = dict(scenario)
    mesh = _cached_brain_mesh(str(config["mesh"])) if config.get("mesh") else None
    summary = run_brain(config, scenario_dir, brain_mesh=mesh)
    return {k: v for k, v in summary.items() if k != "inputs"}


@functools.lru_cache(maxsize=2)
def _cached_brain_mesh(path: str) -> BrainMesh:
    from brainbulge.geometry.brain import load_brain_mesh

    return load_brain_mesh(path)


#: the scenario options that shape the mesh (fixed by ``mesh`` once it is built)
MESH_OPTIONS = ("tets", "labels", "label_map", "brain_volume_ml", "volume_of",
                "flap_centre_mm", "flap_diameter_mm", "refine")


def prepare_study_mesh(out_dir: Path, common: dict[str, Any], folder: str = "mesh") -> Path:
    """Build the study's brain mesh once (``out_dir/folder/brain.npz``); reuse it on resume."""
    from brainbulge.geometry.brain import save_brain_mesh

    path = Path(out_dir) / folder / "brain.npz"
    if common.get("mesh"):
        return Path(common["mesh"])
    keys = MESH_OPTIONS
    spec = {k: common.get(k) for k in keys}
    spec["refine"] = spec["refine"] or None  # 0 and absent alike: a mesh made before --refine
    spec = json.loads(json.dumps(spec))  # tuples -> lists, as read back
    spec_path = path.parent / "spec.json"
    if path.is_file():
        stored = json.loads(spec_path.read_text()) if spec_path.is_file() else spec
        if {k: stored.get(k) for k in keys} != spec:
            raise InputError(
                f"the study's mesh {path} was built for {spec_path.read_text().strip()}; "
                "resume with the same mesh options or pass --overwrite"
            )
        return path
    case = case_from_dict({k: v for k, v in common.items() if k != "mesh"})
    bm = brain_mesh_for(case)
    save_brain_mesh(bm, path.parent)
    atomic_write_text(spec_path, json.dumps(spec))
    return path


def attach_study_meshes(out_dir: Path, scenarios: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The scenarios with the study's shared mesh attached: ``mesh`` (built once from the
    first scenario's mesh options, which are then dropped)."""
    if not scenarios[0].get("mesh"):  # the defaults of the requested size, for all
        scenarios = [with_size_defaults(sc) for sc in scenarios]
    common = scenarios[0]
    mesh = prepare_study_mesh(out_dir, common)
    shared: dict[str, Any] = {"mesh": str(mesh)}
    return [{**{k: v for k, v in sc.items() if k not in MESH_OPTIONS}, **shared}
            for sc in scenarios]


def with_size_defaults(scenario: dict[str, Any]) -> dict[str, Any]:
    """``scenario`` with ``refine`` and ``linear_solver`` of its size
    (:func:`~brainbulge.model.brain.size_defaults`) where it does not give them."""
    refine, solver = size_defaults(
        scenario.get("tets", CraniectomyCase.tets), scenario.get("refine"),
        scenario.get("linear_solver"))
    return {**scenario, "refine": refine, "linear_solver": solver}


def run_study_with_report(out_dir: Path, scenarios: list[dict[str, Any]],
                          scheduler: str | None = None, workers: int | None = None) -> int:
    """Run the scenarios on their shared meshes (:func:`attach_study_meshes`), then write
    ``table.csv``, ``comparison.png`` and ``report.md``; return how many completed."""
    from brainbulge.studies.runner import run_study
    from brainbulge.studies.suites import FIELDS_FILE

    scenarios = attach_study_meshes(out_dir, scenarios)
    rows = run_study(scenarios, "brainbulge.studies.craniectomy:study_task", out_dir,
                     scheduler=scheduler, n_workers=workers, outputs=(FIELDS_FILE,))
    from brainbulge.results.present.craniectomy_report import write_comparison, write_report

    write_comparison(out_dir, scenarios, rows)
    write_report(out_dir, scenarios, rows)
    return sum(1 for r in rows if r.get("complete"))
