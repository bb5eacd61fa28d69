"""Named sets of scenarios and how a named study runs, apart from the command line.

- the paper's studies: ``hemidisk-sector`` (alpha x beta x contact, Figures 2-3),
  ``hemidisk-disk`` (Figure 4) and ``craniectomy`` (the six 3D scenarios, Figures 7-9);
- the demo's plan (the paper in miniature) and the reproduction's (the paper at its
  resolution);
- :func:`run_named_study`: run a study's scenarios on the runner, then write its table,
  figures and report; :func:`incomplete_text` says what became of those that did not
  complete; :func:`brain_meshes_meanwhile` builds a 3D study's meshes on a worker while other
  studies run.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from brainbulge.geometry.brain.defaults import LARGE_TETS

STUDIES = ("hemidisk-sector", "hemidisk-disk", "craniectomy")
#: the file of each scenario that a study's figures read (recomputed on resume if it is lost)
FIELDS_FILE = "fields.npz"

#: default 3D mesh size of the reproduction: Netgen at ~181k tets, refined once to ~1.4M
#: (the paper: 1,275,808 tets)
PAPER_TETS = 1_450_000
#: the paper's brain volume [ml]
PAPER_BRAIN_VOLUME_ML = 1108.0
#: What the reproduction scales the template head to: its white matter to half the paper's
#: brain, the paper's own assumption (gray and white matter of about equal volume) from which
#: it derives its swelling volumes, 10 % of it: 55.4 ml for both hemispheres, 27.7 ml for one
#: (it states 56 / 28 ml). The template's white matter is 40 % of its gray + white matter, so
#: scaling gray + white matter to 1108 ml instead would swell only 44 / 22 ml (docs/paper.md).
PAPER_SCALING = {"volume_of": "white", "brain_volume_ml": PAPER_BRAIN_VOLUME_ML / 2}


def run_named_study(name: str, scenarios: list[dict], out: Path, scheduler: str | None,
                    workers: int | None = None) -> int:
    """Run the scenarios of study ``name``, then write ``table.csv``, the figures and (sector
    and craniectomy studies) ``report.md``; return how many completed."""
    if name == "craniectomy":
        from brainbulge.studies.craniectomy import run_study_with_report

        return run_study_with_report(out, scenarios, scheduler, workers)
    from brainbulge.studies import hemidisk as hd
    from brainbulge.studies.runner import run_study

    rows = run_study(scenarios, "brainbulge.studies.hemidisk:study_task", out,
                     scheduler=scheduler, n_workers=workers, cost=hd.expected_cost,
                     outputs=(FIELDS_FILE,))
    hd.write_study_table(rows, scenarios, out / "table.csv")
    if name == "hemidisk-sector":
        from brainbulge.studies.trends import write_sector_report

        hd.sector_figures(out, scenarios, rows)
        write_sector_report(out, scenarios, rows)
    else:
        hd.disk_figures(out, scenarios, rows)
    return sum(1 for r in rows if r.get("complete"))


@contextlib.contextmanager
def brain_meshes_meanwhile(scheduler: str | None, out: Path, scenarios: list[dict]
                           ) -> Iterator[None]:
    """Build the shared meshes of the 3D study ``scenarios`` in ``out`` (as
    :func:`~brainbulge.studies.craniectomy.attach_study_meshes` does) as one task on the Dask
    cluster at ``scheduler`` while the block runs other studies there; wait for it at the end.

    Netgen meshes on one core while the workers would otherwise wait for the 2D studies to
    finish; the 3D study then finds its meshes built (the quick demo's ~20 s of Netgen
    overlap its 2D studies).
    Nothing happens without a cluster (``"serial"``); a failure is left for the 3D study to
    meet again and report, in this process."""
    if scheduler is None or scheduler == "serial":
        yield
        return
    from distributed import Client

    from brainbulge.studies.craniectomy import attach_study_meshes

    with Client(scheduler, set_as_default=False) as client:
        future = client.submit(attach_study_meshes, out, scenarios, pure=False, priority=1)
        try:
            yield
        finally:
            try:
                future.result()
            except Exception as exc:  # noqa: BLE001 - the 3D study builds the mesh again
                logging.getLogger(__name__).debug("meshing on a worker failed: %s", exc)
            future.release()


def incomplete_text(out: Path, scenarios: list[dict]) -> str:
    """What became of a study's scenarios that did not complete: those that stopped before
    full load (Newton diverged; their last converged state is kept in their folders, and for
    the hemidisk studies in the table and figures too; a rerun computes the same again) and
    those that failed otherwise (a rerun retries them)."""
    from brainbulge.studies.runner import ERROR_FILE, stopped_summary

    failed = [sc for sc in scenarios if (out / sc["name"] / ERROR_FILE).is_file()]
    n_stopped = sum(stopped_summary(out / sc["name"]) is not None for sc in failed)
    parts = []
    if n_stopped:
        parts.append(f"{n_stopped} stopped before full load (their last converged states are "
                     "kept in their folders; a rerun computes the same again)")
    if len(failed) > n_stopped:
        parts.append(f"{len(failed) - n_stopped} failed (rerun the same command to retry them)")
    return "; ".join(parts or ["rerun the same command to retry them"]) + (
        f"; see {out}/study.json")


def demo_plan(quick: bool) -> dict[str, Any]:
    """The demo: the headline case (h = 0.05 R), a sector sweep, the 3D scenarios at 30k
    tets; ``quick`` shrinks each."""
    h = 0.08 if quick else 0.05
    return {
        "headline": {"alpha": 80.0, "beta": 60.0, "swelling": 1.2, "mesh_size": h},
        "sweep": {
            # beta = 30 is left out: the small openings take the most Newton iterations
            # (docs/performance.md)
            "alphas": [40.0, 80.0] if quick else [20.0, 40.0, 60.0, 80.0],
            "betas": [60.0] if quick else [60.0, 120.0],
            "mesh_size": 0.1 if quick else 0.08,
        },
        # Netgen gives up on the template below ~25k target tets (coarse size vs detail)
        "brain": {"tets": 30_000, "steps": 2, "quick": quick},
    }


def demo_scenarios(plan: dict[str, Any]) -> dict[str, list[dict[str, Any]]]:
    """The demo's three studies: ``headline`` (both contacts), ``sweep`` and ``brain`` (the
    six 3D scenarios; with ``quick`` two: left flap/left swelling, frontal/both)."""
    from brainbulge.studies import hemidisk as hd
    from brainbulge.studies.craniectomy import craniectomy_scenarios

    head = plan["headline"]
    sw = plan["sweep"]
    brain = craniectomy_scenarios(tets=plan["brain"]["tets"], steps=plan["brain"]["steps"])
    if plan["brain"]["quick"]:
        keep = {("left", "left"), ("frontal", "both")}
        brain = [sc for sc in brain if (sc["flap"], sc["swell"]) in keep]
    return {
        "headline": [{"name": f"headline_{c}", **head, "contact": c}
                     for c in ("noslip", "sliding")],
        "sweep": hd.sector_scenarios(alphas=sw["alphas"], betas=sw["betas"],
                                     mesh_size=sw["mesh_size"]),
        "brain": brain,
    }


def paper_brain_options(tets: int, fix: str = "inferior+superior") -> dict[str, Any]:
    """The options shared by the reproduction's six 3D scenarios at ``tets`` tets."""
    from brainbulge.model.brain import size_defaults

    common: dict[str, Any] = {"tets": tets, **PAPER_SCALING, "steps": 4, "fix": fix}
    if tets >= LARGE_TETS:  # a refined mesh, Krylov
        refine, solver = size_defaults(tets)
        common.update(refine=refine, linear_solver=solver)
    return common


def paper_parts(tets: int, fix: str, mesh_size: float) -> dict[str, list[dict[str, Any]]]:
    """The reproduction: ``sector`` (32 scenarios), ``disk`` (5) and ``craniectomy`` (6),
    each scenario checked."""
    from brainbulge.studies import hemidisk as hd
    from brainbulge.studies.craniectomy import case_from_dict, craniectomy_scenarios

    brain = craniectomy_scenarios(**paper_brain_options(tets, fix))
    for sc in brain:
        case_from_dict(sc)  # validate before anything is written
    return {
        "sector": hd.sector_scenarios(mesh_size=mesh_size, steps=4),
        "disk": hd.disk_scenarios(mesh_size=mesh_size, steps=4),
        "craniectomy": brain,
    }
