"""The labelled brain mesh and the pipeline that builds it from a tissue image.

``build_brain_mesh`` runs: tissue image -> (optional scaling to a brain volume) -> intracranial
envelope (skull's inner surface) -> Netgen tetrahedra -> tissue and hemisphere tags -> tissue
interfaces fitted to the smoothed label surfaces -> outer surface with base, skull and flaps.
All lengths are world millimetres (RAS+), volumes ml.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from brainbulge.errors import InputError, MeshError
from brainbulge.geometry.brain.boundaries import (
    UNILATERAL_DIAMETER_MM,
    Flap,
    SuperiorBand,
    boundary_faces,
    clear_of_other_skull,
    face_areas_mm2,
    frontal_flap,
    unilateral_flap,
)
from brainbulge.geometry.brain.defaults import BRAIN_VOLUME_RANGE_ML, VOLUME_OF
from brainbulge.geometry.brain.envelope import IntracranialEnvelope, intracranial_envelope
from brainbulge.geometry.brain.interfaces import fit_interfaces
from brainbulge.geometry.brain.labels import TISSUES, ImageGrid, TissueImage
from brainbulge.geometry.brain.quality import quality_stats
from brainbulge.geometry.brain.refine import move_onto_surface, refine_uniformly
from brainbulge.geometry.brain.regions import SIDES, MidSagittalPlane, tag_tissue
from brainbulge.geometry.brain.skull import EDGE_RADIUS_MM, RigidSkull
from brainbulge.geometry.brain.tetmesh import (
    element_size_for,
    mesh_intracranial_volume,
    tet_volumes_mm3,
)

log = logging.getLogger("brainbulge")

#: Fraction of the envelope's inferior-superior extent below the default base cut plane:
#: 0.12 puts it at z = -54 mm in MNI space, about the foramen magnum.
BASE_FRACTION = 0.12
#: A face is left free by the skull where the skull with the flap is this much farther from
#: its centroid than the intact skull (mm): well below the mesh's chord heights, above the
#: spline's round-off.
FREE_GAP_MM = 0.01


@dataclass
class BrainMesh:
    """Labelled tetrahedral brain mesh with its outer-surface boundaries (mm, ml).

    ``tissue``: per-tet code (see :data:`labels.TISSUES`); ``side``: 0 left, 1 right;
    ``faces``: outer-surface triangles (outward); ``face_tet``: the tet owning each face;
    ``base``: mask of faces below the cut plane ``base_z_mm``; ``flaps``: named flaps and
    ``flap_faces`` their face masks (base faces excluded); ``voxel_volumes_ml``: tissue volumes
    counted in the image (CSF includes the layer under the skull); ``midsagittal``: the plane
    that splits the hemispheres (its normal points to the patient's right).
    """

    nodes_mm: np.ndarray
    tets: np.ndarray
    tissue: np.ndarray
    side: np.ndarray
    faces: np.ndarray
    face_tet: np.ndarray
    base: np.ndarray
    base_z_mm: float
    envelope: IntracranialEnvelope
    flaps: dict[str, Flap] = field(default_factory=dict)
    flap_faces: dict[str, np.ndarray] = field(default_factory=dict)
    voxel_volumes_ml: dict[str, float] = field(default_factory=dict)
    timings_s: dict[str, float] = field(default_factory=dict)
    midsagittal: MidSagittalPlane = field(default_factory=MidSagittalPlane)
    #: the voxel grid of the label image the mesh was built from (None: unknown, e.g. a
    #: ``brain.npz`` written before meshes kept it); the NIfTI maps are written on it
    image_grid: ImageGrid | None = None

    def tet_volumes_mm3(self) -> np.ndarray:
        """Volume of each tet (mm^3)."""
        return tet_volumes_mm3(self.nodes_mm, self.tets)

    def tissue_volumes_ml(self) -> dict[str, float]:
        """Mesh volume of each tissue (ml)."""
        vol = self.tet_volumes_mm3()
        return {n: float(vol[self.tissue == c].sum() / 1000) for c, n in TISSUES.items()}

    def material_names(self) -> np.ndarray:
        """``"{tissue}_{side}"`` for each tet."""
        names = np.array([f"{TISSUES.get(c, 'none')}_{SIDES[s]}" for c in range(6)
                          for s in (0, 1)])
        return names[2 * self.tissue.astype(int) + self.side.astype(int)]

    def region_volumes_ml(self) -> dict[str, float]:
        """Mesh volume of each ``"{tissue}_{side}"`` region present (ml)."""
        vol = self.tet_volumes_mm3()
        names = self.material_names()
        return {str(n): float(vol[names == n].sum() / 1000) for n in np.unique(names)}

    def flap_area_cm2(self, name: str) -> float:
        """Nominal area of a flap (cm^2): the outer faces whose centroid lies inside its
        cutter, the flap as specified."""
        area = face_areas_mm2(self.nodes_mm, self.faces)
        return float(area[self.flap_faces[name]].sum() / 100)

    def free_area_cm2(self, name: str, edge_radius_mm: float = EDGE_RADIUS_MM,
                      skull: RigidSkull | None = None) -> float:
        """Area of the outer surface the skull leaves free with flap ``name`` open (cm^2):
        the flap's faces, and the faces (base excluded) where the skull with the flap and its
        rounded cut edge lies more than :data:`FREE_GAP_MM` farther from the centroid than the
        intact skull does. With the rounding in the bone it matches :meth:`flap_area_cm2`.
        ``skull``: that skull, if the caller has it (else made with ``edge_radius_mm``)."""
        area = face_areas_mm2(self.nodes_mm, self.faces)
        centroids = self.nodes_mm[self.faces].mean(axis=1)
        skull = skull if skull is not None else self.skull(name, edge_radius_mm)
        phi_env, _ = skull.envelope_distance(centroids, gradient=False)
        phi, _ = skull.signed_distance(centroids, gradient=False)
        free = self.flap_faces[name] | ((phi_env - phi > FREE_GAP_MM) & ~self.base)
        return float(area[free].sum() / 100)

    def boundary_names(self, flap: str | None = None,
                       superior: SuperiorBand | None = None) -> np.ndarray:
        """``"base"``, ``"superior"``, ``"skull"`` or ``"flap"`` for each outer face, for the
        given flap and fixed superior band (``None``: none). A flap that crosses the band
        wins (the skull there is removed), with a warning."""
        names = np.where(self.base, "base", "skull").astype("<U8")
        if superior is not None:
            names[self.superior_faces(superior)] = "superior"
        if flap is not None:
            mask = self._flap_mask(flap)
            crossed = mask & (names == "superior")
            if crossed.any():
                log.warning("flap %r crosses the fixed superior band: %d of its faces are "
                            "traction-free, not fixed", flap, int(crossed.sum()))
            names[mask] = "flap"
        return names

    def superior_faces(self, band: SuperiorBand) -> np.ndarray:
        """Mask of the outer faces (base excluded) in the superior ``band``."""
        centroids = self.nodes_mm[self.faces].mean(axis=1)
        return band.contains(centroids, self.midsagittal.point_mm, self.midsagittal.normal,
                             self.envelope.centre_mm()) & ~self.base

    def _flap_mask(self, flap: str) -> np.ndarray:
        if flap not in self.flap_faces:
            raise InputError(f"unknown flap {flap!r}: choose one of {sorted(self.flap_faces)}")
        return self.flap_faces[flap]

    def add_flap(self, flap: Flap) -> None:
        """Register a flap and tag its faces: the part of the faces with their centroid inside
        the cutter (base excluded) nearest to its centre. The cut ends above any other skull
        inside the cutter (:func:`~.boundaries.clear_of_other_skull`), so that the obstacle
        opens where the faces are traction-free and nowhere else."""
        centroids = self.nodes_mm[self.faces].mean(axis=1)

        def opening(flap: Flap) -> np.ndarray:
            return _component_nearest(self.faces, flap.contains(centroids) & ~self.base,
                                      centroids, np.asarray(flap.centre_mm))

        mask = opening(flap)
        if not mask.any():
            raise InputError(f"flap {flap.name!r} covers no face of the skull surface: move its "
                             "centre onto the skull or enlarge it")
        on_opening = np.zeros(len(self.nodes_mm), dtype=bool)
        on_opening[self.faces[mask]] = True
        other = np.setdiff1d(np.unique(self.faces), np.flatnonzero(on_opening))
        cleared = clear_of_other_skull(flap, self.nodes_mm[on_opening], self.nodes_mm[other])
        if cleared.depth_mm != flap.depth_mm:
            log.info("flap %r: cut %.1f mm deep instead of %.1f, above the other skull in its "
                     "cylinder", flap.name, cleared.depth_mm,
                     flap.radius_mm if flap.depth_mm is None else flap.depth_mm)
            flap, mask = cleared, opening(cleared)
        self.flaps[flap.name] = flap
        self.flap_faces[flap.name] = mask

    def skull(self, flap: str | None = None, edge_radius_mm: float = EDGE_RADIUS_MM) -> RigidSkull:
        """Rigid-skull obstacle with the given flap removed (``None``: intact skull)."""
        return RigidSkull(self.envelope, None if flap is None else self.flaps[flap],
                          edge_radius_mm)

    def quality(self) -> dict[str, float | int]:
        """Element quality summary (see :func:`quality.quality_stats`)."""
        return quality_stats(self.nodes_mm, self.tets)


def build_brain_mesh(
    image: TissueImage | None = None,
    target_tets: int = 100_000,
    brain_volume_ml: float | None = None,
    volume_of: str = "intracranial",
    csf_layer_mm: float = 1.5,
    base_z_mm: float | None = None,
    midsagittal: MidSagittalPlane | None = None,
    custom_flap_centre_mm: tuple[float, float, float] | None = None,
    custom_flap_diameter_mm: float = UNILATERAL_DIAMETER_MM,
    frontal_area_ratio: float = 2.0,
    refinements: int = 0,
    refine_onto_envelope: bool = True,
    fit_tissue_interfaces: bool = True,
) -> BrainMesh:
    """Build the labelled brain mesh (see module docstring).

    ``image``: tissue labels (default: the ICBM152 template); ``target_tets``: about how many
    tetrahedra; ``brain_volume_ml``: scale the geometry (uniformly, about the envelope's
    centre) so that the volume ``volume_of`` names (:data:`~brainbulge.geometry.brain.defaults.
    VOLUME_OF`: the intracranial volume, all meshed tissue incl. CSF; the ``brain``, cerebral
    gray + white matter, the paper's 1108 ml; or the ``white`` matter) is this [ml]; the
    tissues' volumes are the image's scaled by the factor cubed; ``csf_layer_mm``: CSF between brain
    and skull; ``base_z_mm``: cut plane of the fixed base (default: 12 % of the height above the
    lowest point); ``midsagittal``: the left/right plane (default x = 0 for the template, else
    through the brain centroid). Flaps ``frontal``, ``left``, ``right`` are always made, and
    ``custom`` when its centre is given (by the fitting rule,
    :func:`~brainbulge.geometry.brain.flap_fit.open_flap`). ``refinements``: Netgen meshes at about
    ``target_tets / 8**refinements`` tets, which is then refined uniformly that many times
    (:mod:`refine`: new surface nodes on the envelope): tissues are tagged (and their
    interfaces fitted) on the Netgen mesh and every child tet keeps its parent's, so the
    refined mesh's interfaces are the Netgen mesh's; sides, base and flaps are tagged on the
    final mesh.
    ``refine_onto_envelope=False`` leaves the new surface nodes at their midpoints: the
    refined mesh then has exactly the Netgen mesh's geometry (its surface chords), the
    geometry a Taylor-Hood solution on the Netgen mesh sees, for comparisons of elements and
    mesh sizes on one geometry. ``fit_tissue_interfaces``: move the tissue interfaces' nodes
    onto smoothed label surfaces (:mod:`interfaces`) instead of the voxel staircase of the
    tags (``False``: the staircase, kept for comparisons in ``benchmarks/``).
    """
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    if image is None:
        from brainbulge.geometry.brain.template import icbm152_tissue_image

        image = icbm152_tissue_image()
        midsagittal = midsagittal or MidSagittalPlane()
    midsagittal = midsagittal or MidSagittalPlane.through_centroid(image)
    if not 1_000 <= target_tets <= 20_000_000:
        raise InputError(f"target_tets = {target_tets} is outside 1e3-2e7: ask for e.g. 100000")
    envelope = intracranial_envelope(image, csf_layer_mm=csf_layer_mm)
    if brain_volume_ml is not None:
        lo, hi = BRAIN_VOLUME_RANGE_ML
        if not lo <= brain_volume_ml <= hi:
            raise InputError(f"brain volume {brain_volume_ml} ml is outside {lo:g}-{hi:g} ml")
        factor = (brain_volume_ml / _volume_of(image, envelope, volume_of)) ** (1 / 3)
        centre = envelope.centre_mm()
        image = image.scaled_about(factor, centre)
        envelope = IntracranialEnvelope(envelope.sdf_mm * np.float32(factor),
                                        _scale_affine(envelope.affine, factor, centre))
        midsagittal = MidSagittalPlane(
            tuple((centre + factor * (np.asarray(midsagittal.point_mm) - centre)).tolist()),
            midsagittal.normal)
    timings["envelope"] = time.perf_counter() - t0

    if not (isinstance(refinements, int) and 0 <= refinements <= 3):
        raise InputError(f"refinements = {refinements!r} must be 0, 1, 2 or 3")
    if refinements and target_tets / 8**refinements < 2_000:
        raise InputError(f"{target_tets} tets with {refinements} refinements leaves Netgen "
                         f"{target_tets / 8**refinements:.0f} tets to make (fewer than 2000, "
                         "too coarse for the brain): ask for fewer refinements or more tets")
    t0 = time.perf_counter()
    h_mm = element_size_for(envelope.volume_ml(), target_tets / 8**refinements)
    nodes, tets = mesh_intracranial_volume(envelope, h_mm)
    timings["tetmesh"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    nodes, tissue = _tissues(nodes, tets, image, envelope, midsagittal, fit_tissue_interfaces)
    timings["tags"] = time.perf_counter() - t0
    if refinements:
        t0 = time.perf_counter()
        nodes, tets, parent = refined_on_envelope(nodes, tets, envelope, refinements,
                                                  move=refine_onto_envelope)
        tissue = tissue[parent]
        timings["refine"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    if base_z_mm is None:
        z = nodes[:, 2]
        base_z_mm = float(z.min() + BASE_FRACTION * (z.max() - z.min()))
    def label(nodes: np.ndarray, tets: np.ndarray, tissue: np.ndarray) -> BrainMesh:
        return _labelled(nodes, tets, tissue, image, envelope, midsagittal, base_z_mm,
                         frontal_area_ratio)

    mesh = label(nodes, tets, tissue)
    if custom_flap_centre_mm is not None:  # the one rule of every custom flap
        from brainbulge.geometry.brain.flap_fit import open_flap

        open_flap(mesh, custom_flap_centre_mm, custom_flap_diameter_mm)
    timings["boundaries"] = time.perf_counter() - t0
    mesh.timings_s = timings
    return mesh


def _tissues(nodes: np.ndarray, tets: np.ndarray, image: TissueImage,
             envelope: IntracranialEnvelope, midsagittal: MidSagittalPlane,
             fit_tissue_interfaces: bool) -> tuple[np.ndarray, np.ndarray]:
    """The tissue of every tet (volume-matched tags, :func:`tag_tissue`), and the nodes with
    the interfaces fitted to the smoothed label surfaces (:func:`fit_interfaces`)."""
    tissue = tag_tissue(image, nodes, tets, intracranial_volume_ml=envelope.volume_ml(),
                        plane=midsagittal)
    if fit_tissue_interfaces:
        nodes, tissue = fit_interfaces(nodes, tets, tissue, image, envelope.volume_ml())
    return nodes, tissue


def _labelled(nodes: np.ndarray, tets: np.ndarray, tissue: np.ndarray, image: TissueImage,
              envelope: IntracranialEnvelope, midsagittal: MidSagittalPlane, base_z_mm: float,
              frontal_area_ratio: float) -> BrainMesh:
    """``(nodes, tets)`` with ``tissue``, sides, the base below ``base_z_mm`` and the flaps."""
    side = midsagittal.side(nodes[tets].mean(axis=1))
    faces, face_tet = boundary_faces(tets)
    base = nodes[faces][:, :, 2].mean(axis=1) < base_z_mm
    voxel = image.volumes_ml()
    voxel["csf"] = envelope.volume_ml() - sum(v for k, v in voxel.items() if k != "csf")
    mesh = BrainMesh(nodes, tets, tissue, side.astype(np.int8), faces, face_tet, base,
                     float(base_z_mm), envelope, voxel_volumes_ml=voxel,
                     midsagittal=midsagittal, image_grid=image.grid)
    for s in ("left", "right"):
        mesh.add_flap(unilateral_flap(envelope, s))
    mesh.add_flap(frontal_flap(envelope, nodes, faces, ~base, frontal_area_ratio))
    check_brain_mesh(mesh)
    return mesh


def refined_on_envelope(nodes: np.ndarray, tets: np.ndarray, envelope: IntracranialEnvelope,
                        refinements: int, move: bool = True
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``refinements`` uniform refinements of ``(nodes, tets)`` (mm), each followed by moving
    the new surface nodes onto the envelope (:mod:`refine`) unless ``move`` is false.
    Returns ``(nodes, tets, parent)``: ``parent[i]`` is the original tet that tet ``i`` lies in
    (interior nodes stay at edge midpoints, so tissue interfaces keep their shape)."""
    skull = RigidSkull(envelope, None)
    parent = np.arange(len(tets))
    for _ in range(refinements):
        n_old = len(nodes)
        nodes, tets, p, _ = refine_uniformly(nodes, tets)
        parent = parent[p]
        if not move:
            log.info("refined: %d tets, new surface nodes left at their midpoints", len(tets))
            continue
        faces, _ = boundary_faces(tets)
        surface_new = np.unique(faces)
        surface_new = surface_new[surface_new >= n_old]
        nodes, stayed = move_onto_surface(nodes, tets, surface_new, skull.envelope_distance)
        log.info("refined: %d tets, %d new surface nodes moved onto the envelope (%d kept at "
                 "their midpoint)", len(tets), len(surface_new) - stayed, stayed)
    return nodes, tets, parent


def _component_nearest(faces: np.ndarray, mask: np.ndarray, centroids: np.ndarray,
                       point_mm: np.ndarray) -> np.ndarray:
    """The edge-connected part of the face set ``mask`` that is nearest to ``point_mm``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    idx = np.flatnonzero(mask)
    if len(idx) == 0:
        return mask
    sub = faces[idx]
    edges = np.sort(np.concatenate([sub[:, [0, 1]], sub[:, [1, 2]], sub[:, [2, 0]]]), axis=1)
    owner = np.tile(np.arange(len(idx)), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    e, o = edges[order], owner[order]
    same = np.all(e[1:] == e[:-1], axis=1)
    graph = coo_matrix((np.ones(same.sum()), (o[:-1][same], o[1:][same])),
                       shape=(len(idx), len(idx)))
    _, comp = connected_components(graph, directed=False)
    nearest = np.argmin(np.linalg.norm(centroids[idx] - point_mm, axis=1))
    out = np.zeros_like(mask)
    out[idx[comp == comp[nearest]]] = True
    return out


def _volume_of(image: TissueImage, envelope: IntracranialEnvelope, volume_of: str) -> float:
    """The unscaled volume [ml] that ``brain_volume_ml`` sets (:data:`VOLUME_OF`)."""
    if volume_of not in VOLUME_OF:
        raise InputError(f"volume_of {volume_of!r} unknown; choose one of {', '.join(VOLUME_OF)}")
    if volume_of == "intracranial":
        return envelope.volume_ml()
    vols = image.volumes_ml()
    volume = vols["white"] + (vols["gray"] if volume_of == "brain" else 0.0)
    if volume <= 0:
        raise InputError(f"the label image has no {volume_of} matter to scale to; scale the "
                         "intracranial volume instead")
    return float(volume)


def _scale_affine(affine: np.ndarray, factor: float, centre_mm: np.ndarray) -> np.ndarray:
    scale = np.eye(4)
    scale[:3, :3] *= factor
    scale[:3, 3] = centre_mm * (1 - factor)
    return scale @ affine


#: the least volume of a usable tet [mm^3]; at or below it a tet is degenerate (or inverted)
MIN_TET_VOLUME_MM3 = 1e-9


def check_brain_mesh(mesh: BrainMesh, source: object = None) -> None:
    """Raise :class:`MeshError` (exit 5) for inverted (negative volume) or degenerate (at
    most `MIN_TET_VOLUME_MM3`) tets or an empty gray/white region; ``source``: the file the
    mesh was read from, named in the message."""
    vol = mesh.tet_volumes_mm3()
    where = f"brain mesh {source}: " if source is not None else ""
    inverted, degenerate = int((vol < 0).sum()), int((np.abs(vol) <= MIN_TET_VOLUME_MM3).sum())
    if inverted or degenerate:
        raise MeshError(f"{where}{inverted} of {len(vol)} tetrahedra inverted (negative volume)"
                        f" and {degenerate} degenerate (no volume); rebuild the mesh")
    for code in (1, 2):
        if not np.any(mesh.tissue == code):
            raise MeshError(f"{where}region {TISSUES[code]!r} has no element: ask for more "
                            "tets")
