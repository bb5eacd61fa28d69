"""The 2D headline's region measures at two meshes: which extremes converge, which are singular.

``brainbulge hemidisk`` (alpha 80, beta 60, Js 1.2, the paper's skull), no-slip and sliding, at
the default element size and at half of it (corners and rims scale with it). From each run's
vertex fields, the extremes over two regions:

- ``deep``: the bulge farther than ``DEEP_R`` from every singular point (the opening's
  corners, where the sector's edges meet the arc, the base's centre);
- ``ring``: ``RING_R`` from the opening's corners (the edge ring; the corners themselves
  left out).

Per measure the table gives both meshes' values and the change; a rise beyond ``CONVERGED``
(5 %) names the measure singular (it grows as the mesh refines), a fall beyond it not
converged. Below it, the
ratios of the contacts that trends (iv) (no-slip / sliding of the deep radial maximum) and
(v) (sliding / no-slip of the ring's tangential maximum) compare, per mesh.

Rerun: ``python benchmarks/bench_region_measures_2d.py [--out DIR]`` (four runs, about
2 min on one core beside other work; ``--h`` sets the coarse size).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

#: the regions' bounds [R]: deep beyond DEEP_R of every singular point, the ring between
#: RING_R of the opening's corners
DEEP_R, RING_R = 0.2, (0.05, 0.2)
#: a measure that changes by more than this between the two meshes is singular
CONVERGED = 0.05
#: (region, field, kind, label) of the measures
MEASURES = (("deep", "lambda_n", "max", "deep max lambda_n"),
            ("deep", "lambda_t", "max", "deep max lambda_t"),
            ("ring", "lambda_t", "max", "ring max lambda_t"),
            ("ring", "lambda_n", "min", "ring min lambda_n"),
            ("ring", "max_shear_stress", "max", "ring max shear stress [kPa]"),
            ("all", "u_magnitude", "max", "max |u| [R]"))


def region_measures(fields: Path, summary: dict) -> dict[str, float]:
    """The :data:`MEASURES` of one run's ``fields.npz`` (vertex values, reference positions)."""
    from brainbulge.results.export.writers import load_vertex_fields

    vf = load_vertex_fields(fields)
    X = vf.points[:, :2]
    singular = np.asarray(summary["singular_points"], dtype=float)
    beta = math.radians(float(summary["inputs"]["beta"]) / 2)
    corners = np.array([[math.sin(beta), math.cos(beta)], [-math.sin(beta), math.cos(beta)]])
    d_sing = np.min(np.linalg.norm(X[:, None] - singular[None], axis=2), axis=1)
    d_corner = np.min(np.linalg.norm(X[:, None] - corners[None], axis=2), axis=1)
    regions = {"deep": d_sing > DEEP_R, "ring": (d_corner >= RING_R[0]) & (d_corner <= RING_R[1]),
               "all": np.ones(len(X), bool)}
    out = {}
    for region, field, kind, label in MEASURES:
        v = vf.point_data[field][regions[region]]
        out[label] = float(v.max() if kind == "max" else v.min())
    return out


def run(contact: str, h: float, out: Path) -> dict[str, float]:
    """``brainbulge hemidisk`` of the headline with ``contact`` at element size ``h`` into
    ``out``, and its region measures."""
    folder = out / f"{contact}_h{h:g}"
    if not (folder / "summary.json").is_file():
        env = {**os.environ, "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "1")}
        subprocess.run([sys.executable, "-m", "brainbulge", "hemidisk", "--contact", contact,
                        "--mesh-size", f"{h:g}", "--corner-mesh-size", f"{h / 5:g}",
                        "--rim-mesh-size", f"{h / 10:g}", "--out", str(folder),
                        "--overwrite"], check=True, capture_output=True, env=env)
    summary = json.loads((folder / "summary.json").read_text())
    return region_measures(folder / "fields.npz", summary)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--h", type=float, default=0.05, help="the coarse element size [R]")
    ap.add_argument("--out", type=Path, default=None, help="keep the runs here")
    args = ap.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="regions2d-"))
    sizes = (args.h, args.h / 2)
    res = {(c, h): run(c, h, out) for c in ("noslip", "sliding") for h in sizes}
    print(f"| contact | measure | h {sizes[0]:g} | h {sizes[1]:g} | change | verdict |")
    print("|---|---|---|---|---|---|")
    for c in ("noslip", "sliding"):
        for _, _, _, label in MEASURES:
            a, b = res[(c, sizes[0])][label], res[(c, sizes[1])][label]
            change = b / a - 1
            verdict = ("converged" if abs(change) <= CONVERGED else
                       "singular (grows)" if change > 0 else "not converged (falls)")
            print(f"| {c} | {label} | {a:.4g} | {b:.4g} | {100 * change:+.1f} % | {verdict} |")
    print()
    print("| mesh h | (iv) no-slip / sliding, deep max lambda_n | "
          "(v) sliding / no-slip, ring max lambda_t |")
    print("|---|---|---|")
    for h in sizes:
        n, s = res[("noslip", h)], res[("sliding", h)]
        print(f"| {h:g} | {n['deep max lambda_n'] / s['deep max lambda_n']:.3f} | "
              f"{s['ring max lambda_t'] / n['ring max lambda_t']:.3f} |")


if __name__ == "__main__":
    main()
