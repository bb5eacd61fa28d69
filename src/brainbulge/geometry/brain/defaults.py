"""Defaults of the brain geometry that light modules (the CLI's parser) need without
importing the meshing stack."""

#: Default rounding radius of the skull's cut edge at a flap [mm]. A node pressed on the
#: rounded edge, its contact force times the edge's curvature near its own stiffness, creeps
#: around it and stalls Newton (docs/design.md): 3 mm stalled at >= 400k tets, 6 mm converged
#: at 428k but stalled at the last load step of the 1.54M-tet (paper-resolution) brain, 8 mm
#: converges there (docs/performance.md).
EDGE_RADIUS_MM = 8.0

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
