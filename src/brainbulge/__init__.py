"""brainbulge: swelling brains and decompressive craniectomy by nonlinear finite elements.

Reproduces Weickenmeier, Saez, Goriely, Kuhl, "Bulging brains", J. Elasticity 129 (2017)
197-212: an elastically incompressible, swelling Mooney-Rivlin solid (mixed
displacement-pressure formulation, ``J = Js`` enforced by a Lagrange multiplier) pressed
against a rigid skull with an opening.
"""

import os
from importlib.metadata import PackageNotFoundError, version

# Intel OpenMP (MKL PARDISO) threads spin 200 ms after each parallel region by default and
# then fight NGSolve's assembly threads for the cores: the 2D headline case took 2.8 s with
# the default and 1.6 s with 0 (measured, 2 cores). Read when OpenMP starts, so set it here;
# a value set by the user wins.
os.environ.setdefault("KMP_BLOCKTIME", "0")
# MKL's conditional numerical reproducibility: without it PARDISO on 2 threads gave
# solutions differing by ~1e-12 from one run to the next in the same process (a rerun from
# run.toml was not bit for bit); AUTO keeps the fastest code path (no measurable cost on the
# 22k-DOF hemidisk). Read when MKL loads; a value set by the user wins.
os.environ.setdefault("MKL_CBWR", "AUTO")

# Large freed arrays stay in the process (glibc's mmap/trim thresholds; brainbulge.heap):
# the 1.54M-tet solve 1,145 -> 853 s, peak 10.4 -> 10.8 GB. BRAINBULGE_KEEP_HEAP=0 switches
# it off.
if os.environ.get("BRAINBULGE_KEEP_HEAP", "1") != "0":
    from brainbulge.heap import keep_large_arrays_mapped

    keep_large_arrays_mapped()

try:
    __version__ = version("brainbulge")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
