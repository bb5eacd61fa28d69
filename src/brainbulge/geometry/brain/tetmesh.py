"""Tetrahedral meshing of the intracranial volume with Netgen.

The envelope's zero level set is triangulated by marching cubes (scikit-image) on the smooth
signed distance field, written as STL, and Netgen remeshes that surface at the requested element
size and fills it with tetrahedra (Delaunay + advancing front, then quality optimisation).
Surface nodes lie on the smooth level set: no voxel staircase.
"""

from __future__ import annotations

import logging
import tempfile
from pathlib import Path

import meshio
import numpy as np
from skimage import measure

from brainbulge.errors import MeshError
from brainbulge.geometry.brain.envelope import IntracranialEnvelope
from brainbulge.geometry.brain.quality import dihedral_angles_deg, tet_volumes_mm3

log = logging.getLogger("brainbulge")

#: Netgen fills a smooth volume V (mm^3) at ``maxh`` h (mm) with about
#: V / (TET_FILL h^(3 + TET_FILL_EXPONENT)) tets (fitted on the template: 100k-1.5M tets).
TET_FILL = 0.2
TET_FILL_EXPONENT = 0.225


def element_size_for(volume_ml: float, target_tets: int) -> float:
    """Netgen ``maxh`` (mm) that gives about ``target_tets`` tetrahedra in ``volume_ml``."""
    return float((volume_ml * 1000 / (TET_FILL * target_tets)) ** (1 / (3 + TET_FILL_EXPONENT)))


def envelope_surface(envelope: IntracranialEnvelope, step: int = 1
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Outward-oriented triangulation (world mm) of the envelope by marching cubes on every
    ``step``-th voxel."""
    spacing = float(np.linalg.norm(envelope.affine[:3, :3], axis=0).min())
    verts, faces, _, _ = measure.marching_cubes(envelope.sdf_mm, 0.0, step_size=step,
                                                allow_degenerate=False)
    verts, faces = _weld(envelope.index_to_world(verts), faces, tol_mm=1e-2 * spacing)
    p = verts[faces]
    signed = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6
    if signed < 0:
        faces = faces[:, ::-1]
    return verts, faces


def _weld(verts: np.ndarray, faces: np.ndarray, tol_mm: float
          ) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices closer than ``tol_mm`` and drop the triangles that collapse."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pairs = cKDTree(verts).query_pairs(tol_mm, output_type="ndarray")
    n = len(verts)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, rep = connected_components(graph, directed=False)
    faces = rep[faces]
    keep = ((faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2])
            & (faces[:, 0] != faces[:, 2]))
    used, faces = np.unique(faces[keep], return_inverse=True)
    centres = np.zeros((rep.max() + 1, 3))
    np.add.at(centres, rep, verts)
    centres /= np.bincount(rep)[:, None]
    return centres[used], faces.reshape(-1, 3)


def mesh_intracranial_volume(envelope: IntracranialEnvelope, h_mm: float, optsteps: int = 3,
                             min_dihedral_deg: float = 10.0, max_attempts: int = 4
                             ) -> tuple[np.ndarray, np.ndarray]:
    """Nodes (n, 3) in mm and positively oriented tets (m, 4) filling the envelope.

    Netgen occasionally gives up ("too many trials") or leaves a few slivers where the envelope
    has a crease tighter than the element size. Flat slivers with two faces on the surface are
    removed (:func:`remove_surface_slivers`); if the worst dihedral angle is still under
    ``min_dihedral_deg``, the mesh is redone with the element size and STL resolution nudged
    (up to ``max_attempts``) and the best mesh is kept.
    """
    spacing = float(np.linalg.norm(envelope.affine[:3, :3], axis=0).min())
    # STL from every second voxel: Netgen 6.2.2608 aborts the process on the every-voxel STL
    # of the template at h < 3 mm, and coarser STLs made overlapping surface meshes at h ~ 6 mm
    step = max(1, int(round(2.0 / spacing)))
    attempts = [(h_mm, step), (0.97 * h_mm, step), (1.03 * h_mm, step), (0.95 * h_mm, step + 1)]
    best, best_angle = None, -1.0
    for h, st in attempts[:max(1, max_attempts)]:
        nodes, tets = _netgen_tets(envelope, h, st, optsteps)
        if not len(tets):
            continue
        tets = remove_surface_slivers(nodes, tets, min_dihedral_deg)
        angle = float(dihedral_angles_deg(nodes, tets).min())
        log.info("netgen: h = %.2f mm, STL step %d: %d tets, min dihedral %.1f deg",
                 h, st, len(tets), angle)
        if angle > best_angle:
            best, best_angle = (nodes, tets), angle
        if angle >= min_dihedral_deg:
            break
    if best is None:
        raise MeshError("Netgen failed to mesh the intracranial volume: ask for another --tets, "
                        "or check the label image and --label-map (thin or disconnected pieces, a "
                        "preset that maps only part of the brain)")
    nodes, tets = best
    used = np.unique(tets)
    if len(used) < len(nodes):  # drop nodes orphaned by removed slivers
        renumber = np.full(len(nodes), -1)
        renumber[used] = np.arange(len(used))
        nodes, tets = nodes[used], renumber[tets]
    return nodes, tets


def remove_surface_slivers(nodes: np.ndarray, tets: np.ndarray, min_dihedral_deg: float = 10.0
                           ) -> np.ndarray:
    """Drop flat tets that have two faces on the outer surface and a dihedral angle under
    ``min_dihedral_deg`` (their removal only flattens the surface locally, by < 0.01 mm^3
    each); repeated while some are found, at most 5 times."""
    from brainbulge.geometry.brain.boundaries import boundary_faces
    for _ in range(5):
        bad = np.flatnonzero(dihedral_angles_deg(nodes, tets).min(axis=1) < min_dihedral_deg)
        if not len(bad):
            break
        _, owner = boundary_faces(tets)
        n_outer = np.bincount(owner, minlength=len(tets))
        drop = bad[n_outer[bad] >= 2]
        if not len(drop):
            break
        tets = np.delete(tets, drop, axis=0)
    return tets


def _netgen_tets(envelope: IntracranialEnvelope, h_mm: float, step: int, optsteps: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Netgen's tets, computed in a forked child process: on some surfaces (e.g. a label
    map read with the wrong preset) Netgen aborts the whole process ("GetChartNr(-1)"), which
    must become a failed attempt, not a crash without a message."""
    import os
    import pickle

    empty = np.zeros((0, 3)), np.zeros((0, 4), dtype=np.int64)
    if not hasattr(os, "fork"):  # pragma: no cover - Windows: run in this process
        return _netgen_tets_here(envelope, h_mm, step, optsteps)
    read_fd, write_fd = os.pipe()
    parent = os.getpid()
    pid = os.fork()
    if pid == 0:  # child: mesh, send the arrays, leave without cleanup handlers
        import faulthandler

        faulthandler.disable()  # a Netgen abort here is expected and reported by the parent
        _end_with(parent)
        os.close(read_fd)
        code = 0
        try:
            data = pickle.dumps(_netgen_tets_here(envelope, h_mm, step, optsteps))
            with os.fdopen(write_fd, "wb") as fh:
                fh.write(data)
        except BaseException:
            code = 1
        os._exit(code)
    os.close(write_fd)
    with os.fdopen(read_fd, "rb") as fh:
        data = fh.read()
    _, status = os.waitpid(pid, 0)
    if status != 0 or not data:
        log.warning("netgen: the meshing process failed (status %d)", status)
        return empty
    return pickle.loads(data)


def _end_with(parent: int) -> None:
    """In a forked child: end on the signals that stop a command (not the parent's Python
    handlers, which run only between bytecodes and so never inside Netgen), and when the
    ``parent`` process ends, however it ends (Linux: ``PR_SET_PDEATHSIG``)."""
    import os
    import signal

    from brainbulge.runtime import STOP_SIGNALS

    for signum in (*STOP_SIGNALS, signal.SIGINT):
        signal.signal(signum, signal.SIG_DFL)
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # pragma: no cover - not Linux
        pass
    if os.getppid() != parent:  # the parent ended before the call above
        os._exit(1)


def _netgen_tets_here(envelope: IntracranialEnvelope, h_mm: float, step: int, optsteps: int
                      ) -> tuple[np.ndarray, np.ndarray]:
    import netgen.meshing as nm
    from netgen.stl import STLGeometry

    verts, faces = envelope_surface(envelope, step)
    with tempfile.TemporaryDirectory() as tmp:
        stl = Path(tmp) / "envelope.stl"
        meshio.write(str(stl), meshio.Mesh(verts, [("triangle", faces)]), binary=True)
        geo = STLGeometry(str(stl))
        params = nm.MeshingParameters(maxh=h_mm, grading=0.3, optsteps3d=optsteps)
        try:
            ngmesh = geo.GenerateMesh(params, yangle=60, contyangle=60, edgecornerangle=90,
                                      chartangle=45, outerchartangle=120)
        except Exception:  # netgen raises NgException on failure
            return np.zeros((0, 3)), np.zeros((0, 4), dtype=np.int64)
    nodes = np.array(ngmesh.Coordinates(), dtype=float)
    tets = np.array(ngmesh.Elements3D().NumPy()["nodes"][:, :4], dtype=np.int64) - 1
    if len(tets) == 0:
        return nodes, tets
    vol = tet_volumes_mm3(nodes, tets)
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]
    return nodes, tets
