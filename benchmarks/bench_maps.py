"""Cost of a 3D run's NIfTI maps (``maps/``, results/export/nifti.py) on the template's grid.

Run ``python benchmarks/bench_maps.py [--tets 30000] [--cache DIR] [--mesh brain.npz]``: the
ICBM152 mesh of about ``--tets`` tets is built (or reused from ``--cache``, or read from
``--mesh``, which must record its image grid), its problem set up with the left flap, and
the maps written for the state at Js = 1 (what a voxel costs does not depend on the state:
the same points are located and the same fields interpolated). The table gives the located
voxels and the time of each part: the vertex fields every run computes for ``fields.vtu``
(for reference) and again keeping the maps' fields at each element's corners, the voxel
centres located in the mesh (rasterised), the fields interpolated there, the deformed label
map, and the whole of ``write_maps`` (all of it, files compressed and the figure drawn);
and the peak resident memory.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from brainbulge.runtime import configure as configure_runtime
from memory import peak_mb


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tets", type=int, default=30000)
    p.add_argument("--cache", type=Path, default=Path("bench-maps-cache"))
    p.add_argument("--mesh", type=Path, default=None)
    args = p.parse_args()
    configure_runtime()
    from brainbulge.geometry.brain import build_brain_mesh, load_brain_mesh, save_brain_mesh
    from brainbulge.model.brain import CraniectomyCase, brain_problem, open_case_flap
    from brainbulge.results.export.nifti import (
        locate_voxels,
        map_fields,
        voxel_values,
        write_maps,
    )
    from brainbulge.results.export.writers import vertex_fields
    from brainbulge.results.measures.recovery import recovered_gradient
    from brainbulge.solver import MixedForm

    path = args.mesh or args.cache / f"brain_{args.tets}" / "brain.npz"
    if not path.is_file():
        save_brain_mesh(build_brain_mesh(target_tets=args.tets), path.parent, figures=False)
    bm = load_brain_mesh(path)
    if bm.image_grid is None:
        raise SystemExit(f"{path} does not record its image grid: rebuild it")
    case = CraniectomyCase(flap="left")
    open_case_flap(bm, case)
    form = MixedForm(brain_problem(bm, case), element=case.element)
    centre = bm.envelope.centre_mm()
    rows = {}
    t = time.perf_counter()
    G = recovered_gradient(form.mesh, form.output_displacement())
    vf = vertex_fields(form, centre, gradient=G)
    rows["vertex fields (fields.vtu), for reference"] = time.perf_counter() - t
    t = time.perf_counter()
    vf = vertex_fields(form, centre, gradient=G, corners=map_fields())
    rows["the same, keeping the maps' fields at the corners"] = time.perf_counter() - t
    locate_voxels(vf.points[:0], vf.cells[:0], bm.image_grid)  # numba's compiled kernels loaded
    t = time.perf_counter()
    hits = locate_voxels(vf.points, vf.cells, bm.image_grid)
    rows["locate the voxel centres"] = time.perf_counter() - t
    t = time.perf_counter()
    voxel_values(hits, vf.corner_data)
    rows["interpolate the fields there"] = time.perf_counter() - t
    t = time.perf_counter()
    locate_voxels(vf.points + vf.point_data["u"], vf.cells, bm.image_grid, weights=False)
    rows["locate in the deformed mesh"] = time.perf_counter() - t
    t = time.perf_counter()
    write_maps(vf, bm.image_grid, args.cache / "maps")
    rows["write_maps (all of maps/)"] = time.perf_counter() - t
    import nibabel as nib
    import numpy as np

    from brainbulge.results.export.nifti import save_nifti

    img = nib.load(args.cache / "maps" / "max_principal_strain.nii.gz")
    img = nib.Nifti1Image(np.asarray(img.dataobj), img.affine)
    t = time.perf_counter()
    save_nifti(img, args.cache / "one.nii.gz")
    rows["of which one float32 map written (gzip)"] = time.perf_counter() - t
    peak = peak_mb()
    print(f"{len(bm.tets):,} tets, grid {bm.image_grid.shape}, {len(hits.index):,} voxels "
          f"located, peak {peak:,.0f} MB")
    print("| part | s |\n|---|---|")
    for name, seconds in rows.items():
        print(f"| {name} | {seconds:.1f} |")


if __name__ == "__main__":
    main()
