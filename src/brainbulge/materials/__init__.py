"""Constitutive models (docs/model.md section 2): isochoric energies, nothing about meshes."""

from brainbulge.materials.base import Material
from brainbulge.materials.mooney_rivlin import MooneyRivlin, neo_hookean
from brainbulge.materials.ogden import Ogden
from brainbulge.materials.presets import PRESETS, preset

__all__ = ["Material", "MooneyRivlin", "Ogden", "PRESETS", "neo_hookean", "preset"]
