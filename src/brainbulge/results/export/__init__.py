"""Files for other tools: ParaView (VTU) and NumPy (NPZ) writers of the fields."""
