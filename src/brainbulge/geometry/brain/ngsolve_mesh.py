"""The brain mesh as an NGSolve mesh (mm): materials ``"{tissue}_{side}"``, boundaries
``"base"``, ``"superior"``, ``"skull"``, ``"flap"``."""

from __future__ import annotations

import numpy as np

from brainbulge.geometry.brain.boundaries import SuperiorBand
from brainbulge.geometry.brain.brain_mesh import BrainMesh

BOUNDARY_NAMES = ("base", "superior", "skull", "flap")


def to_ngsolve(brain_mesh: BrainMesh, flap: str | None = None,
               superior: SuperiorBand | None = None):
    """Build an ``ngsolve.Mesh`` of ``brain_mesh`` with the given flap open (``None``: intact)
    and the faces of the ``superior`` band (``None``: none) named ``"superior"``.

    Materials are ``"{tissue}_{side}"`` (e.g. ``"white_left"``); boundary names exactly
    ``"base"``, ``"superior"``, ``"skull"`` and ``"flap"`` (a name with no faces is still
    declared).
    """
    import netgen.meshing as nm
    import ngsolve

    names = brain_mesh.material_names()
    materials, mat_index = np.unique(names, return_inverse=True)
    ngmesh = nm.Mesh(dim=3)
    ngmesh.AddPoints(np.ascontiguousarray(brain_mesh.nodes_mm, dtype=float))
    for i, name in enumerate(materials, start=1):
        ngmesh.SetMaterial(i, str(name))
    # netgen's tets have the opposite orientation to ours: swap two vertices
    tets = np.ascontiguousarray(brain_mesh.tets[:, [0, 2, 1, 3]], dtype=np.int32)
    for i in range(len(materials)):  # elements end up grouped by material, in stable order
        ngmesh.AddElements(dim=3, index=i + 1, data=tets[mat_index == i], base=0)
    # one face descriptor per (boundary name, region of the owning tet): NGSolve takes the
    # region next to a boundary face from its descriptor, and a space defined on one region
    # (the pressure of a zone) would otherwise pick up every boundary vertex
    bnames = brain_mesh.boundary_names(flap, superior)
    faces = np.ascontiguousarray(brain_mesh.faces, dtype=np.int32)  # outward normals
    face_mat = mat_index[brain_mesh.face_tet]
    fd = 0
    for bname in BOUNDARY_NAMES:
        on = bnames == bname
        mats = np.unique(face_mat[on]) if on.any() else np.array([0])
        for m in mats:
            fd += 1
            ngmesh.Add(nm.FaceDescriptor(surfnr=fd, domin=int(m) + 1, domout=0, bc=fd))
            ngmesh.SetBCName(fd - 1, bname)
            sel = on & (face_mat == m)
            if sel.any():
                ngmesh.AddElements(dim=2, index=fd, data=faces[sel], base=0)
    return ngsolve.Mesh(ngmesh)
