"""Changing the mesh during a solve: 2D rezoning of the bulge (:mod:`.rezoning`) and 3D mesh
sequencing, coarse solution carried to a finer mesh (:mod:`.sequencing`)."""
