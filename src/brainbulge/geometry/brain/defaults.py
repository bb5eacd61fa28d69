"""Defaults of the brain geometry that light modules (the CLI's parser) need without
importing the meshing stack."""

#: Default rounding radius of the skull's cut edge at a flap [mm], in the bone outside the
#: opening (the opening on the skull's inner surface is the nominal flap for every radius). A
#: node pressed on the rounded edge, its contact force times the edge's curvature near its own
#: stiffness, creeps around it and stalls Newton: on the 21k-tet template brain 8 mm completes
#: the six scenarios and 4 mm stalls in one (frontal flap, right swelling, Js 1.096; docs/
#: model.md). With the rounding made by eroding the cutter instead, 3 mm stalled at >= 400k
#: tets and 6 mm at 1.54M, 8 mm converged there. In the bone (docs/design.md): on the 111k-tet
#: template 2 mm completes the six scenarios (8-13 Newton iterations) and 1 mm five of six; at
#: 428k tets 2 mm stalls at full load (left flap, both sides), also with the 2D resolved edge's
#: capped Newton updates, and so does 4 mm.
EDGE_RADIUS_MM = 8.0
#: the cut edge's rounding radii a case may ask for [mm]: below 0.1 mm the edge is sharp for
#: any mesh, beyond 10 mm the rounding eats into small flaps
EDGE_RADIUS_RANGE_MM = (0.1, 10.0)

#: diameter of the unilateral (fronto-temporo-parietal) flap and the default of a custom one
#: [mm]: the 12 cm of the guidelines
UNILATERAL_DIAMETER_MM = 120.0
#: diameters of a custom flap [mm] the skull can be cut to
FLAP_DIAMETER_RANGE_MM = (10.0, 250.0)
#: volumes [ml] a geometry may be scaled to (``brain_volume_ml``)
BRAIN_VOLUME_RANGE_ML = (50.0, 5000.0)

#: What ``brain_volume_ml`` scales the geometry to: the ``intracranial`` volume (all meshed
#: tissue incl. CSF), the ``brain`` (cerebral gray + white matter) or the ``white`` matter.
VOLUME_OF = ("intracranial", "brain", "white")

#: The fixed part of the brain's outer surface: the inferior surface (the base), or that and
#: the superior band along the midline (the paper's Figure 6, the default).
FIXATIONS = ("inferior", "inferior+superior")
#: Width (mm) of the fixed superior band across the mid-sagittal plane: the superior sagittal
#: sinus, to whose dura the brain is tied by the falx and the bridging veins, is ~1 cm wide.
SUPERIOR_WIDTH_MM = 10.0
#: the band's widths [mm]: more than zero, at most this
SUPERIOR_WIDTH_RANGE_MM = (0.0, 60.0)
#: The band's extent: faces seen from the brain centre at least this far above the horizontal
#: (deg). The sinus runs along the whole vault from the crista galli to the torcula; above the
#: centre it lies against the convexity (below, it reaches the skull base and the tentorium).
SUPERIOR_ELEVATION_DEG = 0.0
#: the band's lowest elevations [deg]: from this, below the upper bound
SUPERIOR_ELEVATION_RANGE_DEG = (-30.0, 90.0)

#: from this many requested tets up the defaults are those of a large mesh
#: (:func:`brainbulge.model.brain.size_defaults`): below it PARDISO on one Netgen mesh is
#: quicker and lighter
LARGE_TETS = 400_000
