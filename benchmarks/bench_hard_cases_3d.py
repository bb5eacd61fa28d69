"""The 3D rows of the hard-case benchmark (:mod:`bench_hard_cases`): the brain cases that
stall or are slow, each run as the product's own command in its own process.

Cases (``RUNS``; each a flag of ``bench_hard_cases.py``):

- ``study`` (``--3d``): the six craniectomy scenarios on the demo's brain (``brainbulge
  study craniectomy --tets 30000``: Netgen gives 21k tets).
- ``flap`` (``--flap``): what the planner solves for its 80 mm flap at the one-centre
  placement over the left white matter (``brainbulge plan --swell left --centres 1
  --diameters 80``, serial) on the 100k-tet template (111k tets); GMRES + AMG, 8 mm edge.
- ``edge-radius`` (``--edge-radius``): the default scenario (left flap, both-sided
  swelling) with the flap's cut edge rounded by 2 mm instead of 8, GMRES + AMG, the load
  ramped on the 100k-tet template (``ramped``).
- ``taylor-hood`` (``--taylor-hood``): the six scenarios of ``study`` with ``--element
  taylor-hood`` on the same 21k-tet mesh (``--th-scenarios`` picks some).
- ``long`` (``--long``): Taylor-Hood at 175k tets (GMRES) and the default scenario on the
  1.40M-tet mesh, the load ramped there. Hours; not measured by default.

Every row is parsed from the run's ``summary.json`` (a failed Newton solve from a given
state: its iterations and residual from the summary's message); "run s" and the peak memory
(from ``/usr/bin/time`` where present) are the whole process's (for ``study``: all six
scenarios). The meshes are built once by ``brainbulge mesh`` into ``--cache``. Threads:
``OMP_NUM_THREADS=1`` unless set.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

from brainbulge.studies.craniectomy import SCENARIOS
from brainbulge.studies.suites import PAPER_TETS

#: the demo's and the planner's mesh sizes asked of Netgen [tets]
DEMO_TETS, PLAN_TETS = 30_000, 100_000
#: the edge radius of the ``edge-radius`` rows [mm]
SMALL_EDGE_MM = 2.0
#: GNU time, for the peak memory
TIMER = "/usr/bin/time"
#: a Newton solve that failed from a given state, as its message says (its iterations are in no
#: load-step record)
STALLED = re.compile(r"\|R\| = ([0-9.eE+-]+) after (\d+) iterations")
#: a load step accepted, and a scaled residual, in ``brainbulge.log``
ACCEPTED = re.compile(r"load ([0-9.]+): (\d+) Newton iterations")
RESIDUAL = re.compile(r"\|R\| = ([0-9.eE+-]+)")
SCENARIO_NAMES = tuple(f"{flap}-flap_{swell}-swelling" for flap, swell in SCENARIOS)


@dataclasses.dataclass(frozen=True)
class Run3D:
    """One process: ``argv`` of ``brainbulge`` (``{mesh:N}``: the cached N-tet mesh,
    ``{out}``: the run's folder); ``summaries``: the glob of its summary files under
    ``{out}``."""

    case: str
    variant: str
    argv: tuple[str, ...]
    summaries: str = "summary.json"

    def meshes(self) -> list[int]:
        """The cached mesh sizes this run reads."""
        return [int(a[6:-1]) for a in self.argv if a.startswith("{mesh:")]


def _brain(*extra: str) -> tuple[str, ...]:
    return ("brain", "--out", "{out}", *extra)


def runs_for(cases: list[str], th_scenarios: list[str] | tuple[str, ...] = SCENARIO_NAMES
             ) -> list[Run3D]:
    """The runs of the selected ``cases`` (keys of :data:`RUNS`), in order."""
    out = []
    for case in cases:
        if case == "taylor-hood":
            for name in th_scenarios:
                flap, swell = name.split("-flap_")
                out.append(Run3D(case, name, _brain(
                    "--mesh", f"{{mesh:{DEMO_TETS}}}", "--element", "taylor-hood",
                    "--flap", flap, "--swell", swell.removesuffix("-swelling"),
                    "--steps", "4")))
        else:
            out += RUNS[case]
    return out


RUNS: dict[str, list[Run3D]] = {
    "study": [Run3D("study", "production", (
        "study", "craniectomy", "--tets", str(DEMO_TETS), "--scheduler", "serial",
        "--out", "{out}"), summaries="*/summary.json")],
    "flap": [Run3D("flap-80mm", "plan c00-d80", (
        "plan", "--swell", "left", "--centres", "1", "--diameters", "80", "--mesh",
        f"{{mesh:{PLAN_TETS}}}", "--scheduler", "serial", "--out", "{out}"),
        summaries="c00-d80/summary.json")],
    "edge-radius": [
        Run3D("edge-2mm", "ramped", _brain(
            "--mesh", f"{{mesh:{PLAN_TETS}}}", "--skull-edge-radius", f"{SMALL_EDGE_MM:g}",
            "--linear-solver", "krylov"))],
    "taylor-hood": [],  # per scenario: runs_for
    "long": [
        Run3D("taylor-hood-175k", "left-flap_both-swelling", _brain(
            "--tets", "175000", "--element", "taylor-hood", "--linear-solver", "krylov")),
        Run3D("default-1.40M", "ramped", _brain("--tets", str(PAPER_TETS)))],
}


def mesh_file(cache: Path, tets: int) -> Path:
    """The cached template mesh of about ``tets`` tets, built by ``brainbulge mesh`` if
    missing."""
    path = cache / f"mesh_{tets}" / "brain.npz"
    if not path.is_file():
        subprocess.run([sys.executable, "-m", "brainbulge", "mesh", "--tets", str(tets),
                        "--no-figures", "--out", str(path.parent), "--overwrite"],
                       check=True, capture_output=True, env=child_env())
    return path


def child_env() -> dict[str, str]:
    """The environment of a run: one OpenMP thread unless the caller chose."""
    return {**os.environ, "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "1")}


def command(run: Run3D, out: Path, cache: Path) -> list[str]:
    """The run's full command line, its meshes built."""
    meshes = {f"{{mesh:{n}}}": str(mesh_file(cache, n)) for n in run.meshes()}
    argv = [meshes.get(a, a).replace("{out}", str(out)) for a in run.argv]
    return [sys.executable, "-m", "brainbulge", *argv, "--overwrite"]


def row_from_summary(s: dict, case: str, variant: str) -> dict:
    """A table row from a run's ``summary.json``: Krylov iterations only with GMRES; a
    failed Newton solve from a given state (no load step recorded) from its message."""
    inputs = s.get("inputs") or {}
    newton, residual = s.get("newton_iterations"), s.get("final_residual")
    stalled = STALLED.search(s.get("message") or "")
    if not s.get("converged", True) and not s.get("load_steps") and stalled:
        newton, residual = int(stalled[2]), float(stalled[1])
    krylov = inputs.get("linear_solver") == "krylov" or bool(s.get("linear_iterations"))
    return {"case": case, "variant": variant, "converged": bool(s.get("converged", True)),
            "load": s.get("load_reached", 1.0), "newton": newton,
            "gmres": s.get("linear_iterations") if krylov else None,
            "residual": residual, "solve_s": s.get("wall_time_s"),
            "tets": s.get("elements"), "bulge_ml": s.get("bulge_volume_ml"),
            "monro_mm": s.get("midline_shift_mm"),
            "strained_ml": s.get("strained_volume_ml")}


def peak_mb(time_output: str) -> float | None:
    """The largest resident set [MB] from ``/usr/bin/time -v``'s report, if there."""
    for line in time_output.splitlines():
        if "Maximum resident set size" in line:
            return int(line.rsplit(":", 1)[1]) / 1024
    return None


def row_from_log(text: str, case: str, variant: str) -> dict:
    """A row from the ``brainbulge.log`` of a run stopped before its summary: the last
    accepted load, the Newton iterations of the accepted load steps, the last scaled
    residual logged."""
    accepted = ACCEPTED.findall(text)
    residuals = RESIDUAL.findall(text)
    return {"case": case, "variant": variant, "converged": "stopped",
            "load": float(accepted[-1][0]) if accepted else 0.0,
            "newton": sum(int(n) for _, n in accepted), "gmres": None,
            "residual": float(residuals[-1]) if residuals else None, "solve_s": None,
            "tets": None, "bulge_ml": None, "monro_mm": None, "strained_ml": None}


def run_3d(run: Run3D, out: Path, cache: Path, time_limit: float | None = None
           ) -> list[dict]:
    """Run ``run`` into ``out`` and return its rows: one per summary; stopped (SIGTERM)
    after ``time_limit`` [s], one per log; an error row when there is neither."""
    argv = command(run, out, cache)
    timer = Path(TIMER).is_file()
    report = out.parent / f"{out.name}.time"
    if timer:
        argv = [TIMER, "-v", "-o", str(report), *argv]
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=child_env(), start_new_session=True)
    try:
        _, err = proc.communicate(timeout=time_limit)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGTERM)  # the run's own group: the timer and brainbulge
        _, err = proc.communicate()
    wall = time.perf_counter() - t0
    peak = peak_mb(report.read_text()) if timer and report.is_file() else None
    rows = []
    for path in sorted(out.glob(run.summaries)):
        case = run.case if run.case != "study" else path.parent.name
        rows.append({**row_from_summary(json.loads(path.read_text()), case, run.variant),
                     "run_s": wall, "peak_mb": peak})
    if not rows:
        for path in sorted(out.glob(run.summaries.replace("summary.json", "brainbulge.log"))):
            case = run.case if run.case != "study" else path.parent.name
            rows.append({**row_from_log(path.read_text(), case, run.variant),
                         "run_s": wall, "peak_mb": peak})
    if not rows:
        last = (err.strip().splitlines() or ["no output"])[-1]
        rows.append({"case": run.case, "variant": run.variant, "error": last, "run_s": wall})
    return rows


HEADER = ("| case | variant | tets | converged | load | Newton | GMRES | final scaled R | "
          "solve s | run s | peak MB | bulge ml | Monro mm | strained ml |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")


def _num(v, fmt: str) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)


def format_row(r: dict) -> str:
    """A markdown row of :data:`HEADER`."""
    if "error" in r:
        return f"| {r['case']} | {r['variant']} | error: {r['error']} | {r['run_s']:.0f} s |"
    newton = _num(r["newton"], "d") + ("+" if r["converged"] == "stopped" else "")
    return (f"| {r['case']} | {r['variant']} | {_num(r['tets'], ',')} | {r['converged']} | "
            f"{r['load']:.3f} | {newton} | {_num(r['gmres'], ',')} | "
            f"{_num(r['residual'], '.1e')} | {_num(r['solve_s'], '.0f')} | "
            f"{r['run_s']:.0f} | {_num(r['peak_mb'], ',.0f')} | "
            f"{_num(r['bulge_ml'], '.1f')} | {_num(r['monro_mm'], '+.2f')} | "
            f"{_num(r['strained_ml'], '.1f')} |")
