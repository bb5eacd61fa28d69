"""The output folder: claiming it safely, its manifest, run records and run files."""
