"""NIfTI maps of a 3D run on the voxel grid of the label image its mesh was built from.

``write_maps(vf, bm.image_grid, out_dir / "maps")`` writes, on the grid of the mesh's label
image (``bm.image_grid``: the
template's for the default brain, the user's segmentation for ``--labels``), in that image's
own affine (any orientation, oblique included), one ``.nii.gz`` per map of :data:`MAPS`:
``float32`` with **NaN outside the tissue** (outside the mesh), the masks and label maps
``uint8`` with 0 there. A voxel takes the value of the solution at its **centre in the
reference configuration** (the undeformed brain: the maps lie on the image they were made
from); ``tissue_deformed.nii.gz`` is the tissue label at each voxel centre in the deformed
configuration (the mesh moved by its vertex displacements), i.e. the swollen, bulged brain.

Each voxel centre is located in the mesh by rasterising the tetrahedra (numba: the voxel
centres in an element's bounding box, tested by their barycentric coordinates in index
space, which an affine map keeps), and takes the fields at that element's own vertices
(computed for ``fields.vtu``, before it averages them over the elements sharing a vertex)
interpolated linearly: exact at the vertices and wherever the field is linear in the
element (the MINI element's displacement and pressure), one side's value at a tissue
interface. NGSolve's own point location (``mesh(x, y, z)``) finds the same elements (a test
compares them, and the interpolated values against the solution NGSolve evaluates there)
but costs ~40 us per point on a 111k-tet brain (85 s for the template's 2.0M tissue
voxels), and NGSolve's evaluation at scattered points ~6 us per point (12 s); located and
interpolated here they take ~3 s (docs/design.md, "NIfTI maps").
"""

from __future__ import annotations

import gzip
import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from brainbulge.geometry.brain.labels import TISSUE_CODES, TISSUES, ImageGrid
from brainbulge.results.export.writers import VertexFields
from brainbulge.results.measures.plan_defaults import DAMAGE_THRESHOLDS
from brainbulge.results.records.run_record import atomic_output

log = logging.getLogger("brainbulge")

#: map file stem -> (field of :func:`~brainbulge.results.measures.fields.output_fields`,
#: unit, meaning); float32, NaN outside the tissue
MAPS: dict[str, tuple[str, str, str]] = {
    "displacement": ("u", "mm", "displacement vector u (x, y, z: the mesh's world RAS+ axes), "
                     "one 3-vector per voxel (NIfTI intent vector)"),
    "displacement_magnitude": ("u_magnitude", "mm", "|u|"),
    "max_principal_strain": ("max_principal_strain", "-",
                             "maximum principal Green-Lagrange strain"),
    "radial_stretch": ("lambda_n", "-", "stretch lambda_n along the axon (radial) direction"),
    "tangential_stretch": ("lambda_t", "-", "largest stretch lambda_t normal to the axon"),
    "Je": ("Je", "-", "elastic volume ratio Je = J / Js"),
    "hydrostatic_stress": ("pressure", "kPa", "hydrostatic stress -p, positive in compression"),
}
#: the parenchyma's tissues: the damage masks count these
PARENCHYMA_TISSUES = ("gray", "white", "cerebellum", "brainstem")
#: gzip level of the maps (1: fast; the NaN and 0 outside the brain compress well anyway)
COMPRESSION = 1


def damage_mask_name(threshold: float) -> str:
    """``damage_18`` for a strain threshold of 0.18."""
    return f"damage_{round(100 * threshold):d}"


def map_files() -> dict[str, str]:
    """Every file of ``maps/`` -> what it holds (docs/outputs.md lists them)."""
    files = {f"{stem}.nii.gz": f"{meaning} [{unit}], float32, NaN outside the tissue"
             for stem, (_, unit, meaning) in MAPS.items()}
    for name, threshold in DAMAGE_THRESHOLDS.items():
        files[f"{damage_mask_name(threshold)}.nii.gz"] = (
            f"1 where the maximum principal strain exceeds {threshold:g} ({name} damage "
            "threshold) in the parenchyma, else 0; uint8")
    codes = ", ".join(f"{c} {n}" for c, n in TISSUES.items())
    files["tissue.nii.gz"] = f"tissue at each voxel centre as meshed ({codes}; 0 outside), uint8"
    files["tissue_deformed.nii.gz"] = ("the same in the deformed configuration (the swollen, "
                                       "bulged brain), uint8")
    files["max_principal_strain.png"] = "orthogonal sections of the strain map over the image"
    return files


@dataclass
class VoxelHits:
    """Voxel centres located in a mesh: ``index`` (n,) flat voxel indices (C order) of the
    grid, ``element`` (n,) the element holding each, ``weights`` (n, 4) its barycentric
    coordinates there (of the element's vertices in order)."""

    index: np.ndarray
    element: np.ndarray
    weights: np.ndarray


def locate_voxels(points: np.ndarray, cells: np.ndarray, grid: ImageGrid,
                  weights: bool = True) -> VoxelHits:
    """The voxel centres of ``grid`` inside the tetrahedra ``cells`` (vertex numbers into
    ``points``, mesh mm): the element holding each (the last one, on a shared face) and,
    with ``weights``, the barycentric coordinates of the centre in it (else an empty
    array)."""
    from brainbulge.results.export.raster import barycentric_weights, rasterise_tets

    to_index = np.linalg.inv(grid.index_to_mesh())
    ijk = points @ to_index[:3, :3].T + to_index[:3, 3]
    shape = np.asarray(grid.shape, dtype=np.int64)
    corners = np.ascontiguousarray(ijk[cells])
    element = rasterise_tets(corners, shape)
    index = np.flatnonzero(element >= 0)
    el = element[index].astype(np.int64)
    if not weights:
        return VoxelHits(index, el, np.zeros((0, 4)))
    return VoxelHits(index, el, barycentric_weights(corners, el, index, shape))


def map_fields() -> tuple[str, ...]:
    """The vertex fields the maps are made of (``vertex_fields(corners=map_fields())``)."""
    return tuple(dict.fromkeys(field for field, _, _ in MAPS.values()))


def voxel_values(hits: VoxelHits, corner_data: dict[str, np.ndarray]
                 ) -> dict[str, np.ndarray]:
    """The fields of :data:`MAPS` at the located voxel centres: the values at the vertices of
    the element holding each (``corner_data``, (ne, 4, ...): the element's own, not averaged
    with its neighbours') interpolated linearly, float32. Exact where the field is linear in
    the element (the MINI element's displacement and pressure) and at the vertices."""
    w = hits.weights.astype(np.float32)
    out = {}
    for field in map_fields():
        v = corner_data[field][hits.element]  # (n, 4, ...)
        out[field] = (np.einsum("nk,nk->n", w, v) if v.ndim == 2
                      else np.einsum("nk,nkc->nc", w, v))
    return out


def write_maps(vf: VertexFields, grid: ImageGrid, out_dir: Path, background=None
               ) -> dict[str, Path]:
    """Write the maps of :func:`map_files` into ``out_dir`` (see the module docstring) from
    the vertex fields ``vf`` (those of ``fields.vtu``, with the :func:`map_fields` at each
    element's own vertices: ``vertex_fields(corners=map_fields())``); ``background``: the image the
    figure draws the strain over (a NIfTI image or path; default the tissue map)."""
    import nibabel as nib

    started = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cells, regions, region_names = vf.cells, vf.regions, vf.region_names
    hits = locate_voxels(vf.points, cells, grid)
    values = voxel_values(hits, vf.corner_data)

    def image(values_at_hits: np.ndarray, dtype, fill) -> nib.Nifti1Image:
        return grid_image(grid, hits, values_at_hits.astype(dtype), fill)

    paths: dict[str, Path] = {}

    def save(name: str, img: nib.Nifti1Image) -> None:
        paths[name] = save_nifti(img, out_dir / f"{name}.nii.gz")

    for stem, (field, unit, _) in MAPS.items():
        img = image(values[field], np.float32, np.nan)
        if stem == "displacement":
            img.header.set_intent("vector")
            img = nib.Nifti1Image(np.asanyarray(img.dataobj)[:, :, :, None, :], img.affine,
                                  img.header)
        img.header["descrip"] = f"brainbulge {stem} [{unit}]"[:79].encode()
        save(stem, img)
    tissue_of_region = np.array([TISSUE_CODES.get(n.rsplit("_", 1)[0], 0)
                                 for n in region_names], dtype=np.uint8)
    tissue = tissue_of_region[regions[hits.element]]
    parenchyma = np.isin(tissue, [TISSUE_CODES[t] for t in PARENCHYMA_TISSUES])
    for threshold in DAMAGE_THRESHOLDS.values():
        damaged = (parenchyma & (values["max_principal_strain"] > threshold)).astype(np.uint8)
        save(damage_mask_name(threshold), image(damaged, np.uint8, 0))
    save("tissue", image(tissue, np.uint8, 0))
    moved = locate_voxels(vf.points + vf.point_data["u"], cells, grid, weights=False)
    save("tissue_deformed", grid_image(grid, moved, tissue_of_region[regions[moved.element]], 0))
    paths["figure"] = strain_figure(paths["max_principal_strain"], out_dir /
                                    "max_principal_strain.png",
                                    background if background is not None else paths["tissue"])
    log.info("NIfTI maps: %d voxels of a %s grid in %.1f s", len(hits.index),
             " x ".join(map(str, grid.shape)), time.perf_counter() - started)
    return paths


def grid_image(grid: ImageGrid, hits: VoxelHits, values: np.ndarray, fill):
    """An image of ``grid`` (its shape, its affine as sform and qform, aligned to the image
    the mesh came from; mm) holding ``values`` (n, ...) at the located voxels, ``fill``
    elsewhere, in ``values``' type."""
    import nibabel as nib

    flat = np.full((int(np.prod(grid.shape)), *values.shape[1:]), fill, dtype=values.dtype)
    flat[hits.index] = values
    affine = np.asarray(grid.affine, float)
    img = nib.Nifti1Image(flat.reshape(*grid.shape, *values.shape[1:]), affine)
    img.header.set_xyzt_units("mm")
    img.header.set_sform(affine, code=2)
    img.header.set_qform(affine, code=2)
    return img


def save_nifti(img, path: Path) -> Path:
    """Write ``img`` to ``path`` (``.nii.gz``) atomically, gzip level
    :data:`COMPRESSION` (nibabel names the format by the file's ending, which the temporary
    file's name does not keep: the bytes are compressed here)."""
    with atomic_output(path) as tmp:
        tmp.write_bytes(gzip.compress(img.to_bytes(), compresslevel=COMPRESSION))
    return path


#: strains below this are left transparent in the figure, so that the image shows through
FIGURE_THRESHOLD = 0.05


def strain_figure(strain: Path, path: Path, background) -> Path:
    """Orthogonal sections of the strain map over ``background`` (nilearn), the strains above
    :data:`FIGURE_THRESHOLD` coloured, cut where nilearn finds the largest cluster of them."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    import nibabel as nib
    from nilearn import plotting

    img = nib.load(str(strain))
    data = np.asarray(img.dataobj, dtype=np.float32)
    shown = nib.Nifti1Image(np.nan_to_num(data, nan=0.0), img.affine)
    vmax = float(np.nanpercentile(data, 99.9)) if np.isfinite(data).any() else 1.0
    fig = plt.figure(figsize=(10, 3.6))
    display = plotting.plot_stat_map(
        shown, bg_img=background, display_mode="ortho", figure=fig,
        threshold=FIGURE_THRESHOLD, vmax=max(vmax, 2 * FIGURE_THRESHOLD), cmap="inferno",
        symmetric_cbar=False, draw_cross=False,
        title=f"max principal strain > {FIGURE_THRESHOLD:g} (reference configuration)")
    with atomic_output(path) as tmp:
        display.savefig(str(tmp), dpi=110)
    display.close()
    plt.close(fig)
    return path
