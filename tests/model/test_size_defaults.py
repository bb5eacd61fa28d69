"""The defaults chosen from the requested mesh size, and explicit options over them."""

from __future__ import annotations

import numpy as np
import pytest

from brainbulge.cli import build_parser
from brainbulge.cli.brain import config_from_args
from brainbulge.errors import InputError
from brainbulge.geometry.brain.export import stored_tets
from brainbulge.model.brain import (
    LARGE_TETS,
    CraniectomyCase,
    size_defaults,
)
from brainbulge.studies.craniectomy import with_size_defaults


@pytest.mark.parametrize("tets", [30_000, 100_000, LARGE_TETS - 1])
def test_small_meshes_keep_one_netgen_mesh_and_pardiso(tets) -> None:
    assert size_defaults(tets) == (0, "pardiso")


@pytest.mark.parametrize("tets", [LARGE_TETS, 1_400_000, 3_000_000])
def test_large_meshes_refine_once_and_ramp_with_krylov(tets) -> None:
    assert size_defaults(tets) == (1, "krylov")


def test_explicit_options_win() -> None:
    assert size_defaults(1_400_000, linear_solver="pardiso") == (1, "pardiso")
    assert size_defaults(1_400_000, refine=2) == (2, "krylov")
    assert size_defaults(1_400_000, refine=0) == (0, "krylov")
    assert size_defaults(100_000, refine=1, linear_solver="krylov") == (1, "krylov")


def test_a_given_mesh_is_not_refined_unasked() -> None:
    assert size_defaults(1_400_000, mesh_given=True) == (0, "krylov")
    assert size_defaults(100_000, mesh_given=True) == (0, "pardiso")


@pytest.mark.parametrize("tets, solver", [(LARGE_TETS - 1, "pardiso"), (LARGE_TETS, "krylov")])
def test_a_mesh_file_chooses_the_solver_by_its_own_size(tmp_path, tets, solver) -> None:
    """``--mesh`` of a paper-resolution brain gets GMRES, as the same mesh built by the
    command does (PARDISO would need several times the memory); the size is read from the
    file, whatever ``--tets`` says."""
    path = tmp_path / "brain.npz"
    np.savez(path, tets=np.zeros((tets, 4), dtype=np.int32))
    assert stored_tets(path) == tets
    case = CraniectomyCase(mesh=str(path))
    assert (case.refine, case.linear_solver) == (0, solver)
    assert CraniectomyCase(mesh=str(path), tets=5_000_000).linear_solver == solver
    assert CraniectomyCase(mesh=str(path), linear_solver="pardiso").linear_solver == "pardiso"


def test_an_unreadable_mesh_file_is_a_clear_error(tmp_path) -> None:
    """Reading the size refuses a file that is no brain.npz; the case then keeps the
    defaults of ``--tets`` and leaves the refusal to the mesh's reader (which says more)."""
    path = tmp_path / "brain.npz"
    path.write_text("not a mesh")
    with pytest.raises(InputError, match="cannot read brain mesh"):
        stored_tets(path)
    assert CraniectomyCase(mesh=str(path)).linear_solver == "pardiso"
    np.savez(path, nodes=np.zeros((3, 3)))  # a zip without tets
    with pytest.raises(InputError, match="give a brain.npz"):
        stored_tets(path)


def test_the_case_resolves_its_defaults() -> None:
    large = CraniectomyCase(tets=1_400_000)
    assert (large.refine, large.linear_solver) == (1, "krylov")
    small = CraniectomyCase(tets=30_000)
    assert (small.refine, small.linear_solver) == (0, "pardiso")
    other = CraniectomyCase(tets=1_400_000, linear_solver="pardiso")
    assert other.linear_solver == "pardiso"


def test_the_command_line_passes_only_what_the_user_gave() -> None:
    parse = build_parser().parse_args
    cfg = config_from_args(parse(["brain", "--tets", "1400000", "--out", "x"]))
    assert not {"refine", "linear_solver"} & set(cfg)  # left to the case
    case = CraniectomyCase(**cfg)
    assert (case.refine, case.linear_solver) == (1, "krylov")
    cfg = config_from_args(parse(["brain", "--tets", "1400000", "--linear-solver", "pardiso",
                                  "--refine", "0", "--out", "x"]))
    case = CraniectomyCase(**cfg)
    assert (case.refine, case.linear_solver) == (0, "pardiso")


def test_a_study_takes_the_defaults_of_its_size() -> None:
    sc = with_size_defaults({"tets": 1_400_000, "flap": "left"})
    assert (sc["refine"], sc["linear_solver"]) == (1, "krylov")
    sc = with_size_defaults({"tets": 1_400_000, "linear_solver": "pardiso", "refine": 0})
    assert (sc["refine"], sc["linear_solver"]) == (0, "pardiso")
