"""Tissue interfaces before and after fitting (geometry/brain/interfaces.py): sphere, template.

Run ``python benchmarks/bench_interfaces.py [--tets 20000 50000] [--icbm 30000]``.

Sphere: a white-matter sphere of radius 20 mm at the centre of a gray-matter ellipsoid
(semi-axes 65, 55, 50 mm; 1 mm voxels), meshed as ``build_brain_mesh`` does (envelope, Netgen,
``tag_tissue``), then fitted. Printed per size: the white/gray interface's area over the
sphere's ``4 pi R^2``, the mean angle between its faces' normals and the radial direction,
the 95th percentile and maximum of its nodes' distance to the sphere (mm), the minimum
dihedral angle (deg) and the white volume over the voxel count's.
``--icbm N``: the ICBM152 template at about N tets: minimum dihedral angle, inverted tets,
and each tissue's mesh volume over its voxel volume, before and after.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from brainbulge.geometry.brain.envelope import intracranial_envelope
from brainbulge.geometry.brain.interfaces import face_neighbours, fit_interfaces
from brainbulge.geometry.brain.labels import TISSUES, WHITE, TissueImage
from brainbulge.geometry.brain.quality import quality_stats
from brainbulge.geometry.brain.regions import MidSagittalPlane, tag_tissue
from brainbulge.geometry.brain.tetmesh import (
    element_size_for,
    mesh_intracranial_volume,
    tet_volumes_mm3,
)

RADIUS_MM = 20.0


def sphere_image(radius_mm: float = RADIUS_MM) -> TissueImage:
    """Gray ellipsoid (65, 55, 50 mm) with a white sphere of ``radius_mm`` at the origin."""
    g = np.arange(-75.0, 75.5, 1.0)
    x, y, z = np.meshgrid(g, g, g, indexing="ij")
    brain = (x / 65) ** 2 + (y / 55) ** 2 + (z / 50) ** 2 <= 1
    white = x**2 + y**2 + z**2 <= radius_mm**2
    tissue = np.where(white, 2, np.where(brain, 1, 0)).astype(np.int8)
    affine = np.diag([1.0, 1.0, 1.0, 1.0])
    affine[:3, 3] = g[0]
    return TissueImage(tissue, affine)


def tagged_mesh(image: TissueImage, target_tets: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Netgen mesh of the image's envelope with ``tag_tissue``'s tags, as build_brain_mesh
    makes them before fitting; and the envelope's voxel volume (ml)."""
    envelope = intracranial_envelope(image)
    nodes, tets = mesh_intracranial_volume(envelope, element_size_for(envelope.volume_ml(),
                                                                      target_tets))
    tissue = tag_tissue(image, nodes, tets, intracranial_volume_ml=envelope.volume_ml(),
                        plane=MidSagittalPlane())
    return nodes, tets, tissue, envelope.volume_ml()


def sphere_metrics(nodes: np.ndarray, tets: np.ndarray, tissue: np.ndarray,
                   radius_mm: float = RADIUS_MM) -> dict[str, float]:
    """Area ratio, mean normal tilt (deg), node distance p95 / max (mm) of the white surface."""
    nb = face_neighbours(tets)
    faces = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
    t, f = np.nonzero((tissue[:, None] == WHITE) & (nb >= 0)
                      & (tissue[np.maximum(nb, 0)] != WHITE))
    tri = tets[t[:, None], faces[f]]
    p = nodes[tri]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area = 0.5 * np.linalg.norm(n, axis=1)
    c = p.mean(axis=1)
    cos = np.abs(np.einsum("ij,ij->i", n, c)) / (np.linalg.norm(n, axis=1)
                                                  * np.linalg.norm(c, axis=1))
    dist = np.abs(np.linalg.norm(nodes[np.unique(tri)], axis=1) - radius_mm)
    vol = tet_volumes_mm3(nodes, tets)
    return {"area_ratio": float(area.sum() / (4 * np.pi * radius_mm**2)),
            "tilt_deg": float(np.degrees(np.arccos(np.clip(cos, 0, 1))).mean()),
            "dist_p95_mm": float(np.percentile(dist, 95)), "dist_max_mm": float(dist.max()),
            "min_dihedral_deg": quality_stats(nodes, tets)["min_dihedral_deg"],
            "white_volume_ratio": float(vol[tissue == WHITE].sum()
                                        / (4 / 3 * np.pi * radius_mm**3))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tets", type=int, nargs="+", default=[20_000, 50_000])
    parser.add_argument("--icbm", type=int, default=0)
    args = parser.parse_args()
    image = sphere_image()
    cols = ["area_ratio", "tilt_deg", "dist_p95_mm", "dist_max_mm", "min_dihedral_deg",
            "white_volume_ratio"]
    print("sphere R = 20 mm: tets  state  " + "  ".join(cols))
    for n in args.tets:
        nodes, tets, tissue, icv = tagged_mesh(image, n)
        t0 = time.perf_counter()
        fitted = fit_interfaces(nodes, tets, tissue, image, intracranial_volume_ml=icv)
        dt = time.perf_counter() - t0
        for state, (x, tag) in (("staircase", (nodes, tissue)), ("fitted", fitted)):
            m = sphere_metrics(x, tets, tag)
            print(f"{len(tets):8d}  {state:9s}  " + "  ".join(f"{m[c]:.3f}" for c in cols))
        print(f"          fit: {dt:.1f} s")
    if args.icbm:
        from brainbulge.geometry.brain.template import icbm152_tissue_image

        image = icbm152_tissue_image()
        nodes, tets, tissue, icv = tagged_mesh(image, args.icbm)
        t0 = time.perf_counter()
        fitted = fit_interfaces(nodes, tets, tissue, image, intracranial_volume_ml=icv)
        dt = time.perf_counter() - t0
        voxel = image.volumes_ml()
        scale = tet_volumes_mm3(nodes, tets).sum() / 1000 / icv
        print(f"ICBM152, {len(tets)} tets (fit {dt:.1f} s): state  min_dihedral  inverted  "
              + "  ".join(f"{name}/voxel" for name in TISSUES.values() if name != "csf"))
        for state, (x, tag) in (("staircase", (nodes, tissue)), ("fitted", fitted)):
            q = quality_stats(x, tets)
            vol = tet_volumes_mm3(x, tets)
            ratios = [vol[tag == c].sum() / 1000 / (voxel[name] * scale)
                      for c, name in TISSUES.items() if name != "csf"]
            print(f"  {state:9s}  {q['min_dihedral_deg']:.2f}  {q['inverted_tets']}  "
                  + "  ".join(f"{r:.4f}" for r in ratios))
        nb = face_neighbours(tets)
        t, f = np.nonzero((nb >= 0) & (tissue[np.maximum(nb, 0)] != tissue[:, None]))
        iface = np.unique(tets[t[:, None], np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3],
                                                     [0, 1, 2]])[f]])
        moved = np.linalg.norm(fitted[0] - nodes, axis=1) > 1e-9
        print(f"  nodes moved: {moved.sum()} ({moved[iface].sum()} of the {len(iface)} "
              f"interface nodes of the staircase); tets re-tagged: "
              f"{(fitted[1] != tissue).sum()} of {len(tets)}")


if __name__ == "__main__":
    main()
