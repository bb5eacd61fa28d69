"""The solver's convergence mechanisms, each switched off in turn on the hard cases.

A mechanism stays in the solver only with a measurement that shows a case still needs it
(docs/design.md, "Convergence mechanisms"). This benchmark reruns that record: each case set
with the production options (``baseline``) and with one mechanism switched off through the
options tree (``--variants``), and prints per case set the runs that reached full load and
the Newton iterations of all of them, with the runs whose count changed.

Case sets (``--cases``):

- ``sector``: ``brainbulge study hemidisk-sector`` (32 runs, the rounded edge);
- ``disk``: ``brainbulge study hemidisk-disk``;
- ``sharp``: the sector sweep on the paper's sharp edge (``--skull-edge-radius 0``, MINI,
  rezoning on: :mod:`bench_sharp_edge_2d`);
- ``study``: ``brainbulge study craniectomy`` on the 30k-tet mesh (six scenarios, 21k
  tets after meshing);
- ``brain``: ``brainbulge brain --linear-solver krylov`` on the 111k-tet template (left
  flap, both sides);
- ``flap``: ``brainbulge plan --diameters 80 --centres 1`` on the 111k-tet template (the
  80 mm flap at its one-centre placement);
- ``plan``: ``brainbulge plan --diameters 100 120 --centres 1`` on that template (the
  120 mm flap warm-started from the 100 mm flap's state), and ``plan-cold``: the 120 mm
  flap alone (ramped from ``Js = 1``): the warm start with and without.

Each run is its own process (``OMP_NUM_THREADS=1`` unless set, studies on the serial
scheduler), its options changed by wrapping :class:`~brainbulge.solver.options.
SolverOptions`: every options object built in the run has the variant's fields replaced
(``group.field = value``). Newton counts are deterministic; wall times depend on the machine.
The mechanisms deleted for want of a case (docs/design.md, "Convergence mechanisms") have no
variant: their with/without runs are in that record.

Rerun: ``python benchmarks/bench_mechanisms.py --cases study brain --variants baseline
no-grow no-predictor`` (``--cache DIR`` keeps the template mesh, ``--out DIR`` the runs, and
a run whose summaries are there is not run again). On 2 cores beside other work: a sector
study about 12 min, the disk study 2, the six scenarios 5-8, the 111k brain 3-4, the flap 4-6
(building the 111k-tet mesh adds about 5 min once).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

#: variant -> the options it changes (``group.field``: value); ``baseline`` changes none
VARIANTS: dict[str, dict[str, object]] = {
    "baseline": {},
    "one-step": {"ramp.steps": 1},
    "no-grow": {"ramp.grow": 1.0},
    "no-slide": {"ramp.slide": 0.0},
    "no-predictor": {"ramp.predictor": False},
    "tight-intermediate": {"ramp.intermediate_tolerance": 1e-9},
    "no-step-cap": {"newton.step_cap": 0.0},
    "no-hotspot": {"newton.hotspot_relaxation": False},
    "no-inexact": {"linear.eta_max": 1e-10},
}

#: case set -> (argv of ``brainbulge``, glob of its summaries under the run's folder);
#: ``{mesh}``: the cached 111k-tet template mesh, ``{out}``: the run's folder
CASES: dict[str, tuple[tuple[str, ...], str]] = {
    "sector": (("study", "hemidisk-sector", "--scheduler", "serial", "--out", "{out}"),
               "*/summary.json"),
    "disk": (("study", "hemidisk-disk", "--scheduler", "serial", "--out", "{out}"),
             "*/summary.json"),
    "sharp": (("sharp",), "*/summary.json"),
    "study": (("study", "craniectomy", "--tets", "30000", "--scheduler", "serial",
               "--out", "{out}"), "*/summary.json"),
    "brain": (("brain", "--mesh", "{mesh}", "--linear-solver", "krylov", "--out", "{out}"),
              "summary.json"),
    "flap": (("plan", "--swell", "left", "--centres", "1", "--diameters", "80", "--mesh",
              "{mesh}", "--scheduler", "serial", "--out", "{out}"), "c00-d80/summary.json"),
    "plan": (("plan", "--swell", "left", "--centres", "1", "--diameters", "100", "120",
              "--mesh", "{mesh}", "--scheduler", "serial", "--out", "{out}"),
             "c00-d*/summary.json"),
    "plan-cold": (("plan", "--swell", "left", "--centres", "1", "--diameters", "120",
                   "--mesh", "{mesh}", "--scheduler", "serial", "--out", "{out}"),
                  "c00-d*/summary.json"),
}
PLAN_TETS = 100_000


def override_options(changes: dict[str, object]) -> None:
    """Every :class:`SolverOptions` built from now on has ``changes`` (``group.field``:
    value) in its groups."""
    from brainbulge.solver import options

    by_group: dict[str, dict[str, object]] = {}
    for key, value in changes.items():
        group, name = key.split(".")
        by_group.setdefault(group, {})[name] = value
    init = options.SolverOptions.__init__

    def changed_init(self, **values) -> None:
        init(self, **values)
        for group, fields in by_group.items():
            object.__setattr__(self, group, dataclasses.replace(getattr(self, group),
                                                                **fields))

    options.SolverOptions.__init__ = changed_init


def child(changes: dict[str, object], argv: list[str]) -> int:
    """One run in this process with ``changes`` to the options."""
    override_options(changes)
    if argv[0] == "sharp":
        sys.path.insert(0, str(HERE))
        from bench_sharp_edge_2d import sweep

        sweep(Path(argv[1]), rezone=True, full=False)
        return 0
    from brainbulge.cli import main

    return main(argv)


def mesh_file(cache: Path) -> Path:
    path = cache / f"mesh_{PLAN_TETS}" / "brain.npz"
    if not path.is_file():
        subprocess.run([sys.executable, "-m", "brainbulge", "mesh", "--tets", str(PLAN_TETS),
                        "--no-figures", "--out", str(path.parent), "--overwrite"],
                       check=True, capture_output=True, env=_env())
    return path


def _env() -> dict[str, str]:
    return {**os.environ, "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "1")}


def run(case: str, variant: str, out: Path, cache: Path) -> dict:
    """Run ``case`` under ``variant`` into ``out``: its rows (one per summary)."""
    argv, pattern = CASES[case]
    folder = out / f"{case}-{variant}"
    if not any(folder.glob(pattern)):
        mesh = str(mesh_file(cache)) if "{mesh}" in argv else ""
        args = [a.format(out=folder, mesh=mesh) for a in argv]
        if case == "sharp":
            args.append(str(folder))
        start = time.perf_counter()
        subprocess.run([sys.executable, __file__, "--child", json.dumps(VARIANTS[variant]),
                        "--", *args], env=_env(), check=False, capture_output=True)
        (folder / "wall.txt").parent.mkdir(parents=True, exist_ok=True)
        (folder / "wall.txt").write_text(f"{time.perf_counter() - start:.0f}\n")
    rows = {}
    for path in sorted(folder.glob(pattern)):
        s = json.loads(path.read_text())
        rows[path.parent.name] = {"full": s.get("load_reached", 1.0) >= 1 - 1e-9
                                  and s.get("converged", True),
                                  "load": s.get("load_reached", 1.0),
                                  "newton": s.get("newton_iterations", 0),
                                  "gmres": s.get("linear_iterations", 0)}
    wall = folder / "wall.txt"
    return {"rows": rows, "wall": float(wall.read_text()) if wall.is_file() else float("nan")}


def table(case: str, results: dict[str, dict]) -> None:
    """The case set's table: one line per variant."""
    base = results.get("baseline", {}).get("rows", {})
    print(f"\n{case}\n")
    print("| variant | full load | Newton | GMRES | changed runs (Newton, baseline -> variant)"
          " | wall s |")
    print("|---|---|---|---|---|---|")
    for variant, res in results.items():
        rows = res["rows"]
        changed = [f"{n} {base[n]['newton']} -> {r['newton']}"
                   + ("" if r["full"] else f" (load {r['load']:.3f})")
                   for n, r in rows.items() if n in base and (
                       r["newton"] != base[n]["newton"] or r["full"] != base[n]["full"])]
        print(f"| {variant} | {sum(r['full'] for r in rows.values())} of {len(rows)} | "
              f"{sum(r['newton'] for r in rows.values())} | "
              f"{sum(r['gmres'] for r in rows.values())} | "
              f"{'; '.join(changed) or '-'} | {res['wall']:.0f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES))
    ap.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=["baseline"])
    ap.add_argument("--out", type=Path, default=None, help="keep the runs here (a run "
                    "whose summaries are there is not run again)")
    ap.add_argument("--cache", type=Path, default=None, help="the template mesh's folder")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("argv", nargs="*", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child is not None:
        sys.exit(child(json.loads(a.child), a.argv))
    with tempfile.TemporaryDirectory() as tmp:
        out, cache = a.out or Path(tmp), a.cache or Path(tmp) / "cache"
        for case in a.cases:
            table(case, {v: run(case, v, out, cache) for v in a.variants})


if __name__ == "__main__":
    main()
