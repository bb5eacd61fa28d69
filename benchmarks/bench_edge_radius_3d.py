"""The 3D skull edge's radius: convergence and the flap rim's stretches at 8 / 4 / 2 / 1 mm.

Each run is the product's own command, ``brainbulge brain`` (GMRES + AMG, ``--skull-edge-
radius``), in a process of its own (``OMP_NUM_THREADS=1`` unless set) on a cached template
mesh (``--tets``: 100000 asks Netgen for the 111k-tet mesh, 400000 for the 428k one, built
once into ``--cache`` by ``brainbulge mesh``), for each scenario of the paper's six
(``--scenarios``, flap and swelling side), each radius (``--radii``) and, with
``--capped``, also under the resolved edge's step control of the 2D hemidisk
(:data:`~brainbulge.model.hemidisk.RESOLVED_EDGE_STEPS`: each Newton update capped at 0.3 of
a vertex's smallest edge and taken without line search, load steps sized by how far the
vertices slid, no predictor), set in the run's process (:func:`capped_main`).

Per run the table gives whether the load ramp reached full load (else the load reached; a
run stopped before its summary: the last load accepted in its log), Newton iterations
(accepted load steps; rejected steps in brackets), the process's wall time
and, from its vertex fields, the rim's measures over the parenchyma within
:data:`RING_MM` of the flap's rim (the curve where the cutting cylinder meets the skull's
inner surface), where the paper puts its compression (radial stretch down to 0.7) and its
tangential ring (up to 1.3): the radial stretch's 1st percentile by volume and its element
minimum, the tangential stretch's 0.1 ml peak and its element maximum (element values: the
stretches of the element-constant gradient of the P1 displacement,
:func:`~brainbulge.results.measures.extreme_sites.element_fields`), and the midline shift at
the foramen of Monro (``midline_shift_mm``). The band within 5 mm of the rim is included:
there the edge's rounding acts, and the element extremes sit there; the ring from 5 to 25 mm
alone (the summaries leave the band out) gets the percentile and the peak too; beside them
the summary's own 0.1 ml peaks and 1st percentile (integration points outside the band),
the primary measures of the paper's claims (docs/paper.md).

Rerun: ``python benchmarks/bench_edge_radius_3d.py --cache CACHE --out OUT [--tets 100000]
[--radii 8 4 2 1] [--scenarios left-both ...] [--capped]`` (about 7 min per run at 111k tets,
10-30 min at 428k, on one core); a run whose ``summary.json`` is in ``OUT`` is read, not
rerun, one stopped mid-way (its ``restart.npz`` there) resumed; ``--table`` only reads every
run in ``OUT``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import bench_hard_cases_3d as h3
from bench_sensitivity_3d import BAND_MM, RING_MM, elapsed_s, rim_geometry, volume_peaks

#: the radii of the study [mm]
RADII = (8.0, 4.0, 2.0, 1.0)
#: the paper's six scenarios as ``flap-swell``
SCENARIOS = tuple(f"{flap}-{swell}" for flap in ("left", "frontal")
                  for swell in ("both", "left", "right"))
#: the template's sizes asked of Netgen [tets] -> the label of the mesh Netgen gives
MESH_LABELS = {100_000: "111k", 400_000: "428k"}
#: a run's folder name: scenario, radius, mesh, step control
NAME = re.compile(r"(?P<flap>\w+)-(?P<swell>\w+)-r(?P<radius>[0-9.]+)mm-(?P<tets>\d+)"
                  r"(?P<capped>-capped)?$")


@dataclasses.dataclass(frozen=True)
class EdgeRun:
    """One process: the scenario (``flap``, ``swell``), the edge radius [mm], the template's
    size asked of Netgen [tets] and whether the resolved edge's step control is on."""

    flap: str
    swell: str
    radius: float
    tets: int
    capped: bool = False

    @property
    def name(self) -> str:
        return (f"{self.flap}-{self.swell}-r{self.radius:g}mm-{self.tets}"
                + ("-capped" if self.capped else ""))

    @classmethod
    def parse(cls, name: str) -> EdgeRun | None:
        m = NAME.match(name)
        if m is None:
            return None
        return cls(m["flap"], m["swell"], float(m["radius"]), int(m["tets"]),
                   bool(m["capped"]))

    def argv(self, mesh: Path, out: Path) -> list[str]:
        """The arguments of ``brainbulge``: a folder with a restart file (a run stopped
        mid-way) is resumed, any other replaced."""
        resume = (out / "restart.npz").is_file()
        return ["brain", "--mesh", str(mesh), "--linear-solver", "krylov", "--flap", self.flap,
                "--swell", self.swell, "--skull-edge-radius", f"{self.radius:g}",
                "--out", str(out), *([] if resume else ["--overwrite"])]


def run(r: EdgeRun, out: Path, cache: Path) -> float:
    """Run ``r`` into ``out / r.name`` (``/usr/bin/time -v`` beside it as ``NAME.time``);
    return the wall time [s]."""
    folder = out / r.name
    head = ([sys.executable, __file__, "--capped-run"] if r.capped
            else [sys.executable, "-m", "brainbulge"])
    cmd = [*head, *r.argv(h3.mesh_file(cache, r.tets), folder)]
    if Path(h3.TIMER).is_file():
        cmd = [h3.TIMER, "-v", "-o", str(out / f"{r.name}.time"), *cmd]
    t0 = time.perf_counter()
    subprocess.run(cmd, env=h3.child_env(), capture_output=True)
    wall = time.perf_counter() - t0
    (out / f"{r.name}.wall").write_text(f"{wall:.1f}\n")
    return wall


def capped_main(argv: list[str]) -> int:
    """``brainbulge ARGV`` with the resolved edge's step control
    (:data:`~brainbulge.model.hemidisk.RESOLVED_EDGE_STEPS`) in every solve of a brain
    scenario."""
    from brainbulge.cli import main
    from brainbulge.model.hemidisk import RESOLVED_EDGE_STEPS
    from brainbulge.studies import craniectomy

    ramp, newton = RESOLVED_EDGE_STEPS
    plain = craniectomy.SolverOptions

    def capped(**values):
        options = plain(**values)
        options.ramp = dataclasses.replace(options.ramp, **ramp)
        options.newton = dataclasses.replace(options.newton, **newton)
        return options

    craniectomy.SolverOptions = capped
    return main(argv)


def rim_measures(folder: Path, mesh: Path, flap: str) -> dict[str, float]:
    """The rim's measures of a run (parenchyma within :data:`RING_MM` of the rim): ``p01``
    and ``peak_t`` (vertex values by volume, :func:`~bench_sensitivity_3d.volume_peaks`),
    ``min_n`` and ``max_t`` (element values of the tets whose centroid lies there);
    ``ring_p01`` and ``ring_peak_t`` the same as ``p01`` and ``peak_t`` without the band
    within :data:`BAND_MM` of the rim."""
    from brainbulge.results.measures.extreme_sites import element_fields

    g = rim_geometry(folder, mesh, flap)
    peaks = volume_peaks(g, g.parenchyma & (g.rim < RING_MM), "rim")
    peaks |= volume_peaks(g, g.parenchyma & (g.rim >= BAND_MM) & (g.rim < RING_MM), "ring")
    X, cells = np.asarray(g.vf.points, float), np.asarray(g.vf.cells)
    near = g.tissue_tets & (g.rim_of(X[cells].mean(axis=1)) < RING_MM)
    el = element_fields(X, cells[near], np.asarray(g.vf.point_data["u"], float), g.centre)
    return {"p01": peaks["rim_radial_p01"], "peak_t": peaks["rim_tangential_peak"],
            "min_n": float(el["lambda_n"].min()), "max_t": float(el["lambda_t"].max()),
            "ring_p01": peaks["ring_radial_p01"], "ring_peak_t": peaks["ring_tangential_peak"]}


#: the summary's own measures (integration points of the parenchyma outside the 5 mm rim
#: band): the paper's claims' primary measures
SUMMARY_KEYS = ("peak_radial_stretch", "p01_radial_stretch", "peak_tangential_stretch")
HEADER = ("| scenario | radius mm | step control | tets | converged | Newton (rejected steps) "
          "| wall s | radial p01 | radial element min | tangential 0.1 ml peak | tangential "
          "element max | 5-25 mm: radial p01 | 5-25 mm: tangential peak | summary: radial peak / "
          "p01 / tangential peak | midline shift mm |\n" + "|---" * 15 + "|")


def row(r: EdgeRun, out: Path, cache: Path) -> str:
    """The table row of ``r`` from its folder in ``out``."""
    folder = out / r.name
    wall_file, time_file = out / f"{r.name}.wall", out / f"{r.name}.time"
    wall = (float(wall_file.read_text()) if wall_file.is_file()
            else elapsed_s(time_file.read_text()) if time_file.is_file() else math.nan)
    head = (f"| {r.flap}-flap, {r.swell} | {r.radius:g} | "
            f"{'capped' if r.capped else 'line search'} |")
    summary = folder / "summary.json"
    if not summary.is_file():
        log = folder / "brainbulge.log"
        got = h3.row_from_log(log.read_text(), r.name, "") if log.is_file() else None
        cells = ([f"stopped at load {got['load']:.3f}", str(got["newton"])] if got
                 else ["no log", "-"])
        return (head + f" {MESH_LABELS.get(r.tets, r.tets)} | " + " | ".join(cells)
                + f" | {wall:.0f} |" + " - |" * 8)
    s = json.loads(summary.read_text())
    done = s.get("converged", True) and s.get("load_reached", 1.0) >= 1.0
    conv = "yes" if done else f"no: load {s.get('load_reached', 0.0):.3f}"
    cells = [f"{s.get('elements', 0):,}", conv,
             f"{s.get('newton_iterations')} ({s.get('rejected_steps', 0)})", f"{wall:.0f}"]
    if (folder / "fields.npz").is_file():
        m = rim_measures(folder, h3.mesh_file(cache, r.tets), r.flap)
        cells += [f"{m[k]:.3f}" for k in ("p01", "min_n", "peak_t", "max_t", "ring_p01",
                                          "ring_peak_t")]
    else:
        cells += ["-"] * 6
    cells.append(" / ".join(f"{s.get(k, math.nan):.3f}" for k in SUMMARY_KEYS))
    cells.append(f"{s.get('midline_shift_mm', math.nan):+.2f}")
    return head + " " + " | ".join(cells) + " |"


def runs_in(out: Path) -> list[EdgeRun]:
    """The runs with a folder in ``out``, by mesh, scenario, step control and falling
    radius."""
    found = [EdgeRun.parse(p.name) for p in out.iterdir() if p.is_dir()]
    return sorted((r for r in found if r is not None),
                  key=lambda r: (r.tets, SCENARIOS.index(f"{r.flap}-{r.swell}")
                                 if f"{r.flap}-{r.swell}" in SCENARIOS else 99,
                                 r.capped, -r.radius))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, default=Path("edge-radius-3d-cache"),
                    help="the meshes, built once (mesh_<tets>/brain.npz)")
    ap.add_argument("--out", type=Path, default=Path("edge-radius-3d-out"),
                    help="one folder per run; a run with its summary.json is read, not rerun")
    ap.add_argument("--tets", type=int, nargs="+", default=[100_000],
                    help="the templates' sizes asked of Netgen (100000: 111k tets)")
    ap.add_argument("--radii", type=float, nargs="+", default=list(RADII))
    ap.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), choices=SCENARIOS)
    ap.add_argument("--capped", action="store_true",
                    help="the resolved edge's step control instead of the line search")
    ap.add_argument("--table", action="store_true", help="only read every run in --out")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if not args.table:
        for tets in args.tets:
            for sc in args.scenarios:
                for radius in args.radii:
                    r = EdgeRun(*sc.split("-"), radius, tets, args.capped)
                    if not (args.out / r.name / "summary.json").is_file():
                        print(f"{r.name}: {run(r, args.out, args.cache):.0f} s", flush=True)
    print(HEADER)
    for r in runs_in(args.out):
        print(row(r, args.out, args.cache), flush=True)


if __name__ == "__main__":
    if sys.argv[1:2] == ["--capped-run"]:
        sys.exit(capped_main(sys.argv[2:]))
    main()
