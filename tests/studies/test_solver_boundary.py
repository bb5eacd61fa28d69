"""The studies describe a solve, the solver chooses how to run it: a module of
``brainbulge.studies`` imports from ``brainbulge.solver`` only :func:`solve`, the strategy
and the result and option types (parsed, not run: imports inside functions count too)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import brainbulge.solver
import brainbulge.studies

STUDIES = sorted(Path(brainbulge.studies.__file__).parent.glob("*.py"))
#: what a study may take from the solver: the entry point, the strategy and the means it
#: describes, the results (a solution, its form, its failure and records) and the options
ALLOWED = {
    "solve", "Strategy", "Route", "Rezoning",
    "Solution", "Failure", "StepRecord", "MixedForm",
    "SolverOptions", "RezoningOptions",
    "WarmStartOptions", "KrylovOptions", "HotspotOptions",
}


def _solver_imports(path: Path) -> list[tuple[int, str, str]]:
    """``(line, module, name)`` of every import of ``brainbulge.solver`` in ``path``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom) and node.module is not None:
            if node.module == "brainbulge" and any(a.name == "solver" for a in node.names):
                found.append((node.lineno, "brainbulge", "solver"))
            elif node.module.startswith("brainbulge.solver"):
                found += [(node.lineno, node.module, a.name) for a in node.names]
        elif isinstance(node, ast.Import):
            found += [(node.lineno, a.name, "*") for a in node.names
                      if a.name.startswith("brainbulge.solver")]
    return sorted(found)


def test_the_studies_are_found() -> None:
    assert {"craniectomy.py", "hemidisk.py", "plan.py"} <= {p.name for p in STUDIES}


@pytest.mark.parametrize("path", STUDIES, ids=[p.name for p in STUDIES])
def test_a_study_imports_only_solve_the_strategy_and_result_and_option_types(path) -> None:
    wrong = [f"{path.name}:{line}: {module} {name}"
             for line, module, name in _solver_imports(path)
             if module != "brainbulge.solver" or name not in ALLOWED]
    assert not wrong, "studies wire no solvers; import from brainbulge.solver only " + (
        ", ".join(sorted(ALLOWED))) + ":\n" + "\n".join(wrong)


def test_the_allowed_names_are_the_solver_packages_own() -> None:
    exported = set(brainbulge.solver.__all__)
    assert {"solve", "Strategy", "Solution", "SolverOptions", "MixedForm", "Rezoning"} <= exported
    for name in ALLOWED:
        assert hasattr(brainbulge.solver, name) or name.endswith("Options"), name


def test_the_finder_sees_a_forbidden_import(tmp_path) -> None:
    bad = tmp_path / "bad.py"
    bad.write_text("def f():\n    from brainbulge.solver.ramp import NewtonSolver\n"
                   "import brainbulge.solver.remesh.rezoning\n")
    assert [(m, n) for _, m, n in _solver_imports(bad)] == [
        ("brainbulge.solver.ramp", "NewtonSolver"),
        ("brainbulge.solver.remesh.rezoning", "*")]
