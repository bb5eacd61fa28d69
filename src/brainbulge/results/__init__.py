"""Post-processing: kinematic fields, clinical metrics, summaries, files and figures."""
