"""3D sensitivity of the stretch extremes to the choices the paper does not fix, one at a time.

The default scenario (left flap, both hemispheres swelling, ``brainbulge brain``) on the
100k-tet template (Netgen gives about 111k tets), GMRES + AMG, each variant one process
(``OMP_NUM_THREADS=1`` unless set), changing one thing against the baseline (8 mm edge,
1 cm superior band, the base's cut plane at 12 % of the height, the paper's CSF):

- ``edge``: the skull's cut edge rounded 8 / 4 / 2 mm (``--skull-edge-radius``);
- ``band``: the fixed superior band 0 / 1 / 2 cm wide (``--fix inferior`` /
  ``--superior-width``);
- ``base``: the fixed base's cut plane ``BASE_SHIFTS_MM`` lower / higher (a mesh of its own,
  ``brainbulge mesh --base-z``);
- ``csf``: the CSF's Mooney-Rivlin constants x0.1 / x1 / x10 (the ``paper`` preset scaled in
  the run's process);
- ``mesh`` (``--mesh-428k``, hours): the 428k-tet template (``--tets 400000``).

Per run the table gives the measures of the paper's three zones over three regions of the
parenchyma (:func:`zone_measures`): the radial stretch's 1st percentile (``p01``, by
volume) and 0.1 ml peak, the tangential stretch's 0.1 ml peak; ``band``: within ``BAND_MM``
of the flap's rim (left out of the summaries' extremes: the edge is singular there);
``ring``: from there to ``RING_MM``; ``deep``: under the flap and farther than ``RING_MM``
from the rim (vertex values, each vertex weighing a quarter of its tets' volumes); beside
them the summary's own ``p01_radial_stretch``, ``peak_radial_stretch`` and
``peak_tangential_stretch`` (integration points of the parenchyma outside the 5 mm rim band).
The paper's values: radial up to 1.3 and down to 0.7, tangential up to 1.3. A run that does
not converge is a row with its load reached.

Rerun: ``python benchmarks/bench_sensitivity_3d.py --cache CACHE --out OUT`` (about 10 min
per run beside other work; a run whose ``summary.json`` is in ``OUT`` is read, not rerun;
``--only NAME ...`` picks variants; ``--table`` only reads).
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

#: the template's size asked of Netgen [tets] (111k tets)
TETS = h3.PLAN_TETS
#: the ring around the opening and the deep bulge's distance from the rim [mm]
RING_MM = 25.0
#: the band along the rim that the summaries' max_* leave out (``--edge-exclusion``) [mm]
BAND_MM = 5.0
#: the base's cut plane moved by these [mm] (negative: lower, more of the brain free)
BASE_SHIFTS_MM = (-10.0, 10.0)
#: the paper's values: radial stretch up to / down to, tangential stretch up to
PAPER = {"radial_peak": 1.3, "radial_p01": 0.7, "tangential_peak": 1.3}
#: the volume of a peak set [ml]
PEAK_ML = 0.1


@dataclasses.dataclass(frozen=True)
class Variant:
    """One run: ``factor`` and ``value`` name it; ``argv``: options of ``brainbulge brain``
    beside the baseline's; ``base_shift_mm``: the base's cut plane moved; ``csf_scale``: the
    CSF's constants scaled; ``tets``: the template's size."""

    factor: str
    value: str
    argv: tuple[str, ...] = ()
    base_shift_mm: float = 0.0
    csf_scale: float = 1.0
    tets: int = TETS

    @property
    def name(self) -> str:
        return f"{self.factor}-{self.value}".replace(" ", "")


VARIANTS: list[Variant] = [
    Variant("baseline", "8mm-1cm-base-csf"),
    Variant("edge", "4mm", ("--skull-edge-radius", "4")),
    Variant("edge", "2mm", ("--skull-edge-radius", "2")),
    Variant("band", "0cm", ("--fix", "inferior")),
    Variant("band", "2cm", ("--superior-width", "20")),
    Variant("csf", "x10", csf_scale=10.0),
    Variant("csf", "x0.1", csf_scale=0.1),
    *(Variant("base", f"{s:+g}mm", base_shift_mm=s) for s in BASE_SHIFTS_MM),
]
MESH_428K = Variant("mesh", "428k", tets=400_000)


def mesh_for(v: Variant, cache: Path) -> Path:
    """The cached template of ``v``: the shared one, or one with its base moved."""
    if not v.base_shift_mm:
        return h3.mesh_file(cache, v.tets)
    path = cache / f"mesh_{v.tets}_base{v.base_shift_mm:+g}" / "brain.npz"
    if not path.is_file():
        from brainbulge.geometry.brain import load_brain_mesh

        base_z = load_brain_mesh(h3.mesh_file(cache, v.tets)).base_z_mm + v.base_shift_mm
        subprocess.run([sys.executable, "-m", "brainbulge", "mesh", "--tets", str(v.tets),
                        "--base-z", f"{base_z:.3f}", "--no-figures", "--out",
                        str(path.parent), "--overwrite"], check=True, capture_output=True,
                       env=h3.child_env())
    return path


def run_variant(v: Variant, out: Path, cache: Path) -> float:
    """Run ``v`` into ``out`` (``brainbulge brain``, the CSF scaled in the process); the
    process's peak memory [MB] is written beside it. Returns the wall time [s]."""
    argv = ["brain", "--mesh", str(mesh_for(v, cache)), "--linear-solver", "krylov",
            *v.argv, "--out", str(out), "--overwrite"]
    cmd = [sys.executable, __file__, "--csf-scale", repr(v.csf_scale), *argv]
    report = out.parent / f"{out.name}.time"
    if Path(h3.TIMER).is_file():
        cmd = [h3.TIMER, "-v", "-o", str(report), *cmd]
    t0 = time.perf_counter()
    subprocess.run(cmd, env=h3.child_env(), capture_output=True)
    return time.perf_counter() - t0


@dataclasses.dataclass
class RimGeometry:
    """A run's vertex fields (``vf``, :func:`~brainbulge.results.export.writers.
    load_vertex_fields`) placed against its flap: ``weights`` a quarter of each vertex's tets'
    volumes [mm^3] (vertices are per region, so they sum to a region's volume), ``parenchyma``
    the vertices and ``tissue_tets`` the tets of the parenchyma, ``rim`` and ``under`` each
    vertex's distance to the flap's rim [mm] and whether it lies inside the cutter, ``rim_of``
    the rim distance of any points [mm]."""

    vf: object
    weights: np.ndarray
    parenchyma: np.ndarray
    tissue_tets: np.ndarray
    rim: np.ndarray
    under: np.ndarray
    rim_of: object
    centre: np.ndarray


def rim_geometry(run: Path, mesh: Path, flap: str = "left") -> RimGeometry:
    """The :class:`RimGeometry` of a run's ``fields.npz`` on its mesh ``mesh`` (``brain.npz``)
    and flap ``flap``; the rim is where the cutting cylinder meets the skull's inner surface."""
    from brainbulge.geometry.brain import load_brain_mesh
    from brainbulge.geometry.brain.skull import RigidSkull
    from brainbulge.results.export.writers import load_vertex_fields
    from brainbulge.studies.craniectomy import PARENCHYMA

    vf = load_vertex_fields(run / "fields.npz")
    bm = load_brain_mesh(mesh)
    skull, cut = RigidSkull(bm.envelope, bm.flaps[flap]), bm.flaps[flap]
    X, cells = np.asarray(vf.points, float), np.asarray(vf.cells)
    edges = X[cells[:, 1:]] - X[cells[:, :1]]
    vol = np.abs(np.linalg.det(edges)) / 6.0  # [mm^3]
    w = np.bincount(cells.ravel(), np.repeat(vol / 4.0, 4), minlength=len(X))
    names = np.asarray(vf.region_names).astype(str)
    tissue = np.array([bool(re.fullmatch(PARENCHYMA, n)) for n in names])
    tissue_tets = tissue[np.asarray(vf.regions)]
    par = np.zeros(len(X), bool)
    par[cells[tissue_tets].ravel()] = True

    def rim_of(points: np.ndarray) -> np.ndarray:
        return np.hypot(cut.cutter_distance(points)[0],
                        skull.envelope_distance(points, gradient=False)[0])

    return RimGeometry(vf, w, par, tissue_tets, rim_of(X), cut.cutter_distance(X)[0] < 0,
                       rim_of, bm.envelope.centre_mm())


def volume_peaks(g: RimGeometry, mask: np.ndarray, prefix: str) -> dict[str, float]:
    """``<prefix>_radial_p01`` (the radial stretch exceeded by all but 1 % of the vertices'
    volume in ``mask``), ``<prefix>_radial_peak`` and ``<prefix>_tangential_peak`` (exceeded
    in :data:`PEAK_ML`)."""
    w = g.weights[mask]
    lam_n, lam_t = g.vf.point_data["lambda_n"][mask], g.vf.point_data["lambda_t"][mask]
    return {f"{prefix}_radial_p01": _volume_quantile(lam_n, w, 0.01 * w.sum()),
            f"{prefix}_radial_peak": -_volume_quantile(-lam_n, w, 1000 * PEAK_ML),
            f"{prefix}_tangential_peak": -_volume_quantile(-lam_t, w, 1000 * PEAK_ML)}


def zone_measures(run: Path, mesh: Path, flap: str = "left") -> dict[str, float]:
    """The three zones' measures of a run's vertex fields (``fields.npz``): ``<zone>_<measure>``
    for the parenchyma's zones ``band`` (within :data:`BAND_MM` of the flap's rim, where the
    edge is singular), ``ring`` (from there to :data:`RING_MM`) and ``deep`` (under the flap,
    farther than :data:`RING_MM` from the rim), the measures of :func:`volume_peaks`. Each
    vertex weighs a quarter of its tets' volumes (vertices are per region, so the weights sum
    to the zone's volume)."""
    g = rim_geometry(run, mesh, flap)
    par, rim = g.parenchyma, g.rim
    zones = {"band": par & (rim < BAND_MM), "ring": par & (rim >= BAND_MM) & (rim < RING_MM),
             "deep": par & g.under & (rim >= RING_MM)}
    out = {}
    for zone, mask in zones.items():
        out.update(volume_peaks(g, mask, zone))
    return out


def _volume_quantile(v: np.ndarray, w: np.ndarray, volume: float) -> float:
    """The smallest value of ``v`` below which at least ``volume`` of the weights ``w`` lie."""
    order = np.argsort(v)
    k = min(int(np.searchsorted(np.cumsum(w[order]), volume)), len(v) - 1)
    return float(v[order][k])


ZONE_COLUMNS = [(f"{z}_{m}", f"{m.replace('_', ' ')} {z}") for m in PAPER
                for z in ("band", "ring", "deep")]
#: the summary's own measures (integration points, parenchyma outside its rim band) beside
#: the zones'
SUMMARY_COLUMNS = {"radial_p01": "p01_radial_stretch", "radial_peak": "peak_radial_stretch",
                   "tangential_peak": "peak_tangential_stretch"}


#: the empty cells of a row without fields
EMPTY = " |" * (len(ZONE_COLUMNS) + len(SUMMARY_COLUMNS) + 1)


def variant_row(v: Variant, out: Path, cache: Path) -> str:
    """The table row of ``v`` from its folder in ``out``."""
    folder = out / v.name
    summary = folder / "summary.json"
    wall = out / f"{v.name}.wall"
    wall_s = float(wall.read_text()) if wall.is_file() else math.nan
    time_report = out / f"{v.name}.time"
    report = time_report.read_text() if time_report.is_file() else ""
    peak = h3.peak_mb(report)
    if math.isnan(wall_s):
        wall_s = elapsed_s(report)
    head = f"| {v.factor} | {v.value} |"
    if not summary.is_file():
        log = folder / "brainbulge.log"
        r = h3.row_from_log(log.read_text(), v.factor, v.value) if log.is_file() else None
        load = f"load {r['load']:.3f}" if r else "no log"
        return head + f" no: {load} |" + EMPTY + f" {wall_s:.0f} |"
    s = json.loads(summary.read_text())
    conv = "yes" if s.get("converged", True) and s.get("load_reached", 1) >= 1 else (
        f"no: load {s.get('load_reached', 0):.3f}")
    if not (folder / "fields.npz").is_file():
        return head + f" {conv} |" + EMPTY + f" {wall_s:.0f} |"
    z = zone_measures(folder, mesh_for(v, cache))
    cells = [f"{z[k]:.3f}" for k, _ in ZONE_COLUMNS]
    cells += [f"{s[k]:.3f}" for k in SUMMARY_COLUMNS.values()]
    return (head + f" {conv} | {s.get('elements', 0):,} | " + " | ".join(cells)
            + f" | {wall_s:.0f} | {h3._num(peak, ',.0f')} |")


def elapsed_s(time_report: str) -> float:
    """The wall time [s] from ``/usr/bin/time -v``'s report (NaN without one)."""
    for line in time_report.splitlines():
        if "Elapsed (wall clock)" in line:
            parts = [float(p) for p in line.rsplit(": ", 1)[1].split(":")]
            return sum(p * 60 ** k for k, p in enumerate(reversed(parts)))
    return math.nan


def print_table(variants: list[Variant], out: Path, cache: Path) -> None:
    print("| factor | value | converged | tets | " + " | ".join(c for _, c in ZONE_COLUMNS)
          + " | " + " | ".join(f"summary {k}" for k in SUMMARY_COLUMNS)
          + " | run s | peak MB |")
    print("|---" * (6 + len(ZONE_COLUMNS) + len(SUMMARY_COLUMNS)) + "|")
    paper = [PAPER[k.split("_", 1)[1]] for k, _ in ZONE_COLUMNS] + list(
        PAPER[k] for k in SUMMARY_COLUMNS)
    print("| paper | | | | " + " | ".join(f"{p:g}" for p in paper) + " | | |")
    for v in variants:
        print(variant_row(v, out, cache), flush=True)


def scaled_csf_main(scale: float, argv: list[str]) -> int:
    """``brainbulge ARGV`` with the ``paper`` preset's CSF constants times ``scale``."""
    from brainbulge.cli import main
    from brainbulge.materials.presets import PRESETS

    c1, c2 = PRESETS["paper"]["csf"]
    PRESETS["paper"]["csf"] = (c1 * scale, c2 * scale)
    return main(argv)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, default=Path("sensitivity-3d-cache"),
                    help="the meshes, built once")
    ap.add_argument("--out", type=Path, default=Path("sensitivity-3d-out"),
                    help="one folder per run; a run with its summary.json is read, not rerun")
    ap.add_argument("--only", nargs="+", help="the variants' names to run")
    ap.add_argument("--mesh-428k", action="store_true", help="also the 428k-tet template")
    ap.add_argument("--table", action="store_true", help="only read the runs in --out")
    ap.add_argument("--no-table", action="store_true", help="only run")
    args = ap.parse_args()
    variants = VARIANTS + ([MESH_428K] if args.mesh_428k else [])
    if args.only:
        variants = [v for v in variants if v.name in args.only]
    args.cache.mkdir(parents=True, exist_ok=True)
    args.out.mkdir(parents=True, exist_ok=True)
    if not args.table:
        for v in variants:
            if not (args.out / v.name / "summary.json").is_file():
                wall = run_variant(v, args.out / v.name, args.cache)
                (args.out / f"{v.name}.wall").write_text(f"{wall:.1f}\n")
                print(f"{v.name}: {wall:.0f} s", flush=True)
    if not args.no_table:
        print_table(variants, args.out, args.cache)


if __name__ == "__main__":
    if sys.argv[1:2] == ["--csf-scale"]:
        sys.exit(scaled_csf_main(float(sys.argv[2]), sys.argv[3:]))
    main()
