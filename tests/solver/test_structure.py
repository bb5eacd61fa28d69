"""The solver's shape, held by parsing ``solver/`` (not running it): the continuation
driver's step loop and Newton's loop each fit on one screen (at most 60 lines), and no
solver class inherits from another (composition: a class holds what it builds on)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import brainbulge.solver

SOLVER = Path(brainbulge.solver.__file__).parent
#: bases a class may have: interfaces and kinds (records), not other solvers
INTERFACES = {"Protocol", "Enum", "NamedTuple", "OptionGroup", "NewtonObserver"}
#: inheritance left as it is, and why
LEFT = {
    ("fast/mini_plane.py", "PlaneMiniTangent"): "the 2D closed-form element kernels reuse "
    "the 3D kernels' bubble operators (extend, inner_solve); not a solve's layer",
    ("linear/direct.py", "PatternReusingPardiso"): "extends the pypardiso library's solver "
    "(keeps its symbolic factorisation per sparsity pattern); not one of ours",
}


def _function(module: str, name: str) -> ast.FunctionDef:
    tree = ast.parse((SOLVER / module).read_text())
    return next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == name)


@pytest.mark.parametrize(("module", "name"), [("driver.py", "walk"),
                                              ("newton.py", "_iterate")])
def test_the_loops_fit_on_one_screen(module, name) -> None:
    f = _function(module, name)
    assert f.end_lineno - f.lineno + 1 <= 60


def test_no_solver_class_inherits_from_another() -> None:
    wrong = []
    for path in sorted(SOLVER.rglob("*.py")):
        module = path.relative_to(SOLVER).as_posix()
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ClassDef) or (module, node.name) in LEFT:
                continue
            bases = {b.id if isinstance(b, ast.Name) else getattr(b, "attr", "?")
                     for b in node.bases}
            if bases - INTERFACES:
                wrong.append(f"{module}: {node.name}({', '.join(sorted(bases))})")
    assert not wrong, "hold, do not inherit:\n" + "\n".join(wrong)
