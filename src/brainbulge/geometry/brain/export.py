"""Writing and reading brain meshes: VTU/XDMF (meshio), a fast ``.npz`` and ``mesh.json``."""

from __future__ import annotations

import json
import logging
import zipfile
from dataclasses import asdict
from pathlib import Path
from typing import Any

import meshio
import numpy as np

from brainbulge.atomic import atomic_output, atomic_write_text, note_written
from brainbulge.errors import InputError
from brainbulge.geometry.brain.boundaries import Flap, SuperiorBand
from brainbulge.geometry.brain.brain_mesh import BrainMesh
from brainbulge.geometry.brain.defaults import EDGE_RADIUS_MM
from brainbulge.geometry.brain.envelope import IntracranialEnvelope
from brainbulge.geometry.brain.labels import TISSUES, ImageGrid
from brainbulge.geometry.brain.regions import SIDES, MidSagittalPlane

log = logging.getLogger("brainbulge")

#: Boundary codes in the VTU/XDMF files (cell data ``boundary`` on triangles).
BOUNDARY_CODES = {"base": 1, "skull": 2, "flap": 3, "superior": 4}


def brain_summary(mesh: BrainMesh) -> dict:
    """The content of ``mesh.json``: sizes, volumes (ml), quality, flap areas (cm^2: the
    nominal flap, and the surface the skull leaves free with the default rounding of its
    cut edge)."""
    mesh_vol = mesh.tissue_volumes_ml()
    return {
        "units": {"length": "mm", "volume": "ml", "area": "cm^2"},
        "nodes": int(len(mesh.nodes_mm)),
        "tets": int(len(mesh.tets)),
        "boundary_faces": int(len(mesh.faces)),
        "tissue_codes": {str(k): v for k, v in TISSUES.items()},
        "side_codes": {str(k): v for k, v in SIDES.items()},
        "intracranial_volume_ml": {"mesh": float(mesh.tet_volumes_mm3().sum() / 1000),
                                   "voxels": mesh.envelope.volume_ml()},
        "tissue_volumes_ml": {
            name: {"mesh": mesh_vol[name], "voxels": float(mesh.voxel_volumes_ml.get(name, 0.0)),
                   "relative_difference": (mesh_vol[name] / mesh.voxel_volumes_ml[name] - 1)
                   if mesh.voxel_volumes_ml.get(name, 0.0) > 0 else None}
            for name in TISSUES.values()
        },
        "region_volumes_ml": mesh.region_volumes_ml(),
        "quality": mesh.quality(),
        "base": {"cut_plane_z_mm": mesh.base_z_mm, "faces": int(mesh.base.sum()),
                 "area_cm2": float(_area(mesh, mesh.base))},
        "superior": _superior_dict(mesh, SuperiorBand()),
        "flaps": {name: {"flap_nominal_area_cm2": mesh.flap_area_cm2(name),
                         "flap_area_cm2": mesh.free_area_cm2(name),
                         "edge_radius_mm": EDGE_RADIUS_MM,
                         "faces": int(mesh.flap_faces[name].sum()), **_flap_dict(f)}
                  for name, f in mesh.flaps.items()},
        "timings_s": mesh.timings_s,
    }


def _area(mesh: BrainMesh, mask: np.ndarray) -> float:
    from brainbulge.geometry.brain.boundaries import face_areas_mm2

    return float(face_areas_mm2(mesh.nodes_mm, mesh.faces)[mask].sum() / 100)


def _superior_dict(mesh: BrainMesh, band: SuperiorBand) -> dict:
    mask = mesh.superior_faces(band)
    return {"width_mm": band.width_mm, "elevation_deg": band.elevation_deg,
            "faces": int(mask.sum()), "area_cm2": float(_area(mesh, mask))}


def _flap_dict(flap: Flap) -> dict:
    d = asdict(flap)
    d.pop("meta")
    return d


def save_brain_mesh(mesh: BrainMesh, out_dir: str | Path, flap: str | None = None,
                    figures: bool = True) -> dict[str, Path]:
    """Write ``brain.vtu``, ``brain.xdmf`` (+ ``.h5``), ``brain.npz``, ``mesh.json`` and, with
    ``figures``, ``sections.png`` and ``boundaries.png`` into ``out_dir``. The VTU/XDMF
    boundary codes (1 base, 2 skull, 3 flap) use ``flap`` (default: none)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    names = mesh.boundary_names(flap, SuperiorBand())
    bcode = np.array([BOUNDARY_CODES[n] for n in names], dtype=np.int32)
    region = (2 * mesh.tissue.astype(np.int32) + mesh.side).astype(np.int32)
    mm = meshio.Mesh(
        mesh.nodes_mm,
        [("tetra", mesh.tets.astype(np.int64)), ("triangle", mesh.faces.astype(np.int64))],
        cell_data={
            "tissue": [mesh.tissue.astype(np.int32), np.zeros(len(mesh.faces), np.int32)],
            "side": [mesh.side.astype(np.int32), np.zeros(len(mesh.faces), np.int32)],
            "region": [region, np.zeros(len(mesh.faces), np.int32)],
            "boundary": [np.zeros(len(mesh.tets), np.int32), bcode],
        },
    )
    paths = {"vtu": out / "brain.vtu", "xdmf": out / "brain.xdmf", "npz": out / "brain.npz",
             "json": out / "mesh.json"}
    with atomic_output(paths["vtu"]) as tmp:
        mm.write(tmp)
    try:  # meshio's XDMF writer needs h5py (heavy data in brain.h5)
        import h5py  # noqa: F401
    except ImportError:
        log.warning("h5py is not installed: brain.xdmf not written (pip install h5py)")
        paths.pop("xdmf")
    else:  # in place: its heavy data goes to brain.h5, which the file names
        from meshio.xdmf.main import XdmfWriter

        # meshio leaves brain.h5 open for the garbage collector to close; closed later (in a
        # Dask worker it was), the file changed after it was noted, and the next --overwrite
        # refused it as not brainbulge's: close it here, before it is noted
        XdmfWriter(paths["xdmf"], mm).h5_file.close()
        for written in (paths["xdmf"], paths["xdmf"].with_suffix(".h5")):
            if written.is_file():
                note_written(written)  # in the output folder's manifest
    with atomic_output(paths["npz"]) as tmp:
        _save_npz(tmp, mesh)
    summary = brain_summary(mesh)
    atomic_write_text(paths["json"], json.dumps(summary, indent=2, default=_json_default))
    if figures:
        from brainbulge.geometry.brain.figures import plot_boundaries, plot_sections

        paths["sections"] = plot_sections(mesh, out / "sections.png")
        paths["boundaries"] = plot_boundaries(mesh, out / "boundaries.png")
    return paths


def _save_npz(path: Path, mesh: BrainMesh) -> None:
    """``brain.npz``: everything :func:`load_brain_mesh` needs."""
    env = mesh.envelope
    np.savez(
        path, nodes_mm=mesh.nodes_mm, tets=mesh.tets, tissue=mesh.tissue,
        side=mesh.side, faces=mesh.faces, face_tet=mesh.face_tet, base=mesh.base,
        base_z_mm=mesh.base_z_mm, envelope_sdf_mm=env.sdf_mm, envelope_affine=env.affine,
        flaps_json=json.dumps({n: _flap_dict(f) for n, f in mesh.flaps.items()}),
        voxel_volumes_json=json.dumps(mesh.voxel_volumes_ml),
        midsagittal_json=json.dumps(asdict(mesh.midsagittal)),
        **_grid_arrays(mesh.image_grid),
    )


def _grid_arrays(grid: ImageGrid | None) -> dict[str, np.ndarray]:
    """The label image's grid in ``brain.npz`` (none if unknown)."""
    if grid is None:
        return {}
    return {"image_shape": np.asarray(grid.shape, np.int64), "image_affine": grid.affine,
            "image_to_mesh": grid.to_mesh, "image_source": np.asarray(grid.source)}


def _json_default(o: object) -> object:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o))


def stored_tets(path: str | Path) -> int:
    """The number of tets in a ``brain.npz`` of :func:`save_brain_mesh`, from the header of
    its ``tets`` array (milliseconds: the arrays are not read)."""
    try:
        with zipfile.ZipFile(path) as archive, archive.open("tets.npy") as f:
            version = np.lib.format.read_magic(f)
            read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                    else np.lib.format.read_array_header_2_0)
            return int(read(f)[0][0])
    except (OSError, KeyError, ValueError, zipfile.BadZipFile) as err:
        raise InputError(f"cannot read brain mesh {path}: {err}; give a brain.npz") from None


def check_mesh_arrays(d: Any, path: str | Path) -> None:
    """Refuse (`InputError`, one line naming the array) the arrays of a ``brain.npz`` that
    NGSolve, Netgen or the solver would not survive or would misread: shapes and integer
    types, node indices within the nodes (a bad index crashes native code), finite
    coordinates [mm], known tissue and side codes, faces on existing nodes and tets. Element
    volumes are checked on the mesh (:func:`check_brain_mesh`, exit 5)."""
    def bad(what: str) -> InputError:
        return InputError(f"brain mesh {path}: {what}; rebuild it with `brainbulge mesh "
                          "--out DIR` and pass DIR/brain.npz")

    nodes, tets, faces = d["nodes_mm"], d["tets"], d["faces"]
    arrays = {"tets": tets, "tissue": d["tissue"], "side": d["side"], "faces": faces,
              "face_tet": d["face_tet"]}
    if nodes.ndim != 2 or nodes.shape[1] != 3 or not len(nodes) or nodes.dtype.kind != "f":
        raise bad(f"nodes_mm has shape {nodes.shape} ({nodes.dtype}), not (n, 3) numbers")
    if not np.all(np.isfinite(nodes)):
        raise bad(f"{int((~np.isfinite(nodes).all(axis=1)).sum())} nodes have a NaN or "
                  "infinite coordinate")
    for name, a in arrays.items():
        if a.dtype.kind not in "iu":
            raise bad(f"{name} holds {a.dtype} values, not whole numbers")
    if tets.ndim != 2 or tets.shape[1] != 4 or not len(tets):
        raise bad(f"tets has shape {tets.shape}, not (n, 4) node indices")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise bad(f"faces has shape {faces.shape}, not (n, 3) node indices")
    for name, a in (("tets", tets), ("faces", faces)):
        if a.size and (a.min() < 0 or a.max() >= len(nodes)):
            raise bad(f"{name} refers to node {int(a.min() if a.min() < 0 else a.max())}, "
                      f"outside the {len(nodes)} nodes")
    for name, n, codes in (("tissue", len(tets), TISSUES), ("side", len(tets), SIDES),
                           ("face_tet", len(faces), range(len(tets)))):
        a = arrays[name]
        if a.shape != (n,):
            raise bad(f"{name} has shape {a.shape}, not ({n},)")
        unknown = a[~np.isin(a, list(codes))] if name != "face_tet" else a[(a < 0)
                                                                          | (a >= len(tets))]
        if unknown.size:
            raise bad(f"{name} holds {int(unknown[0])}, not one of "
                      + (f"{len(tets)} tets" if name == "face_tet" else
                         ", ".join(f"{k} ({v})" for k, v in codes.items())))
    if d["base"].shape != (len(faces),):
        raise bad(f"base has shape {d['base'].shape}, not ({len(faces)},)")


def load_brain_mesh(path: str | Path) -> BrainMesh:
    """Read a ``brain.npz`` written by :func:`save_brain_mesh` (a second or two), its arrays
    checked whole (:func:`check_mesh_arrays`: `InputError`; inverted or degenerate tets,
    an empty gray or white region: `MeshError`, exit 5)."""
    from brainbulge.geometry.brain.brain_mesh import check_brain_mesh

    try:
        d = np.load(path)
    except (OSError, ValueError):
        raise InputError(f"brain mesh {path} is not a brain.npz written by `brainbulge mesh` "
                         "(unreadable, or not an .npz of arrays); build one with `brainbulge "
                         "mesh --out DIR` and pass DIR/brain.npz") from None
    check_mesh_arrays(d, path)
    mesh = BrainMesh(
        d["nodes_mm"], d["tets"], d["tissue"], d["side"], d["faces"], d["face_tet"],
        d["base"], float(d["base_z_mm"]),
        IntracranialEnvelope(d["envelope_sdf_mm"], d["envelope_affine"]),
        voxel_volumes_ml=json.loads(str(d["voxel_volumes_json"])),
    )
    if "image_shape" in d:  # meshes written before the grid was kept have none
        mesh.image_grid = ImageGrid(tuple(int(n) for n in d["image_shape"]),  # type: ignore[arg-type]
                                    d["image_affine"], d["image_to_mesh"],
                                    str(d["image_source"]))
    if "midsagittal_json" in d:
        plane = json.loads(str(d["midsagittal_json"]))
        mesh.midsagittal = MidSagittalPlane(tuple(plane["point_mm"]), tuple(plane["normal"]))
    for f in json.loads(str(d["flaps_json"])).values():
        f = {k: tuple(v) if isinstance(v, list) else v for k, v in f.items()}
        mesh.add_flap(Flap(**f))
    check_brain_mesh(mesh, path)
    return mesh
