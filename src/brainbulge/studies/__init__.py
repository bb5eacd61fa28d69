"""Studies: the paper's parameter studies and sweeps, run in parallel by `runner.run_study`."""
