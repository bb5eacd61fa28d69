"""Defaults of the brain geometry that light modules (the CLI's parser) need without
importing the meshing stack."""

#: Default rounding radius of the skull's cut edge at a flap [mm]. A node pressed on the
#: rounded edge, its contact force times the edge's curvature near its own stiffness, creeps
#: around it and stalls Newton (docs/design.md): 3 mm stalled at >= 400k tets, 6 mm converged
#: at 428k but stalled at the last load step of the 1.54M-tet (paper-resolution) brain, 8 mm
#: converges there (docs/performance.md).
EDGE_RADIUS_MM = 8.0
