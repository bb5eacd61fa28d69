"""What a solve leaves behind, in four rooms, each importing only the ones before it:
:mod:`.records` (the output folder, its manifest and run records), :mod:`.measures` (fields
and the summary's measures from a solution), :mod:`.export` (files for other tools: VTU,
NPZ) and :mod:`.present` (figures, sections, 3D views and the HTML reports)."""
