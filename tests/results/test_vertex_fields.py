"""Vertex fields for export (:func:`brainbulge.results.export.writers.vertex_fields`) on the coarse
capped ball of contact_cases."""

from __future__ import annotations

import ngsolve as ngs
import numpy as np

from contact_cases import _coords, _forms


def test_vertex_fields_give_the_vertex_values():
    """Vertex DOFs set to ``G X + c`` (bubbles zero): the vertex fields give them at every
    vertex (each vertex's value is the mean over the corners of its elements, so a corner
    matched to the wrong vertex shows), and the cells their regions."""
    from brainbulge.results.export.writers import vertex_fields

    form, _ = _forms()
    G = np.array([[0.02, 0.01, -0.03], [0.0, -0.01, 0.02], [0.01, 0.0, 0.03]])
    c = np.array([0.1, -0.2, 0.05])
    u_exact = _coords(form.mesh) @ G.T + c
    V = form.fes.components[0]
    uvec = form.u.vec.FV().NumPy()
    uvec[:] = 0.0
    for v in range(form.mesh.nv):
        uvec[list(V.GetDofNrs(ngs.NodeId(ngs.VERTEX, v)))] = u_exact[v]
    vf = vertex_fields(form, np.zeros(3))
    np.testing.assert_allclose(vf.point_data["u"], u_exact, atol=1e-13)
    np.testing.assert_allclose(vf.point_data["u_magnitude"], np.linalg.norm(u_exact, axis=1),
                               atol=1e-13)
    regions = [el.index for el in form.mesh.Elements(ngs.VOL)]
    np.testing.assert_array_equal(vf.cell_data["region"], regions)
