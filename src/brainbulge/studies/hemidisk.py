"""The hemidisk cases and the paper's 2D studies (its Figures 2-4), as runnable tasks.

``run_hemidisk(case, out_dir)`` solves one case and writes ``summary.json``, ``fields.vtu``
(ParaView), ``fields.npz`` (vertex fields for figures) and ``fields.png``. A run that stops
early keeps the last converged state on disk, marked ``"converged": false``, and raises
:class:`~brainbulge.errors.ConvergenceError`.

Studies:

- ``hemidisk-sector``: alpha x beta x {noslip, sliding} at the case's sector swelling
  (Js = 1.2);
- ``hemidisk-disk``: five positions of a swelling disk (the case's disk swelling, Js = 1.3)
  under an opening inclined off the symmetry axis, sliding contact.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from brainbulge.errors import ConvergenceError, InputError
from brainbulge.model.hemidisk import (
    DISK_SWELLING,
    SECTOR_SWELLING,
    HemidiskCase,
    hemidisk_problem,
)
from brainbulge.model.problem import case_from_config
from brainbulge.results.export.writers import (
    add_contact_fields,
    load_vertex_fields,
    save_vertex_fields,
    vertex_fields,
    write_vtu,
)
from brainbulge.results.measures.folds import boundary_self_crossings
from brainbulge.results.measures.recovery import recovered_gradient
from brainbulge.results.measures.summary import point_fields, solution_summary
from brainbulge.results.present.figures import (
    plot_fields,
    plot_grid,
    plot_row,
    plot_rows,
    plot_side_by_side,
)
from brainbulge.results.records.run_record import atomic_output, atomic_write_json
from brainbulge.solver import MixedForm, Rezoning, Solution, Strategy, solve
from brainbulge.studies.runner import stopped_summary

SECTOR_ALPHAS = (20.0, 40.0, 60.0, 80.0)
SECTOR_BETAS = (30.0, 60.0, 90.0, 120.0)
#: The swelling-disk case (the paper's Figure 1B) inclines the opening off the symmetry axis:
#: its centre at this angle [deg] from the base (90 = on the axis), so with beta = 60 the
#: opening spans 30-90 deg and the axis passes through its edge.
DISK_OPENING_CENTER = 60.0
#: (label, angle of the disk's centre [deg], its distance from the hemidisk's centre [R], its
#: radius [R]): five disks on one arc, under the opening's far edge, its centre and its edge on
#: the axis, then under the skull 30 and 60 deg past that edge.
DISK_POSITIONS = (
    ("edge-30", 30.0, 0.55, 0.15),
    ("centre-60", 60.0, 0.55, 0.15),
    ("edge-90", 90.0, 0.55, 0.15),
    ("skull-120", 120.0, 0.55, 0.15),
    ("skull-150", 150.0, 0.55, 0.15),
)


def case_from_dict(config: dict[str, Any]) -> HemidiskCase:
    """A :class:`HemidiskCase` from a plain dict (TOML table, CLI, study scenario); the
    ``contact_method = "active-set"`` of older run files is accepted (the only method)."""
    config = dict(config)
    if config.pop("contact_method", "active-set") != "active-set":
        raise InputError("contact_method 'augmented' is no longer available: contact is solved "
                         "by the active set; remove contact_method from the case")
    return case_from_config(HemidiskCase, config, "hemidisk")


def run_hemidisk(
    config: dict[str, Any] | HemidiskCase, out_dir: Path, progress: bool = False
) -> dict[str, Any]:
    """Solve one hemidisk case; write its files into ``out_dir``; return the summary."""
    case = config if isinstance(config, HemidiskCase) else case_from_dict(dict(config))
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    problem = hemidisk_problem(case)
    geo = case.geometry
    options = case.solver_options(progress)
    rezoning = None
    # how the deformed domain is meshed afresh (the solver decides when); the resolved edge
    # needs no rezoning
    if case.rezone and not case.rounded:
        rim_h = case.rim_h
        rezoning = Rezoning(lambda mesh: hemidisk_problem(case, mesh), geo.project,
                            case.mesh_size * case.R, case.corner_h, geo.singular_points(),
                            geo.rim_points(case.edge_exclusion * case.R, rim_h or 0.0), rim_h)
    sol = solve(problem, Strategy.from_problem(problem, options, element=case.element,
                                               rezoning=rezoning))
    form = sol.form
    centre = np.zeros(2)
    G = recovered_gradient(form.mesh, form.output_displacement())  # one projection for both
    points = point_fields(form, centre, gradient=G)
    whole = dataclasses.replace(geo, half=False)  # the outputs are the whole hemidisk's
    summary: dict[str, Any] = {
        "case": case.name,
        "inputs": dataclasses.asdict(case),
        **solution_summary(
            sol, centre, whole.singular_points(), case.edge_exclusion * case.R,
            points=points.mirrored() if case.half else points,
        ),
    }
    summary["rezones"] = sol.rezones
    summary["swelling_area_ratio_expected"] = _expected_area_ratio(case)
    vf = vertex_fields(form, centre, gradient=G)
    x = vf.points[:, :2] + vf.point_data["u"][:, :2]  # deformed vertex positions
    summary["max_skull_crossing"] = skull_crossing(case, form, x)
    add_contact_fields(vf, form)
    if case.half:
        vf = vf.mirrored()
    summary["boundary_self_crossings"] = boundary_self_crossings(vf.points, vf.cells,
                                                                 vf.point_data["u"])
    write_vtu(out_dir / "fields.vtu", vf)
    save_vertex_fields(out_dir / "fields.npz", vf)
    js = sol.swelling_reached
    state = "" if sol.converged else f" (stopped at Js {js:.3f}, load {sol.load:.3f})"
    plot_fields(vf, out_dir / "fields.png", title=f"{_label(case)}{state}",
                mark=summary.get("failure_site"))
    atomic_write_json(out_dir / "summary.json", summary)
    if not sol.converged:
        raise ConvergenceError(
            f"{stopped_message(case, sol)}; partial "
            f"results (up to Js = {js:.3f}) in {out_dir}")
    return summary


#: points per boundary segment at which the deformed arc is checked against the skull
CROSSING_SAMPLES = 8


def skull_crossing(case: HemidiskCase, form: MixedForm, x: np.ndarray) -> float:
    """``max_skull_crossing`` [length]: how far the deformed tissue reaches into the skull.
    On a rounded edge, the largest ``max(-g, 0)`` of the rounded skull's signed distance over
    the deformed arc (``skull`` and ``opening``, :data:`CROSSING_SAMPLES` points per segment:
    between the contact's Gauss points, and the end face included); on the paper's sharp
    edge, the largest ``|x| - R`` of the deformed vertices ``x`` (n, 2) where the skull is."""
    import ngsolve as ngs

    mesh = form.mesh
    if not case.rounded:
        return case.skull_arc.crossing(x)
    rule = ngs.IntegrationRule([((k + 0.5) / CROSSING_SAMPLES, 0.0, 0.0)
                                for k in range(CROSSING_SAMPLES)],
                               [1.0 / CROSSING_SAMPLES] * CROSSING_SAMPLES)
    pts = mesh.MapToAllElements(rule, mesh.Boundaries("skull|opening"))
    x = np.asarray(ngs.CF((ngs.x + form.u[0], ngs.y + form.u[1]))(pts)).reshape(-1, 2)
    g = case.obstacle.gap_numpy(x)
    return float(max(np.max(-g, initial=0.0), 0.0)) + 0.0


#: why a hemidisk ramp stops on the skull's rounded cut edge (docs/design.md, Rezoning)
CUT_EDGE_ADVICE = (
    "That is on the skull's rounded cut edge: the tissue pressed around it is squeezed in "
    "a thin layer, which a finer mesh sharpens and more steps do not get past (a known "
    "limit for small openings with large swelling regions, docs/design.md); with a larger "
    "opening (--beta) or a smaller swelling region the case runs to full load"
)


#: why Taylor-Hood stops sliding on the sharp edge (docs/model.md section 10)
SHARP_EDGE_ADVICE = (
    "On the sharp edge (--skull-edge-radius 0) Taylor-Hood's edge element next to the corner "
    "is squeezed along the arc; take --element mini there, or round the edge"
)


def stopped_message(case: HemidiskCase, sol: Solution) -> str:
    """Why the ramp of ``sol`` stopped, with :data:`CUT_EDGE_ADVICE` as the advice when
    the largest unbalanced force sat at the skull's rounded edge, and
    :data:`SHARP_EDGE_ADVICE` for Taylor-Hood sliding on the sharp edge."""
    site = sol.failure_site
    if not case.rounded and case.element == "taylor-hood" and case.contact == "sliding":
        return sol.describe(SHARP_EDGE_ADVICE)
    if site is None or not case.rounded or not case.obstacle.near_cut_edge(np.asarray(site)):
        return sol.describe()
    return sol.describe(CUT_EDGE_ADVICE)


def _expected_area_ratio(case: HemidiskCase) -> float:
    """Added area / hemidisk area: ``alpha/pi (Js - 1)`` for a sector (docs/model.md section 1)."""
    if case.alpha is not None:
        return case.alpha / 180.0 * (case.swelling - 1)
    r = case.disk[2] if case.disk else 0.0
    return (r / case.R) ** 2 * 2 * (case.swelling - 1)


def _label(case: HemidiskCase) -> str:
    what = f"alpha {case.alpha:g}" if case.alpha is not None else f"disk {case.disk}"
    return f"{what}, beta {case.beta:g}, Js {case.swelling:g}, {case.contact}"


# --- studies ----------------------------------------------------------------------------
def sector_scenarios(
    alphas=SECTOR_ALPHAS, betas=SECTOR_BETAS, contacts=("noslip", "sliding"), **common: Any
) -> list[dict[str, Any]]:
    """The paper's sector sweep (Figures 2-4) as scenario dicts."""
    return [
        {
            "name": f"{contact}_a{alpha:g}_b{beta:g}",
            **common,
            "alpha": float(alpha),
            "beta": float(beta),
            "contact": contact,
            "swelling": common.get("swelling", SECTOR_SWELLING),
        }
        for contact in contacts
        for beta in betas
        for alpha in alphas
    ]


def disk_scenarios(**common: Any) -> list[dict[str, Any]]:
    """The five disk positions of :data:`DISK_POSITIONS` (the paper's Figure 4) under the
    inclined opening of :data:`DISK_OPENING_CENTER`, sliding contact, the case's disk swelling
    (:data:`~brainbulge.model.hemidisk.DISK_SWELLING`) unless ``common`` gives one."""
    return [
        {
            "name": f"disk_{label}",
            "opening_center": DISK_OPENING_CENTER,
            **common,
            "alpha": None,
            "disk": [round(dist * math.cos(math.radians(angle)), 6),
                     round(dist * math.sin(math.radians(angle)), 6), radius],
            "contact": "sliding",
            "swelling": common.get("swelling", DISK_SWELLING),
        }
        for label, angle, dist, radius in DISK_POSITIONS
    ]


def expected_cost(scenario: dict[str, Any]) -> float:
    """Relative run time of a hemidisk scenario, for the order in which a study starts them
    (:func:`brainbulge.studies.runner.run_study`): the swelling sector's angle over the
    opening's, ``alpha / beta`` (1 for a disk). A large sector pushed through a narrow opening
    folds the bulge over the opening's edges and takes the longest: in the sector study the
    three slowest were alpha 80 / beta 30 (both contacts) and sliding alpha 60 / beta 30
    (ratios 2-2.7), 10-20 s of solve against 0.3-2 s for each case with a ratio of at most 1
    (docs/performance.md, "2D hemidisk")."""
    alpha = scenario.get("alpha")
    if not alpha:
        return 1.0
    return float(alpha) / float(scenario.get("beta", HemidiskCase.beta))


def study_task(scenario: dict[str, Any], scenario_dir: Path) -> dict[str, Any]:
    """Runner task: one hemidisk scenario (``name`` is the folder, the rest the case)."""
    config = {k: v for k, v in scenario.items() if k != "name"}
    config["name"] = scenario["name"]
    summary = run_hemidisk(config, scenario_dir)
    return {k: v for k, v in summary.items() if k != "inputs"}


def reached_swelling(swelling: float, load: float) -> float:
    """``Js`` at the load factor a run reached, ``1 + load (Js - 1)`` (the ramp of
    :meth:`MixedForm.Js_current`)."""
    return 1 + float(load) * (float(swelling) - 1)


def _reached_swelling(scenario: dict, partial: dict[str, Any]) -> float:
    """``Js`` a stopped scenario reached, from its partial summary's ``load_reached``."""
    return reached_swelling(scenario["swelling"], partial.get("load_reached", 0.0))


def _with_stopped(out_dir: Path, scenarios: list[dict], rows: list[dict]) -> list[dict]:
    """``rows`` with each failed scenario's row completed by its stopped run's summary
    (results computed so far are reported, not dropped); its ``error`` stays."""
    merged = []
    for sc, r in zip(scenarios, rows, strict=True):
        partial = None if r.get("complete") else stopped_summary(out_dir / sc["name"])
        merged.append({**partial, **r} if partial else r)
    return merged


def write_study_table(rows: list[dict[str, Any]], scenarios: list[dict], path: Path) -> Path:
    """``table.csv``: one row per scenario with its inputs and summary keys; a scenario that
    stopped before full load has the keys of its last converged state (``converged`` false,
    ``load_reached``) and its ``error``."""
    import csv

    rows = _with_stopped(Path(path).parent, scenarios, rows)
    keys: list[str] = []
    for r in rows:
        for k, v in r.items():
            if k not in keys and not isinstance(v, (list, dict)):
                keys.append(k)
    in_keys = [k for k in ("alpha", "beta", "contact", "swelling", "disk") if k]
    with atomic_output(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(in_keys + [k for k in keys if k not in in_keys])
        for sc, r in zip(scenarios, rows, strict=True):
            w.writerow(
                [
                    json.dumps(sc.get(k)) if isinstance(sc.get(k), list) else sc.get(k)
                    for k in in_keys
                ]
                + [r.get(k) for k in keys if k not in in_keys]
            )
    return path


def sector_figures(out_dir: Path, scenarios: list[dict], rows: list[dict]) -> list[Path]:
    """Grid PNGs (rows beta, columns alpha) of lambda_n and lambda_t for each contact, and
    the side-by-side no-slip | sliding figure of the headline case."""
    paths = []
    done = {sc["name"] for sc, r in zip(scenarios, rows, strict=True) if r.get("complete")}
    for contact in sorted({sc["contact"] for sc in scenarios}):
        panels, notes = {}, {}
        for sc in scenarios:
            if sc["contact"] != contact:
                continue
            key = (sc["beta"], sc["alpha"])
            fields = out_dir / sc["name"] / "fields.npz"
            partial = None if sc["name"] in done else stopped_summary(out_dir / sc["name"])
            if sc["name"] in done or (partial is not None and fields.is_file()):
                panels[key] = load_vertex_fields(fields)
            if sc["name"] not in done:  # drawn as far as it got, or an empty cell, labelled
                notes[key] = (f"stopped at Js {_reached_swelling(sc, partial):.3f}"
                              if key in panels else "no result")
        if not panels and not notes:
            continue
        for field in ("lambda_n", "lambda_t"):
            paths.append(
                plot_grid(
                    panels,
                    field,
                    out_dir / f"grid_{field}_{contact}.png",
                    title=f"{field} ({contact})",
                    notes=notes,
                )
            )
    pairs = {}
    for sc in scenarios:
        if sc["name"] in done:
            pairs.setdefault((sc["alpha"], sc["beta"]), {})[sc["contact"]] = sc["name"]
    key = (80.0, 60.0) if (80.0, 60.0) in pairs else next(iter(pairs), None)
    if key is not None and len(pairs[key]) == 2:
        left = load_vertex_fields(out_dir / pairs[key]["noslip"] / "fields.npz")
        right = load_vertex_fields(out_dir / pairs[key]["sliding"] / "fields.npz")
        paths.append(
            plot_side_by_side(
                left,
                right,
                out_dir / "side_by_side.png",
                title=f"alpha {key[0]:g}, beta {key[1]:g}: no-slip (left) | sliding (right)",
            )
        )
    return paths


def disk_figures(out_dir: Path, scenarios: list[dict], rows: list[dict]) -> list[Path]:
    """lambda_n and lambda_t for the disk positions side by side (a run that stopped early
    as far as it got, labelled with the swelling it reached)."""
    panels = []
    for sc, r in zip(scenarios, rows, strict=True):
        label, fields = sc["name"].removeprefix("disk_"), out_dir / sc["name"] / "fields.npz"
        partial = None if r.get("complete") else stopped_summary(out_dir / sc["name"])
        if partial is not None and fields.is_file():
            label += f"\nstopped at Js {_reached_swelling(sc, partial):.3f}"
        elif not r.get("complete"):
            continue
        panels.append((label, load_vertex_fields(fields)))
    if not panels:
        return []
    paths = [plot_row(panels, f, out_dir / f"disk_{f}.png") for f in ("lambda_n", "lambda_t")]
    case = case_from_dict({k: v for k, v in scenarios[0].items() if k != "name"})
    paths.append(plot_rows(panels, ("lambda_n", "lambda_t"), out_dir / "disk_panel.png",
                           title=f"swelling disk, Js {case.swelling:g}, {case.contact}: "
                           "lambda_n (top), lambda_t",
                           opening_deg=case.geometry.opening_angles_deg))
    return paths
