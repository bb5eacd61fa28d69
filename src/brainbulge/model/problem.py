"""A swelling problem on a mesh: what is solved, independent of how.

Regions of the mesh (NGSolve material names) map to materials and to a target swelling ``Js``
[-]. Boundaries (NGSolve boundary names, regular expressions allowed) are clamped, clamped per
component (symmetry planes), in frictionless contact with a rigid obstacle, or traction-free
(everything else).
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

import ngsolve as ngs
import numpy as np

from brainbulge.errors import InputError
from brainbulge.materials.base import Material


class Obstacle(Protocol):
    """A rigid body described by its signed distance ``g(x)`` [length] on point arrays.

    ``g > 0`` outside the rigid body (admissible), ``g < 0`` inside it (penetration).
    """

    def gap_and_normal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``g`` (n,) at the (deformed) points ``x`` (n, dim) and ``grad g`` (n, dim)."""
        ...


@dataclass
class Contact:
    """Frictionless unilateral contact of ``boundary`` with a rigid ``obstacle``: with exact
    multipliers at the boundary nodes by a primal-dual active set (``penalty`` None), or by
    a penalty ``penalty/2 max(-g, 0)^2`` at the boundary's Gauss points (``penalty``: its
    stiffness [stress/length]; the obstacle then needs ``gap(x)`` on NGSolve coefficient
    functions; 2D)."""

    boundary: str
    obstacle: Obstacle
    penalty: float | None = None

    def __post_init__(self) -> None:
        need = "gap_and_normal" if self.penalty is None else "gap"
        if not hasattr(self.obstacle, need):
            raise InputError(f"the obstacle of contact boundary {self.boundary!r} has no "
                             f"{need}(x); give it one")


@dataclass
class Problem:
    """Everything that defines a swelling solve.

    Attributes:
        mesh: NGSolve mesh, 2D (plane strain) or 3D, lengths in the user's unit.
        materials: region name -> material; a region absent here is an error.
        swelling: region name -> target ``Js`` (>0; default 1 for unnamed regions).
        clamped: regex of boundaries where ``u = 0``.
        clamped_components: component index -> regex of boundaries where ``u_i = 0``.
        contacts: frictionless contact conditions.
        displacements: boundary regex -> displacement at full load per component (``None``
            leaves a component free), ramped with the load factor like ``Js`` [length].
    """

    mesh: ngs.Mesh
    materials: dict[str, Material]
    swelling: dict[str, float] = field(default_factory=dict)
    clamped: str = ""
    clamped_components: dict[int, str] = field(default_factory=dict)
    contacts: list[Contact] = field(default_factory=list)
    displacements: dict[str, tuple[float | None, ...]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        regions = set(self.mesh.GetMaterials())
        missing = regions - set(self.materials)
        if missing:
            raise InputError(
                f"no material for mesh region(s) {', '.join(sorted(missing))}; "
                "assign one to every region"
            )
        for region, Js in self.swelling.items():
            if region not in regions:
                raise InputError(f"swelling given for unknown region {region!r}")
            if not isinstance(Js, (int, float)) or not math.isfinite(Js) or Js <= 0:
                raise InputError(
                    f"swelling Js = {Js!r} in region {region!r} must be a positive number"
                )

    @property
    def dim(self) -> int:
        return self.mesh.dim

    def swelling_cf(self) -> ngs.CoefficientFunction:
        """Piecewise-constant target swelling ``Js(X)`` [-]."""
        values = {r: float(self.swelling.get(r, 1.0)) for r in self.mesh.GetMaterials()}
        return self.mesh.MaterialCF(values, default=1.0)

    def boundary_names(self) -> list[str]:
        return sorted(set(self.mesh.GetBoundaries()))

    def traction_free_boundaries(self) -> list[str]:
        """Boundaries that are neither clamped (fully or per component) nor in contact."""
        taken = [self.clamped, *self.clamped_components.values()]
        taken += [c.boundary for c in self.contacts]
        taken += list(self.displacements)
        pats = [re.compile(f"^(?:{p})$") for p in taken if p]
        outer = outer_boundary_names(self.mesh)
        return [b for b in outer if not any(p.match(b) for p in pats)]


def outer_boundary_names(mesh: ngs.Mesh) -> list[str]:
    """Names of boundary parts on the outer surface (internal interfaces, which netgen
    also lists as boundaries when regions are glued, are left out)."""
    names = mesh.GetBoundaries()
    found: set[str] = set()
    for el in mesh.Elements(ngs.BND):
        name = names[el.index]
        if name in found:
            continue
        facet = el.edges[0] if mesh.dim == 2 else el.faces[0]
        if len(mesh[facet].elements) == 1:
            found.add(name)
    return sorted(found)


Case = TypeVar("Case")


def case_from_config(cls: type[Case], config: dict[str, Any], what: str) -> Case:
    """A case dataclass ``cls`` from a plain dict (TOML table, CLI, study scenario), with a
    one-line error naming unknown or ill-typed ``what`` options."""
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(config) - names)
    if unknown:
        import difflib

        near = difflib.get_close_matches(unknown[0], sorted(names), n=1, cutoff=0.6)
        raise InputError(
            f"unknown {what} option(s) {', '.join(unknown)}; "
            + (f"did you mean {near[0]!r}?" if near else f"valid: {', '.join(sorted(names))}")
        )
    try:
        return cls(**config)
    except TypeError as err:
        raise InputError(f"invalid {what} options: {err}") from None



def case_tables(case: Any, solver_fields: tuple[str, ...]) -> dict[str, dict[str, Any]]:
    """A case dataclass as the two tables of a run file: ``case`` (what is simulated: physics,
    geometry, outputs) and ``solver`` (how: the discretisation and the solver's numerics,
    the names ``solver_fields``). ``None`` values are left out (TOML has no null), tuples
    become lists."""
    tables: dict[str, dict[str, Any]] = {"case": {}, "solver": {}}
    for key, value in dataclasses.asdict(case).items():
        if value is None or (key == "extra" and not value):
            continue
        table = "solver" if key in solver_fields else "case"
        tables[table][key] = list(value) if isinstance(value, tuple) else value
    return tables


def case_options(config: dict[str, Any], command: str, where: str) -> dict[str, Any]:
    """The flat options of a run file: its ``[case]`` and ``[solver]`` tables, or the one
    ``[<command>]`` table of files written before the two were separate."""
    if "case" not in config and "solver" not in config:
        table = config.get(command)
        if not isinstance(table, dict):
            raise InputError(f"{where}: missing the tables [case] and [solver] with the "
                             "case's options")
        return dict(table)
    options: dict[str, Any] = {}
    for name in ("case", "solver"):
        table = config.get(name, {})
        if not isinstance(table, dict):
            raise InputError(f"{where}: [{name}] must be a table of options")
        twice = set(options) & set(table)
        if twice:
            raise InputError(f"{where}: {', '.join(sorted(twice))} given in both [case] and "
                             "[solver]; keep one")
        options.update(table)
    return options
