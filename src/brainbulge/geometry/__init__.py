"""Geometries and meshes: verification inclusions, the 2D hemidisk, brains from MRI."""
