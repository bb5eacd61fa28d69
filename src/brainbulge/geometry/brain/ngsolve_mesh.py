"""The brain mesh as an NGSolve mesh (mm): materials ``"{tissue}_{side}"``, boundaries
``"base"``, ``"skull"``, ``"flap"``."""

from __future__ import annotations

import numpy as np

from brainbulge.geometry.brain.brain_mesh import BrainMesh

BOUNDARY_NAMES = ("base", "skull", "flap")


def to_ngsolve(brain_mesh: BrainMesh, flap: str | None = None):
    """Build an ``ngsolve.Mesh`` of ``brain_mesh`` with the given flap open (``None``: intact).

    Materials are ``"{tissue}_{side}"`` (e.g. ``"white_left"``); boundary names exactly
    ``"base"``, ``"skull"`` and ``"flap"`` (a name with no faces is still declared).
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
    bnames = brain_mesh.boundary_names(flap)
    for i, bname in enumerate(BOUNDARY_NAMES, start=1):
        ngmesh.Add(nm.FaceDescriptor(surfnr=i, domin=1, domout=0, bc=i))
        ngmesh.SetBCName(i - 1, bname)
    faces = np.ascontiguousarray(brain_mesh.faces, dtype=np.int32)  # outward normals
    for i, bname in enumerate(BOUNDARY_NAMES, start=1):
        if np.any(bnames == bname):
            ngmesh.AddElements(dim=2, index=i, data=faces[bnames == bname], base=0)
    return ngsolve.Mesh(ngmesh)
