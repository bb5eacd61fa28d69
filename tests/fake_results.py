"""What the data-safety tests' stand-ins for a run return, and how they read its one-line error."""

from __future__ import annotations

#: a hemidisk summary with every key the command's printout reads (nondimensional, R = 1)
SUMMARY = {"max_displacement": 0.1, "min_radial_stretch": 0.9, "max_radial_stretch": 1.1,
           "min_tangential_stretch": 0.9, "max_tangential_stretch": 1.2, "max_penetration": 0.0,
           "max_skull_crossing": 0.0}
#: a brain summary with the keys the command's printout reads
BRAIN = {"swelling_reached": 1.1, "max_displacement": 1.0, "midline_shift_mm": 0.1,
         "bulge_volume_ml": 10.0, "max_principal_strain": 0.1, "max_penetration_mm": 0.0}


def one_line(capsys) -> str:
    """The run's error: one line on stderr, neither a traceback nor an internal error."""
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0] and "internal" not in err[0], err
    return err[0]
