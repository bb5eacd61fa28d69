"""Defaults of the brain geometry that light modules (the CLI's parser) need without
importing the meshing stack."""

#: Default rounding radius of the skull's cut edge at a flap [mm], in the bone outside the
#: opening (the opening on the skull's inner surface is the nominal flap for every radius). A
#: node pressed on the rounded edge, its contact force times the edge's curvature near its own
#: stiffness, creeps around it and stalls Newton: on the 21k-tet template brain 8 mm completes
#: the six scenarios and 4 mm stalls in one (frontal flap, right swelling, Js 1.096; docs/
#: model.md). With the rounding made by eroding the cutter instead, 3 mm stalled at >= 400k
#: tets and 6 mm at 1.54M, 8 mm converged there; not yet measured at that size in the bone.
EDGE_RADIUS_MM = 8.0

#: What ``brain_volume_ml`` scales the geometry to: the ``intracranial`` volume (all meshed
#: tissue incl. CSF), the ``brain`` (cerebral gray + white matter) or the ``white`` matter.
VOLUME_OF = ("intracranial", "brain", "white")

#: The fixed part of the brain's outer surface: the inferior surface (the base), or that and
#: the superior band along the midline (the paper's Figure 6, the default).
FIXATIONS = ("inferior", "inferior+superior")
#: Width (mm) of the fixed superior band across the mid-sagittal plane: the superior sagittal
#: sinus, to whose dura the brain is tied by the falx and the bridging veins, is ~1 cm wide.
SUPERIOR_WIDTH_MM = 10.0
#: The band's extent: faces seen from the brain centre at least this far above the horizontal
#: (deg). The sinus runs along the whole vault from the crista galli to the torcula; above the
#: centre it lies against the convexity (below, it reaches the skull base and the tentorium).
SUPERIOR_ELEVATION_DEG = 0.0

#: from this many requested tets up the defaults are those of a large mesh
#: (:func:`brainbulge.model.brain.size_defaults`): below it PARDISO on one Netgen mesh is
#: quicker and lighter
LARGE_TETS = 400_000
