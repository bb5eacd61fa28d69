"""Fields on the mesh vertices and their ParaView file (VTU via meshio).

Stretches and strains come from the recovered gradient (:mod:`..measures.recovery`),
continuous inside each region and discontinuous across regions, so every field is evaluated at
each element's own vertices and averaged over the elements that share a vertex (point data);
region and element averages are cell data. ParaView: *Warp By Vector* on ``u`` shows the
deformed shape.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import meshio
import ngsolve as ngs
import numpy as np

from brainbulge.geometry.ngsolve_arrays import (
    element_corners,
    element_vertices,
    vertex_coordinates,
)
from brainbulge.results.measures.fields import output_fields, sample
from brainbulge.results.measures.recovery import recovered_gradient
from brainbulge.results.records.run_record import atomic_output
from brainbulge.solver.mixed import MixedForm


@dataclass
class VertexFields:
    """Mesh vertices, simplices (0-based vertex numbers) and fields on them."""

    points: np.ndarray  # (nv, dim)
    cells: np.ndarray  # (ne, dim + 1)
    regions: np.ndarray  # (ne,) region index
    region_names: list[str]
    point_data: dict[str, np.ndarray]
    cell_data: dict[str, np.ndarray]
    #: fields at each element's own vertices (ne, dim + 1, ...), float32, before averaging
    #: (those ``vertex_fields(corners=...)`` names: the NIfTI maps interpolate them)
    corner_data: dict[str, np.ndarray] = field(default_factory=dict)

    def mirrored(self) -> VertexFields:
        """The whole domain of a solution computed on its half ``x >= 0``: these vertices and
        elements and their mirror images ``(-x, y, ...)`` about ``x = 0``, the vertices on
        the plane shared. Vector fields (``u``) have their x component reversed; the scalar
        fields are the reflection's own."""
        n = len(self.points)
        on_plane = np.abs(self.points[:, 0]) <= 1e-12 * np.abs(self.points).max()
        image = np.where(on_plane, np.arange(n), n + np.cumsum(~on_plane) - 1)
        points = np.concatenate([self.points, _reflect(self.points[~on_plane])])
        cells = image[self.cells][:, ::-1]  # reversed: the images keep their orientation

        def both(a: np.ndarray, keep: np.ndarray | slice = slice(None)) -> np.ndarray:
            return np.concatenate([a, _reflect(a[keep]) if a.ndim == 2 else a[keep]])

        return VertexFields(
            points=points, cells=np.concatenate([self.cells, cells]),
            regions=np.tile(self.regions, 2), region_names=self.region_names,
            point_data={k: both(v, ~on_plane) for k, v in self.point_data.items()},
            cell_data={k: both(v) for k, v in self.cell_data.items()},
            corner_data={k: np.concatenate([v, _reflect(v)[:, ::-1] if v.ndim == 3
                                            else v[:, ::-1]])
                         for k, v in self.corner_data.items()})


def _reflect(a: np.ndarray) -> np.ndarray:
    """Vectors (the last axis) reflected about the plane ``x = 0``."""
    out = np.array(a, copy=True)
    out[..., 0] *= -1
    return out


def vertex_fields(
    form: MixedForm,
    centre: np.ndarray,
    extra: dict[str, ngs.CoefficientFunction] | None = None,
    fibres: Callable[[np.ndarray], np.ndarray] | None = None,
    gradient: ngs.CoefficientFunction | None = None,
    corners: tuple[str, ...] = (),
) -> VertexFields:
    """Evaluate the outputs of docs/model.md section 3 at the vertices of every element
    (``fibres(X)``: unit axon directions replacing the radial default; ``gradient``: the
    state's recovered gradient when the caller has it, else computed here; ``corners``: the
    fields also kept at each element's own vertices, ``corner_data``)."""
    mesh = form.mesh
    dim = mesh.dim
    points = vertex_coordinates(mesh)
    cells, regions = element_vertices(mesh)
    names = list(mesh.GetMaterials())

    mips = element_corners(mesh)
    if gradient is None:
        gradient = recovered_gradient(mesh, form.output_displacement())
    s = sample(form, mips, gradient=gradient)
    fields = output_fields(s, centre, None if fibres is None else fibres(s.X))
    for name, cf in (extra or {}).items():
        fields[name] = np.asarray(cf(mips)).reshape(len(s.X), -1).squeeze()
    vid = cells.ravel()  # the sampled corners, element by element
    count = np.bincount(vid, minlength=len(points)).astype(float)
    point_data, cell_data = {}, {}
    for name, values in fields.items():
        val = np.asarray(values, dtype=float)
        flat = val.reshape(len(vid), -1)
        acc = np.stack([np.bincount(vid, weights=c, minlength=len(points)) for c in flat.T],
                       axis=1)
        point_data[name] = (acc / count[:, None]).reshape((len(points),) + val.shape[1:])
        cell_data[name] = val.reshape(len(cells), dim + 1, *val.shape[1:]).mean(axis=1)
    cell_data["region"] = regions.astype(float)
    corner_data = {name: np.asarray(fields[name], dtype=np.float32).reshape(
        len(cells), dim + 1, *np.shape(fields[name])[1:]) for name in corners}
    return VertexFields(points, cells, regions, names, point_data, cell_data, corner_data)


def add_contact_fields(vf: VertexFields, form: MixedForm) -> None:
    """Point data ``contact_pressure`` [kPa] and ``contact_status`` (1 in contact with the
    obstacle, 0 separated from it, -1 off the contact boundaries: clamped base, 3D flap,
    interior): the exact multipliers of the active-set contacts, the penalty's
    ``kappa max(-g, 0)`` of the penalty contacts; empty fields without contacts."""
    status = -np.ones(len(vf.points))
    pressure = np.zeros(len(vf.points))
    for pc in form.point_contacts:
        pc.update(form.gfu.vec.FV().NumPy())
        nv = len(pc.vertices)
        touching = (pc.lam[:nv] > 0) | (np.abs(pc.g[:nv]) < 1e-6 * form.h)
        status[pc.vertices] = touching.astype(float)
        pressure[pc.vertices] = pc.pressure()[:nv]
    for pen in form.penalty_contacts:  # in contact: pressed into the obstacle, or on it
        g, p = pen.at_vertices()
        status[pen.vertices] = (g < 1e-6 * form.h).astype(float)
        pressure[pen.vertices] = p
    vf.point_data["contact_pressure"] = pressure
    vf.point_data["contact_status"] = status


def write_vtu(path: Path, vf: VertexFields) -> Path:
    """Write the fields to a VTU file (ParaView, VisIt, meshio)."""
    dim = vf.points.shape[1]
    pts = np.pad(vf.points, ((0, 0), (0, 3 - dim)))
    point_data = {}
    for k, v in vf.point_data.items():
        point_data[k] = np.pad(v, ((0, 0), (0, 3 - dim))) if v.ndim == 2 else v
    cell_type = "triangle" if dim == 2 else "tetra"
    cell_data = {
        k: [np.pad(v, ((0, 0), (0, 3 - dim))) if v.ndim == 2 else v]
        for k, v in vf.cell_data.items()
    }
    m = meshio.Mesh(pts, [(cell_type, vf.cells)], point_data=point_data, cell_data=cell_data)
    path = Path(path)
    with atomic_output(path) as tmp:
        m.write(tmp)
    return path


def save_vertex_fields(path: Path, vf: VertexFields) -> Path:
    """Write the vertex fields to ``path`` (compressed ``.npz``, atomically)."""
    with atomic_output(path) as tmp:
        np.savez_compressed(
            tmp,
            points=vf.points,
            cells=vf.cells,
            regions=vf.regions,
            region_names=np.array(vf.region_names),
            **{f"point_{k}": v for k, v in vf.point_data.items()},
        )
    return path


def load_vertex_fields(path: Path) -> VertexFields:
    d = np.load(path)
    pd = {k[6:]: d[k] for k in d.files if k.startswith("point_")}
    return VertexFields(d["points"], d["cells"], d["regions"], list(d["region_names"]), pd, {})
