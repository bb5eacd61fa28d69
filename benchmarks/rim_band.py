"""A brain mesh refined in a band around one flap's rim: the rounded cut edge resolved.

A comparison prototype, not the product's meshing. A contact point pressed on a tightly
rounded edge of radius ``rho`` loses tangential stiffness unless the mesh resolves the
rounding: in 2D the same contact converged once the mesh along the edge was ``rho / 3`` to
``rho / 4``. Netgen's STL mesher ignores ``MeshingParameters.RestrictH`` on the surface, so
here a cached template mesh (``brain.npz``) is refined after the fact, conformingly, in a band
around the rim (the curve where the flap's cutting cylinder meets the skull's inner surface;
the distance to it as ``bench_sensitivity_3d.rim_geometry`` takes it, ``hypot(d_cut,
phi_env)`` [mm]): every tet whose centroid lies within ``band_mm`` of the rim gets its longest
edge at most ``h_band_mm`` (``rho / 3``), and outside the band the size grows by ``grading``
[mm per mm of distance], the 2:1-ish transition of bisection.

The refinement is longest-edge bisection (Rivara) with conformity by construction: each round
the candidate edges are the longest edges of the tets still too large for the size at their
distance, closed under "a tet touching a candidate edge adds its own longest edge" (the
longest-edge propagation path); the edges that are the longest edge of every tet containing
them (the terminal edges; ties by edge number) are split at their midpoints, every tet
containing one becomes two. Each tet has one longest edge, so the split edges share no tet,
and every tet is cut across its longest edge (the shapes stay in a bounded set, no sliver
cascade). Children keep their parent's tissue and side (the tissue interfaces keep their
shape: new interior nodes lie on the parents' edges); the boundary faces, their tets, the base
and the flaps' faces are recomputed by the package's own functions, and new outer-surface
nodes are moved onto the envelope (:func:`~brainbulge.geometry.brain.refine.move_onto_surface`,
as the package's uniform refinement does).

Written by hand (NumPy, vectorised): Netgen's ``Refine`` / ``RefineHP`` work on its own mesh
objects, without our tissue tags, sides and the envelope's distance, and refine everywhere or
by its own marks without a conforming local bisection we could steer by the rim's distance.

Rerun: ``python benchmarks/rim_band.py --mesh CACHE/mesh_100000/brain.npz --flap left
--rho 2 --out OUT`` writes ``OUT/brain.npz`` (read by ``brainbulge brain --mesh``) and
``OUT/band.json`` (tets before and after, the checks); ``--run`` then runs the default
scenario on it with ``--skull-edge-radius RHO`` as ``bench_edge_radius_3d.py`` does
(``/usr/bin/time -v`` beside it) and prints its row with the rim measures.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from brainbulge.geometry.brain.boundaries import boundary_faces, face_areas_mm2
from brainbulge.geometry.brain.brain_mesh import BrainMesh, check_brain_mesh
from brainbulge.geometry.brain.quality import tet_volumes_mm3
from brainbulge.geometry.brain.refine import TET_EDGES, move_onto_surface
from brainbulge.geometry.brain.skull import RigidSkull

log = logging.getLogger("rim_band")

#: the band's half-width in edge radii: tets within ``BAND_RHO * rho`` of the rim are refined
#: (from the 111k template, grading 2: a longest edge of rho / 3 within rho gave 1.43M tets,
#: rho / 2 within rho 0.70M; grading 0.5: rho / 2 within 2 rho 1.91M. Bisection's tets are
#: flat, their mean edge well below the longest: rho / 2 gives a mean edge of about rho / 3)
BAND_RHO = 1.0
#: the band's size in edge radii: the longest edge there at most ``rho / RHO_PER_H``
RHO_PER_H = 2.0
#: growth of the size outside the band [mm per mm of distance] (0.5 doubled the added tets
#: against 2: the transition to the template's 4-7 mm longest edges, not the band, dominates)
GRADING = 2.0
#: rounds of bisection at most (each splits the terminal edges of the marked tets' paths)
MAX_ROUNDS = 400


def rim_distance(bm: BrainMesh, flap: str) -> Callable[[np.ndarray], np.ndarray]:
    """``d(x)`` [mm]: the distance of points (n, 3) to the flap's rim, ``hypot(d_cut,
    phi_env)`` (the cutting cylinder's and the skull's inner surface's distances)."""
    cut, skull = bm.flaps[flap], RigidSkull(bm.envelope, None)

    def d(points_mm: np.ndarray) -> np.ndarray:
        return np.hypot(cut.cutter_distance(points_mm)[0],
                        skull.envelope_distance(points_mm, gradient=False)[0])

    return d


def graded_size(h_band_mm: float, band_mm: float, grading: float
                ) -> Callable[[np.ndarray], np.ndarray]:
    """``h(d)`` [mm]: ``h_band_mm`` within ``band_mm`` of the rim, growing by ``grading`` per
    mm beyond."""
    def h(d_mm: np.ndarray) -> np.ndarray:
        return h_band_mm + grading * np.maximum(d_mm - band_mm, 0.0)

    return h


def mesh_edges(tets: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Sorted vertex pairs (n_edges, 2) and each tet's edge numbers (n_tets, 6) in the order
    of :data:`TET_EDGES` (pairs coded as one integer: faster than ``unique(axis=0)``)."""
    pairs = np.sort(tets[:, TET_EDGES], axis=2).reshape(-1, 2).astype(np.int64)
    code, inverse = np.unique(pairs[:, 0] * n_nodes + pairs[:, 1], return_inverse=True)
    return np.stack([code // n_nodes, code % n_nodes], axis=1), inverse.reshape(len(tets), 6)


def bisect_round(nodes: np.ndarray, tets: np.ndarray, too_large: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """One round of conforming longest-edge bisection of the tets ``too_large`` (mask).

    Returns ``(nodes, tets, parent, split)``: the new nodes appended (edge midpoints), each
    tet's parent in the given ``tets``, and how many edges were split."""
    edges, tet_edges = mesh_edges(tets, len(nodes))
    length = np.linalg.norm(nodes[edges[:, 1]] - nodes[edges[:, 0]], axis=1)
    rank = np.empty(len(edges), np.int64)
    rank[np.lexsort((np.arange(len(edges)), length))] = np.arange(len(edges))
    longest = tet_edges[np.arange(len(tets)), np.argmax(rank[tet_edges], axis=1)]
    candidate = np.zeros(len(edges), bool)
    candidate[longest[too_large]] = True
    while True:  # close: a tet touching a candidate adds its longest edge
        touched = candidate[tet_edges].any(axis=1)
        grown = candidate.copy()
        grown[longest[touched]] = True
        if grown.sum() == candidate.sum():
            break
        candidate = grown
    # terminal edges: the longest edge of every tet that contains them
    not_terminal = np.zeros(len(edges), bool)
    other = candidate[tet_edges] & (tet_edges != longest[:, None])
    not_terminal[tet_edges[other]] = True
    split = candidate & ~not_terminal
    new_id = np.full(len(edges), -1, np.int64)
    new_id[split] = len(nodes) + np.arange(split.sum())
    nodes = np.concatenate([nodes, nodes[edges[split]].mean(axis=1)])
    cut = split[longest]  # tets cut this round, each across its longest edge
    a, b = edges[longest[cut], 0], edges[longest[cut], 1]
    m = new_id[longest[cut]]
    parent_tets = tets[cut]
    first = np.where(parent_tets == b[:, None], m[:, None], parent_tets)  # keeps a
    second = np.where(parent_tets == a[:, None], m[:, None], parent_tets)  # keeps b
    idx = np.flatnonzero(cut)
    tets = np.concatenate([tets[~cut], first, second])
    parent = np.concatenate([np.flatnonzero(~cut), idx, idx])
    return nodes, tets, parent, int(split.sum())


def refine_band(nodes: np.ndarray, tets: np.ndarray, distance: Callable[[np.ndarray],
                np.ndarray], size: Callable[[np.ndarray], np.ndarray],
                max_rounds: int = MAX_ROUNDS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bisect ``(nodes, tets)`` [mm] until every tet's longest edge is at most ``size(d)``,
    ``d`` its centroid's ``distance`` less half its longest edge (the tet's near side).
    Returns ``(nodes, tets, parent)``, ``parent[i]`` the original tet that tet ``i`` lies in;
    new nodes are midpoints (appended after the old ones)."""
    parent = np.arange(len(tets))
    for k in range(max_rounds):
        p = nodes[tets]
        longest = _longest_edges(p)
        near = np.maximum(distance(p.mean(axis=1)) - longest / 2, 0.0)
        too_large = longest > size(near)
        if not too_large.any():
            log.info("band: %d rounds, %d tets", k, len(tets))
            return nodes, tets, parent
        nodes, tets, pk, split = bisect_round(nodes, tets, too_large)
        parent = parent[pk]
        log.debug("round %d: %d too large, %d edges split, %d tets", k, too_large.sum(),
                  split, len(tets))
    raise RuntimeError(f"the band is not refined after {max_rounds} rounds")


def _longest_edges(p: np.ndarray) -> np.ndarray:
    """The longest edge [mm] of each tet of vertex coordinates ``p`` (m, 4, 3)."""
    return np.linalg.norm(p[:, TET_EDGES[:, 1]] - p[:, TET_EDGES[:, 0]], axis=2).max(axis=1)


def face_counts(tets: np.ndarray) -> np.ndarray:
    """How many tets share each distinct face (1: outer surface, 2: interior)."""
    f = np.sort(tets[:, [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]].reshape(-1, 3), axis=1)
    n = int(tets.max()) + 1
    _, counts = np.unique((f[:, 0] * n + f[:, 1]) * n + f[:, 2], return_counts=True)
    return counts


def band_mesh(bm: BrainMesh, flap: str = "left", rho_mm: float = 2.0,
              band_rho: float = BAND_RHO, rho_per_h: float = RHO_PER_H,
              grading: float = GRADING) -> tuple[BrainMesh, dict]:
    """``bm`` refined in the band within ``band_rho * rho_mm`` of flap ``flap``'s rim to a
    longest edge of ``rho_mm / rho_per_h`` [mm], graded by ``grading`` beyond; returns the
    refined :class:`BrainMesh` (its flaps the same cutters) and the checks: tets before and
    after, the tissues' volumes before and after the surface move [ml], face counts, the
    outer surface's area before the move [mm^2], quality and the largest longest edge in
    the band [mm]."""
    t0 = time.perf_counter()
    d = rim_distance(bm, flap)
    h_band, band = rho_mm / rho_per_h, band_rho * rho_mm
    nodes, tets, parent = refine_band(bm.nodes_mm, bm.tets, d, graded_size(h_band, band,
                                                                           grading))
    tissue, side = bm.tissue[parent], bm.side[parent]
    info: dict = {"flap": flap, "rho_mm": rho_mm, "band_mm": band, "h_band_mm": h_band,
                  "grading": grading, "tets_before": len(bm.tets), "tets_after": len(tets),
                  "nodes_before": len(bm.nodes_mm), "nodes_after": len(nodes)}
    v0, v1 = bm.tet_volumes_mm3(), tet_volumes_mm3(nodes, tets)
    info["volume_ml"] = [float(v0.sum() / 1000), float(v1.sum() / 1000)]
    info["tissue_volume_change_mm3"] = {
        str(c): float(v1[tissue == c].sum() - v0[bm.tissue == c].sum())
        for c in np.unique(bm.tissue)}
    counts = face_counts(tets)
    info["faces_shared_by"] = {str(k): int((counts == k).sum()) for k in np.unique(counts)}
    faces, face_tet = boundary_faces(tets)
    info["outer_area_mm2"] = [float(face_areas_mm2(bm.nodes_mm, bm.faces).sum()),
                              float(face_areas_mm2(nodes, faces).sum())]
    p = nodes[tets]
    info["band_longest_edge_max_unmoved_mm"] = float(_longest_edges(p)[
        d(p.mean(axis=1)) < band].max(initial=0.0))
    surface_new = np.unique(faces)
    surface_new = surface_new[surface_new >= len(bm.nodes_mm)]
    nodes, stayed = move_onto_surface(nodes, tets, surface_new,
                                      RigidSkull(bm.envelope, None).envelope_distance)
    info["surface_nodes_moved"] = int(len(surface_new) - stayed)
    info["surface_nodes_stayed"] = stayed
    base = nodes[faces][:, :, 2].mean(axis=1) < bm.base_z_mm
    out = BrainMesh(nodes, tets, tissue, side, faces, face_tet, base, bm.base_z_mm,
                    bm.envelope, voxel_volumes_ml=bm.voxel_volumes_ml,
                    midsagittal=bm.midsagittal, image_grid=bm.image_grid)
    for f in bm.flaps.values():
        out.add_flap(f)
    check_brain_mesh(out)
    p = nodes[tets]
    longest = _longest_edges(p)
    in_band = d(p.mean(axis=1)) < band
    info["band_tets"] = int(in_band.sum())
    info["band_tets_before"] = int((d(bm.nodes_mm[bm.tets].mean(axis=1)) < band).sum())
    info["band_longest_edge_max_mm"] = float(longest[in_band].max(initial=0.0))
    info["band_longest_edge_mean_mm"] = float(longest[in_band].mean()) if in_band.any() else 0.0
    band_edges = np.unique(np.sort(tets[in_band][:, TET_EDGES], axis=2).reshape(-1, 2), axis=0)
    info["band_edge_mean_mm"] = float(np.linalg.norm(nodes[band_edges[:, 1]]
                                                     - nodes[band_edges[:, 0]], axis=1).mean())
    info["quality_before"] = bm.quality()
    info["quality"] = out.quality()
    info["tissue_volumes_ml"] = out.tissue_volumes_ml()
    info["flap_faces"] = {n: int(m.sum()) for n, m in out.flap_faces.items()}
    info["seconds"] = time.perf_counter() - t0
    return out, info


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", type=Path, required=True, help="the template's brain.npz")
    ap.add_argument("--flap", default="left")
    ap.add_argument("--rho", type=float, default=2.0, help="the edge radius [mm]")
    ap.add_argument("--band-rho", type=float, default=BAND_RHO,
                    help="the band's half-width in edge radii")
    ap.add_argument("--rho-per-h", type=float, default=RHO_PER_H)
    ap.add_argument("--grading", type=float, default=GRADING)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--run", action="store_true",
                    help="then run the flap's scenario (both-sided swelling) on it")
    ap.add_argument("--swell", default="both")
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    from brainbulge.geometry.brain import load_brain_mesh, save_brain_mesh

    mesh = args.out / "brain.npz"
    if not mesh.is_file():
        bm, info = band_mesh(load_brain_mesh(args.mesh), args.flap, args.rho, args.band_rho,
                             args.rho_per_h, args.grading)
        save_brain_mesh(bm, args.out, flap=args.flap, figures=False)
        info["template"] = str(args.mesh)
        (args.out / "band.json").write_text(json.dumps(info, indent=2))
    print((args.out / "band.json").read_text())
    if args.run:
        import bench_edge_radius_3d as er

        r = er.EdgeRun(args.flap, args.swell, args.rho, int(json.loads(
            (args.out / "band.json").read_text())["tets_after"]))
        runs = args.out / "runs"
        runs.mkdir(exist_ok=True)
        er.h3.mesh_file = lambda cache, tets: mesh  # every run's template: the refined mesh
        if not (runs / r.name / "summary.json").is_file():
            print(f"{r.name}: {er.run(r, runs, args.out):.0f} s", flush=True)
        print(er.HEADER)
        print(er.row(r, runs, args.out))


if __name__ == "__main__":
    sys.exit(main())
