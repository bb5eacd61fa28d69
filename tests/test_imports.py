"""Start-up cost: the command line's parser does not load the meshing stack, and the brain
geometry package still offers every public name (loaded on first use)."""

from __future__ import annotations

import subprocess
import sys

import pytest


def test_the_parser_does_not_import_the_brain_meshing_stack() -> None:
    """Building every subcommand's parser (what each ``brainbulge`` call does first) leaves
    scipy.ndimage and the brain mesh modules unloaded (~0.3 s per command), and NGSolve,
    which must load after the runtime's configuration (threads, MKL), though the hemidisk's
    options are read from its case."""
    code = ("import sys; from brainbulge.cli import build_parser; build_parser(); "
            "print(sorted(m for m in ('scipy.ndimage', 'brainbulge.geometry.brain.skull', "
            "'brainbulge.geometry.brain.brain_mesh', 'ngsolve', 'netgen') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]"


def test_every_public_name_of_the_brain_package_resolves() -> None:
    import brainbulge.geometry.brain as brain
    from brainbulge.geometry.brain.defaults import EDGE_RADIUS_MM
    from brainbulge.geometry.brain.skull import EDGE_RADIUS_MM as from_skull

    for name in brain.__all__:
        assert getattr(brain, name) is not None
        assert name in dir(brain)
    assert from_skull == EDGE_RADIUS_MM
    with pytest.raises(AttributeError, match="no attribute 'nonexistent'"):
        brain.nonexistent  # noqa: B018
