"""Craniectomy planning: search the flap's centre and diameter for the least tissue damage.

A *plan* is a list of :class:`~brainbulge.model.brain.CraniectomyCase` values, one per
(centre, diameter) pair, all on one shared brain mesh: a flap is a boundary condition, opened
on the loaded mesh (:func:`~brainbulge.model.brain.open_case_flap`), not a new mesh.

- :func:`plan_cases` makes the cases from candidate centres (given, or spread evenly over the
  convexity above the swelling by :func:`~brainbulge.geometry.brain.flap_fit.
  convexity_centres`) and diameters; a flap that does not fit on the skull above the fixed
  base (:mod:`~brainbulge.geometry.brain.flap_fit`) stays in the list, marked
  ``extra["refused"]`` with the reason, and is not run.
- :func:`run_plan` runs them on the study runner (:mod:`brainbulge.studies.runner`: serial or
  Dask, resumable: rerun on the same folder and only what is missing runs), each into its own
  folder with the usual outputs of a 3D scenario plus the damage measures of
  :mod:`brainbulge.results.measures.plan_measures`, then writes ``plan.csv``, ``pareto.png``,
  ``centres.png`` and ``report.md`` (:mod:`brainbulge.results.present.plan_report`).

**Warm starts.** The cases run diameter by diameter, smallest first. A plan starts Newton at
full load from the finished state (``state.npz``) of the plan at the same centre with the
next smaller diameter: that flap lies inside this one, so its state is admissible (no tissue
inside the bone) and only the newly opened skull lets go. Where that state is missing (the
smallest diameter, or still running on another worker) or Newton does not converge from it,
the load is ramped from ``Js = 1`` as for any scenario; with GMRES a first linear solve
that fails gives the start up at once (``SolverOptions.warm_start``). The state reached is
the same equilibrium to within the solver's tolerance (tests/test_plan.py).

**Damage measures** come from the fields the summary samples at its integration points
(``write_brain_outputs(..., measures=...)``): one sampling, one recovered gradient per plan.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import logging
from pathlib import Path
from typing import Any

import numpy as np

from brainbulge.errors import InputError
from brainbulge.geometry.brain import BrainMesh
from brainbulge.geometry.brain.boundaries import SuperiorBand
from brainbulge.geometry.brain.flap_fit import fit_flap, signed_lateral_mm
from brainbulge.model.brain import CraniectomyCase, open_case_flap
from brainbulge.results.measures.plan_defaults import DIAMETERS_MM, N_CENTRES, STRAIN_THRESHOLD
from brainbulge.results.measures.plan_measures import damage_measures
from brainbulge.results.records.run_record import atomic_output
from brainbulge.studies.craniectomy import (
    PARENCHYMA,
    case_from_dict,
    solve_brain,
    write_brain_outputs,
)

log = logging.getLogger("brainbulge")

PLAN_TASK = "brainbulge.studies.plan:plan_task"
STATE_FILE = "state.npz"


def plan_name(centre_index: int, diameter_mm: float) -> str:
    """Folder name of a plan: ``c03-d120`` (centre 3, 120 mm)."""
    return f"c{centre_index:02d}-d{diameter_mm:g}"


def plan_cases(base: CraniectomyCase | dict[str, Any], bm: BrainMesh,
               centres_mm: np.ndarray, diameters_mm=DIAMETERS_MM) -> list[CraniectomyCase]:
    """One case per (centre, diameter), diameter-major (all centres at the smallest diameter
    first: the order warm starts need), each a custom flap on ``base``'s mesh.

    ``extra`` of each case: ``centre_index``, ``side`` (of the mid-sagittal plane),
    ``centre_on_skull_mm`` (the flap's centre projected onto the skull), ``flap_area_cm2``
    and ``clipped_area_cm2`` (:class:`~brainbulge.geometry.brain.flap_fit.FlapFit`) and
    ``refused``: why the flap does not fit (empty when it does; refused flaps are logged and
    not run)."""
    base = base if isinstance(base, CraniectomyCase) else case_from_dict(dict(base))
    diameters = sorted({float(d) for d in diameters_mm})
    if not diameters:
        raise InputError("a plan needs at least one flap diameter (--diameters)")
    centres = np.atleast_2d(np.asarray(centres_mm, float))
    band = base.superior_band()
    cases = []
    for d in diameters:
        for i, c in enumerate(centres):
            fit = fit_flap(bm, c, d, band)
            side = "right" if signed_lateral_mm(bm, c[None])[0] > 0 else "left"
            if not fit.fits:
                log.warning("plan %s: the %g mm flap at (%s) mm %s; left out", plan_name(i, d),
                            d, ", ".join(f"{v:.0f}" for v in c), fit.reason)
            extra = {"centre_index": i, "side": side,
                     "centre_on_skull_mm": [round(float(v), 6) for v in fit.flap.centre_mm],
                     "flap_area_cm2": fit.area_cm2, "clipped_area_cm2": fit.clipped_cm2,
                     "refused": fit.reason}
            cases.append(dataclasses.replace(
                base, flap="custom", flap_centre_mm=tuple(float(v) for v in c),
                flap_diameter_mm=d, name=plan_name(i, d), extra=extra))
    return cases


def plan_scenarios(cases: list[CraniectomyCase],
                   threshold: float = STRAIN_THRESHOLD) -> list[dict[str, Any]]:
    """The runner's scenarios of the cases that fit: the case as a dict, the strain threshold
    and ``warm_from``, the plans at the same centre with smaller diameters (nearest first)."""
    run = [c for c in cases if not c.extra.get("refused")]
    out = []
    for c in run:
        smaller = sorted((o for o in run if o.extra["centre_index"] == c.extra["centre_index"]
                          and o.flap_diameter_mm < c.flap_diameter_mm),
                         key=lambda o: -o.flap_diameter_mm)
        config = {k: v for k, v in dataclasses.asdict(c).items() if v is not None}
        out.append({**config, "strain_threshold": float(threshold),
                    "warm_from": [o.name for o in smaller]})
    return out


def run_plan(cases: list[CraniectomyCase], out_dir: Path, scheduler: str | None = None,
             workers: int | None = None, threshold: float = STRAIN_THRESHOLD,
             progress: bool = True) -> list[dict[str, Any]]:
    """Run the plan's cases that fit (module docstring) into ``out_dir/<name>/`` and write
    the plan's table, figures and report; return one row per case (refused ones included,
    ``complete`` false with the reason as ``error``)."""
    from brainbulge.results.present.plan_report import write_plan_report
    from brainbulge.studies.runner import run_study

    if not cases:
        raise InputError("the plan has no cases")
    meshes = {c.mesh for c in cases}
    if len(meshes) != 1 or None in meshes:
        raise InputError("every case of a plan must name one shared brain mesh (mesh = ...)")
    if all(c.extra.get("refused") for c in cases):
        raise InputError("no flap of the plan fits on the skull: "
                         f"{cases[0].name} {cases[0].extra['refused']}; try smaller "
                         "--diameters or other centres")
    scenarios = plan_scenarios(cases, threshold)
    rows = run_study(scenarios, PLAN_TASK, out_dir, scheduler=scheduler, n_workers=workers,
                     progress=progress)
    by_name = {r.get("name"): r for r in rows}
    table = []
    for c in cases:
        refused = c.extra.get("refused")
        table.append({"name": c.name, "complete": False, "error": f"does not fit: {refused}"}
                     if refused else by_name.get(c.name, {"name": c.name, "complete": False}))
    write_plan_report(Path(out_dir), cases, table, shared_mesh(str(cases[0].mesh)),
                      threshold)
    return table


# --- the runner's task -----------------------------------------------------------------
def plan_task(scenario: dict[str, Any], folder: Path) -> dict[str, Any]:
    """Runner task: one plan (its custom flap opened on the shared mesh, warm-started where
    a smaller flap at its centre has finished), its outputs, damage measures and
    ``state.npz``."""
    config = dict(scenario)
    sources = config.pop("warm_from", [])
    threshold = config.pop("strain_threshold", STRAIN_THRESHOLD)
    case = case_from_dict(config)
    bm = shared_mesh(str(case.mesh))
    open_case_flap(bm, case)
    key = _state_key(case, bm)
    folder = Path(folder)
    used: list[str] = []

    def start(form) -> bool:
        for name in sources:
            if load_state(form, folder.parent / name / STATE_FILE, key):
                used.append(name)
                return True
        return False

    run = solve_brain(case, folder, brain_mesh=bm, start=start)
    extra = {
        "centre_on_skull_mm": list(bm.flaps["custom"].centre_mm),
        "flap_diameter_mm": case.flap_diameter_mm,
        "plan_flap_area_cm2": bm.flap_area_cm2("custom"),
        "warm_start_from": used[0] if used else None,
        "warm_start_converged": run.started,
    }
    if run.sol.converged:
        save_state(run.form, folder / STATE_FILE, key)
    summary = write_brain_outputs(run, folder, extra, measures=lambda points: damage_measures(
        points, bm.flaps["custom"], run.skull, PARENCHYMA, threshold))
    return {k: v for k, v in summary.items() if k != "inputs"}


@functools.lru_cache(maxsize=1)
def shared_mesh(path: str) -> BrainMesh:
    """The plan's shared mesh, read once per process (its custom flap changes per plan)."""
    from brainbulge.geometry.brain import load_brain_mesh

    p = Path(path)
    return load_brain_mesh(p / "brain.npz" if p.is_dir() else p)


# --- start states ----------------------------------------------------------------------
def _state_key(case: CraniectomyCase, bm: BrainMesh) -> str:
    """What a start state must share with a plan: the mesh and every input but the flap."""
    skip = ("flap", "flap_centre_mm", "flap_diameter_mm", "name", "extra", "steps",
            "tolerance")
    inputs = {k: v for k, v in dataclasses.asdict(case).items() if k not in skip}
    mesh = hashlib.sha1(np.ascontiguousarray(bm.nodes_mm).tobytes()
                        + np.ascontiguousarray(bm.tets).tobytes()).hexdigest()
    return json.dumps([inputs, mesh], sort_keys=True, default=str)


def save_state(form, path: Path, key: str) -> Path:
    """The solved state of a plan, for the warm starts of others: the DOF vector (same mesh,
    same numbering) and each contact point's pressure by mesh vertex (atomic write)."""
    verts = [pc.vertices for pc in form.point_contacts]
    lams = [pc.lam[:len(pc.vertices)] for pc in form.point_contacts]
    with atomic_output(Path(path)) as tmp:
        np.savez(tmp, key=key, x=form.gfu.vec.FV().NumPy(),
                 contact_vertices=np.concatenate(verts) if verts else np.zeros(0, int),
                 contact_pressure=np.concatenate(lams) if lams else np.zeros(0))
    return Path(path)


def load_state(form, path: Path, key: str) -> bool:
    """Set ``form`` to the state in ``path`` at full load; False (nothing changed) if there is
    none, it is unreadable or of another mesh or problem."""
    path = Path(path)
    if not path.is_file():
        return False
    try:
        with np.load(path, allow_pickle=False) as f:
            data = {k: f[k] for k in ("key", "x", "contact_vertices", "contact_pressure")}
    except Exception as exc:  # noqa: BLE001 - a truncated or foreign file: start cold
        log.info("start state %s unreadable (%s): ramping the load", path, exc)
        return False
    x = form.gfu.vec.FV().NumPy()
    if str(data["key"]) != key or len(data["x"]) != len(x):
        return False
    x[:] = data["x"]
    form.set_load(1.0)
    pressure = np.zeros(form.mesh.nv)
    pressure[data["contact_vertices"].astype(int)] = data["contact_pressure"]
    for pc in form.point_contacts:
        lam = np.zeros(pc.n_points)
        lam[:len(pc.vertices)] = pressure[pc.vertices]
        pc.lam = lam
        pc.update(x)
    log.info("warm start from %s", path.parent.name)
    return True


def centres_for(bm: BrainMesh, swell: str, n: int | None, given, band: SuperiorBand | None
                ) -> np.ndarray:
    """The plan's candidate centres: ``given`` (k, 3) [mm], else ``n`` spread evenly over
    the convexity above the swelling."""
    from brainbulge.geometry.brain.flap_fit import convexity_centres

    if given is not None and len(given):
        return np.atleast_2d(np.asarray(given, float))
    return convexity_centres(bm, swell, N_CENTRES if n is None else n, band)
