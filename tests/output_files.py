"""What a run wrote into its folder, read back for the tests of the output schema."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def written_fields(folder: Path) -> tuple[set[str], set[str], set[str]]:
    """The fields of ``folder``'s ``fields.npz`` (its ``point_<field>`` arrays) and the
    point and cell data of its ``fields.vtu``."""
    import meshio

    with np.load(folder / "fields.npz") as npz:
        in_npz = {k.removeprefix("point_") for k in npz.files if k.startswith("point_")}
    vtu = meshio.read(folder / "fields.vtu")
    return in_npz, set(vtu.point_data), set(vtu.cell_data)
