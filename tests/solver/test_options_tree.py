"""The solver's options tree: every field of every group of :class:`SolverOptions` declares
its default, unit, range and reason (a switch: its reason; a choice: its choices), the default
lies in the range, and a value outside it is refused with a message that names the field.
No tunable lives outside the tree: no module-level numeric constant in ``solver/`` (but the
round-off guards and fixed discretisation choices listed here, each with its reason), and no
number other than 0, 1, 2 in the control flow of the solver's loops (parsed, not run)."""

from __future__ import annotations

import ast
import dataclasses
import math
from pathlib import Path

import pytest

import brainbulge.solver
from brainbulge.errors import InputError
from brainbulge.model.options import label
from brainbulge.solver import SolverOptions

GROUPS = [f for f in dataclasses.fields(SolverOptions)
          if dataclasses.is_dataclass(getattr(SolverOptions(), f.name))]
LEAVES = [(g.name, type(getattr(SolverOptions(), g.name)), f)
          for g in GROUPS for f in dataclasses.fields(getattr(SolverOptions(), g.name))]


def test_the_tree_has_the_solvers_and_the_continuations_groups() -> None:
    assert {g.name for g in GROUPS} >= {"ramp", "newton", "linear", "rezoning", "warm_start",
                                        "krylov", "hotspot"}
    for g in GROUPS:
        group = getattr(SolverOptions(), g.name)
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(group, dataclasses.fields(group)[0].name, 1)


@pytest.mark.parametrize(("group", "cls", "f"), LEAVES,
                         ids=[f"{g}.{f.name}" for g, _, f in LEAVES])
def test_each_field_has_a_default_unit_range_and_reason(group, cls, f) -> None:
    assert f.default is not dataclasses.MISSING
    assert len(f.metadata["help"]) > 40  # the reason for the default, not just a name
    if isinstance(f.default, bool):  # a switch: on or off, its reason
        assert f.metadata["range"] is None
        return
    if isinstance(f.default, str):  # a choice
        assert f.default in f.metadata["choices"]
        with pytest.raises(InputError, match="unknown"):
            cls(**{f.name: "no-such-choice"})
        return
    assert f.metadata["unit"].strip()
    lo, hi = (getattr(cls(), b) if isinstance(b, str) else b for b in f.metadata["range"])
    assert lo <= f.default <= hi and lo < hi
    integer = isinstance(f.default, int)
    above = hi + 1 if integer else hi * 2 + 1
    below = lo - 1 if integer else (lo / 2 if lo > 0 else lo - 1.0)
    for bad in (above, below, math.nan):
        with pytest.raises(InputError, match=label(f)):
            cls(**{f.name: bad})
    if integer:
        with pytest.raises(InputError, match="whole number"):
            cls(**{f.name: f.default + 0.5})


def test_the_old_flat_names_set_the_groups_fields() -> None:
    """``SolverOptions(steps=2, tolerance=1e-8, linear_solver="krylov")`` (the API's and the
    run files' names) sets the groups' fields; ``dataclasses.replace`` takes them too."""
    from brainbulge.solver.options import SHORTHAND

    opt = SolverOptions(steps=2, tolerance=1e-8, linear_solver="krylov", eta_max=1e-3)
    assert (opt.ramp.steps, opt.newton.tolerance, opt.linear.solver, opt.linear.eta_max) == (
        2, 1e-8, "krylov", 1e-3)
    again = dataclasses.replace(opt, max_iterations=8)
    assert again.newton.max_iterations == 8 and again.ramp.steps == 2
    for name, (group, key) in SHORTHAND.items():
        assert key in {f.name for f in dataclasses.fields(getattr(opt, group))}, name
    with pytest.raises(TypeError, match="unknown"):
        SolverOptions(no_such_option=1)


SOLVER = Path(brainbulge.solver.__file__).parent
#: module-level numbers in ``solver/`` that are not tunables of a solve, and why
NOT_TUNABLE = {
    ("driver.py", "REACHED"): "round-off: a parameter within 1e-12 of its target reached it",
    ("mixed.py", "SPLIT_MIN_ELEMENTS"): "how the form is compiled (the same energy), not how "
                                       "it is solved",
    ("fast/hotspot.py", "HEAP"): "NGSolve's local heap in bytes: memory, not numerics",
    ("fast/mini_plane.py", "QUAD_ORDER"): "the quadrature of the MINI bubble (discretisation)",
    ("contact/penalty.py", "POINTS"): "the penalty contact's Gauss points per boundary segment "
    "(discretisation)",
    ("fast/mini_plane.py", "NGSOLVE_ORDER"): "NGSolve's numbering of the element DOFs",
    ("fast/mini_plane.py", "_REF_GRAD"): "the reference triangle's barycentric gradients",
    ("fast/mini_kernels.py", "QUAD_POINTS"): "the tetrahedron's 4-point rule (discretisation)",
    ("fast/mini_kernels.py", "_A"): "the 4-point rule's barycentric coordinate",
    ("fast/mini_kernels.py", "_B"): "the 4-point rule's barycentric coordinate",
    ("fast/mini_kernels.py", "QUAD_WEIGHT"): "the 4-point rule's weight",
}


def _numeric(node: ast.AST) -> bool:
    """An expression of numbers only (``1 - 1e-12``, ``np.array([[1.0, 0.0]])``)."""
    consts = [n for n in ast.walk(node) if isinstance(n, ast.Constant)]
    names = {n.id for n in ast.walk(node) if isinstance(n, ast.Name)} - {"np", "_A", "_B"}
    return bool(consts) and not names and all(
        type(c.value) in (int, float) for c in consts)


def _module_numbers() -> list[tuple[str, str]]:
    found = []
    for path in sorted(SOLVER.rglob("*.py")):
        for node in ast.parse(path.read_text()).body:
            targets, value = [], None
            if isinstance(node, ast.Assign):
                targets, value = node.targets, node.value
            elif isinstance(node, ast.AnnAssign) and node.value is not None:
                targets, value = [node.target], node.value
            for t in targets:
                if isinstance(t, ast.Name) and _numeric(value):
                    found.append((path.relative_to(SOLVER).as_posix(), t.id))
    return found


def test_no_module_level_tunable_constant_in_the_solver() -> None:
    tunable = [f"{f}: {name}" for f, name in _module_numbers() if (f, name) not in NOT_TUNABLE]
    assert not tunable, ("a tunable belongs in the options tree (solver/option_groups.py), "
                         "with its default, unit, range and reason:\n" + "\n".join(tunable))


#: the solver's loops: a module and its functions or classes (every method)
LOOPS = {
    "driver.py": ("walk", "fallback"),
    "newton.py": ("newton", "_iterate", "_step"),
    "ramp.py": ("NewtonSolver", "LoadRamp"),
    "remesh/rezoning.py": ("RezoningRamp",),
    "warm_start.py": ("solve_from_start", "warm_start_options"),
    "strategy.py": ("Strategy", "solve"),
}


def _loop_numbers() -> list[str]:
    found, seen = [], set()
    for module, names in LOOPS.items():
        for node in ast.parse((SOLVER / module).read_text()).body:
            name = getattr(node, "name", None)
            if name not in names:
                continue
            seen.add((module, name))
            found += [f"{module}:{n.lineno} {name}: {n.value!r}" for n in ast.walk(node)
                      if isinstance(n, ast.Constant) and type(n.value) in (int, float)
                      and n.value not in (0, 1, 2)]
    assert seen == {(m, n) for m, names in LOOPS.items() for n in names}  # all found
    return found


def test_no_bare_number_in_the_solvers_loops() -> None:
    """Cut, growth, halving factors: option fields, not
    numbers in the code (0, 1, 2 are arithmetic: an index, a unit step, a halving's
    inverse)."""
    numbers = _loop_numbers()
    assert not numbers, "an option field instead of:\n" + "\n".join(numbers)
