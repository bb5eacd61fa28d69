"""Tissue parameter presets of docs/model.md section 2 [kPa].

``paper``: the values printed in Weickenmeier et al. (2017), Table 1. ``paper-pa``: the same
with ``c2`` read as Pa instead of kPa (``c2/c1`` about 1.19 instead of 1190), closer to the
~1 kPa shear moduli that brain-tissue experiments report.
"""

from __future__ import annotations

from brainbulge.errors import InputError
from brainbulge.materials.mooney_rivlin import MooneyRivlin

#: region name -> (c1, c2) [kPa]
PRESETS: dict[str, dict[str, tuple[float, float]]] = {
    "paper": {
        "gray": (0.28, 333.0),
        "white": (0.56, 666.0),
        "cerebellum": (0.28, 333.0),
        "csf": (0.03, 33.3),
    },
    "paper-pa": {
        "gray": (0.28, 0.333),
        "white": (0.56, 0.666),
        "cerebellum": (0.28, 0.333),
        "csf": (0.03, 0.0333),
    },
}


def preset(name: str) -> dict[str, MooneyRivlin]:
    """Region name -> :class:`MooneyRivlin` for a named preset."""
    try:
        table = PRESETS[name]
    except KeyError:
        raise InputError(
            f"unknown material preset {name!r}; choose one of {', '.join(PRESETS)}"
        ) from None
    return {region: MooneyRivlin(c1, c2, name=region) for region, (c1, c2) in table.items()}
