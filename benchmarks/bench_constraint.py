"""How well the incompressibility constraint J = Js holds: MINI against Taylor-Hood at about
equal DOFs, on the 2D headline case (no-slip and sliding, alpha 80, beta 60, Js 1.2).

Prints DOFs and the volume-weighted median, 95th percentile and largest ``|Je - 1|`` (``Je =
J / Js``, at the integration points; docs/model.md section 9). Rerun with
``python benchmarks/bench_constraint.py`` (``--mini-h 0.05 --th-h 0.1``: mesh sizes [R]).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from brainbulge.studies.hemidisk import run_hemidisk


def run(element: str, h: float, contact: str, out: Path) -> dict:
    s = run_hemidisk({"alpha": 80.0, "beta": 60.0, "swelling": 1.2, "contact": contact,
                      "element": element, "mesh_size": h, "name": f"{element}-{h:g}"},
                     out / f"{element}-{h:g}-{contact}")
    return {"element": element, "h": h, "contact": contact, "dofs": s["dofs"],
            "median": s["median_abs_Je_minus_1"], "p95": s["p95_abs_Je_minus_1"],
            "raw_max": s["raw_max_abs_Je_minus_1"], "max_lambda_t": s["max_tangential_stretch"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mini-h", type=float, default=0.05)
    ap.add_argument("--th-h", type=float, default=0.1)
    ap.add_argument("--contacts", nargs="+", default=["noslip"])
    args = ap.parse_args()
    print("| element | h [R] | contact | DOFs | median \\|Je - 1\\| | p95 \\|Je - 1\\| | "
          "max \\|Je - 1\\| | max lambda_t |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for contact in args.contacts:
            for element, h in (("mini", args.mini_h), ("taylor-hood", args.th_h)):
                r = run(element, h, contact, Path(tmp))
                print(f"| {r['element']} | {r['h']:g} | {r['contact']} | {r['dofs']} | "
                      f"{r['median']:.2e} | {r['p95']:.2e} | {r['raw_max']:.2e} | "
                      f"{r['max_lambda_t']:.3f} |")


if __name__ == "__main__":
    main()
