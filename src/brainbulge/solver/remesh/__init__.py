"""Changing the mesh during a solve: 2D rezoning of the bulge (:mod:`.rezoning`)."""
