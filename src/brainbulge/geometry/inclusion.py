"""A swelling inclusion in an incompressible matrix: a check of docs/model.md section 8.

By symmetry only a quarter disk (2D) or an octant of a ball (3D) is meshed. Boundaries:
``sym_x`` (plane x = 0, where u_x = 0), ``sym_y``, ``sym_z`` and the traction-free ``outer``
surface. Regions: ``inclusion`` (radius ``A``) and ``matrix`` (out to radius ``R``).
"""

from __future__ import annotations

import ngsolve as ngs
from netgen.occ import Box, Circle, Glue, OCCGeometry, Rectangle, Sphere, X, Y, Z

from brainbulge.errors import InputError


def inclusion_mesh(
    dim: int, A: float = 0.1, R: float = 1.0, h: float = 0.1, h_inclusion: float | None = None
) -> ngs.Mesh:
    """Mesh of a quarter disk / ball octant of radius ``R`` with an inclusion of radius ``A``.

    ``h`` is the element size in the matrix, ``h_inclusion`` (default ``A/3``) in and around
    the inclusion [length].
    """
    if not 0 < A < R:
        raise InputError(f"inclusion radius A = {A} must lie in (0, R = {R})")
    hi = h_inclusion if h_inclusion is not None else A / 3
    if dim == 2:
        quad = Rectangle(2 * R, 2 * R).Face()
        quad.edges.Min(X).name = "sym_x"
        quad.edges.Min(Y).name = "sym_y"
        outer = Circle((0, 0), R).Face()
        outer.edges.name = "outer"
        inner = Circle((0, 0), A).Face()
        inner.edges.name = "interface"
        inc = inner * quad
        mat = (outer * quad) - inner
    elif dim == 3:
        box = Box((0, 0, 0), (2 * R, 2 * R, 2 * R))
        box.faces.Min(X).name = "sym_x"
        box.faces.Min(Y).name = "sym_y"
        box.faces.Min(Z).name = "sym_z"
        outer = Sphere((0, 0, 0), R)
        outer.faces.name = "outer"
        inner = Sphere((0, 0, 0), A)
        inner.faces.name = "interface"
        inc = inner * box
        mat = (outer * box) - inner
    else:
        raise InputError(f"dimension must be 2 or 3, got {dim}")
    if dim == 2:
        inc.faces.name, mat.faces.name = "inclusion", "matrix"
        inc.faces.maxh = hi
    else:
        inc.mat("inclusion")
        mat.mat("matrix")
        inc.maxh = hi
    shape = Glue([inc, mat])
    mesh = ngs.Mesh(OCCGeometry(shape, dim=dim).GenerateMesh(maxh=h, grading=0.25))
    mesh.Curve(2)
    return mesh
