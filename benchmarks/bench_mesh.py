"""Benchmark of the MRI -> tet mesh pipeline on the ICBM152 template.

Run ``python benchmarks/bench_mesh.py [--sizes 100000 400000 1300000] [--refine K]``. Each
size runs in a fresh subprocess (so peak memory is its own) and the table gives: tets and
nodes reached, wall time per stage (envelope, Netgen tet meshing at ``size / 8**K``, tissue
tags with the fitted interfaces, the K uniform refinements, sides / base / flaps), total, peak
resident memory, minimum dihedral angle, tets under 10 deg, and the largest tissue-volume
difference to the voxels.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

from brainbulge.runtime import configure as configure_runtime
from memory import peak_mb


def one(target_tets: int, refinements: int = 0) -> dict:
    """Build one mesh and return its numbers."""
    from brainbulge.geometry.brain import build_brain_mesh

    t0 = time.perf_counter()
    mesh = build_brain_mesh(target_tets=target_tets, refinements=refinements)
    total = time.perf_counter() - t0
    q = mesh.quality()
    vols = mesh.tissue_volumes_ml()
    rel = max(abs(vols[k] / v - 1) for k, v in mesh.voxel_volumes_ml.items() if v > 0)
    return {
        "target": target_tets, "tets": q["tets"], "nodes": q["nodes"], "total_s": total,
        **{f"{k}_s": v for k, v in mesh.timings_s.items()},
        "peak_mb": peak_mb(),
        "min_dihedral_deg": q["min_dihedral_deg"], "below_10deg": q["tets_below_10deg"],
        "inverted": q["inverted_tets"], "max_volume_error": rel,
        "flap_cm2": {n: round(mesh.flap_area_cm2(n), 1) for n in mesh.flaps},
    }


def main() -> int:
    configure_runtime()
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sizes", type=int, nargs="+", default=[100_000, 400_000, 1_300_000])
    parser.add_argument("--refine", type=int, default=0, metavar="K")
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print("RESULT " + json.dumps(one(args.one, args.refine)), flush=True)
        return 0
    header = (f"{'target':>9} {'tets':>9} {'nodes':>8} {'envelope s':>10} {'netgen s':>9} "
              f"{'tags s':>7} {'refine s':>8} {'bounds s':>8} {'total s':>8} {'peak MB':>8} "
              f"{'min dih':>8} {'<10deg':>7} {'max dV':>7}  flaps cm2")
    print(header)
    for n in args.sizes:
        proc = subprocess.run([sys.executable, __file__, "--one", str(n), "--refine",
                               str(args.refine)], capture_output=True, text=True)
        lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
        if proc.returncode or not lines:
            print(f"{n:>9} failed: {proc.stderr.strip().splitlines()[-1:]}")
            continue
        r = json.loads(lines[-1][7:])
        print(f"{r['target']:>9} {r['tets']:>9} {r['nodes']:>8} {r['envelope_s']:>10.1f} "
              f"{r['tetmesh_s']:>9.1f} {r['tags_s']:>7.1f} {r.get('refine_s', 0.0):>8.1f} "
              f"{r['boundaries_s']:>8.1f} {r['total_s']:>8.1f} "
              f"{r['peak_mb']:>8.0f} {r['min_dihedral_deg']:>8.1f} {r['below_10deg']:>7} "
              f"{100 * r['max_volume_error']:>6.2f}%  {r['flap_cm2']}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
