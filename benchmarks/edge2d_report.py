"""Reports of the resolved-edge prototype (:mod:`bench_edge_2d`): the per-solve trace of
``--trace`` and the sector study's sweep of ``--sweep``."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np


def print_trace(its_log: list[tuple], history: list[list[float]]) -> None:
    """Per Newton solve (one load step's attempt), on stderr: load, iterations, capped
    iterations and their mean cap factor, the residual history, the penetrating Gauss points
    and how many entered / left the set per iteration."""
    k = 0
    for h in history:
        n = len(h) - 1
        rows = its_log[k:k + n]
        k += n
        if not rows:
            print(f"solve: 0 its |R| {h[0]:.1e}", file=sys.stderr)
            continue
        capped = [r[1] for r in rows if r[1] < 1]
        res = " ".join(f"{v:.0e}" for v in h)
        churn = " ".join(f"{r[3]}+{r[4]}-{r[5]}" for r in rows)
        print(f"load {rows[0][0]:.4f}: {n} its, capped {len(capped)}"
              f" (f {np.mean(capped) if capped else 1:.2f}) |R| {res} | set {churn}",
              file=sys.stderr)


def sweep(script: str, args: list[str]) -> None:
    """The sector study's scenarios, each with ``args`` (the last --alpha / --beta /
    --contact win): a Markdown table row per run, and the totals."""
    from brainbulge.studies.hemidisk import SECTOR_ALPHAS, SECTOR_BETAS

    print("| scenario | load | Newton | crossing [R] | u_y top [R] | wall s |")
    print("|---|---|---|---|---|---|")
    total_its, total_wall, full = 0, 0.0, 0
    for contact in ("noslip", "sliding"):
        for beta in SECTOR_BETAS:
            for alpha in SECTOR_ALPHAS:
                name = f"{contact}_a{alpha:g}_b{beta:g}"
                cmd = [sys.executable, script, *args, "--alpha", str(alpha), "--beta",
                       str(beta), "--contact", contact]
                out = subprocess.run(cmd, capture_output=True, text=True)
                try:
                    r = json.loads(out.stdout.strip().splitlines()[-1])
                except (IndexError, json.JSONDecodeError):
                    print(f"| {name} | failed: {out.stderr[-120:]!r} |", flush=True)
                    continue
                its = r.get("newton_all", r["newton"])
                total_its += its
                total_wall += r["wall_s"]
                full += r["converged"]
                print(f"| {name} | {r['load']} | {its} | {r['crossing_round']:.1e} | "
                      f"{r['top_uy']:.5f} | {r['wall_s']} |", flush=True)
    print(f"\n{full} at full load; {total_its} Newton iterations, {total_wall:.0f} s of "
          "solves in all")
