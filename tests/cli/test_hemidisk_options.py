"""The hemidisk case owns its options: the command line's options, defaults, ranges and
help, the run file's keys and the checks all come from :class:`HemidiskCase`, so one
mistake gives one message whichever way the case is given."""

from __future__ import annotations

import dataclasses
import re

import pytest

from brainbulge.cli import main
from brainbulge.errors import InputError
from brainbulge.model.hemidisk import (
    DISK_SWELLING,
    SECTOR_SWELLING,
    SOLVER_FIELDS,
    SWELLING_RANGE,
    HemidiskCase,
)

#: fields set through a run file or the Python API only, deliberately not command-line options
INTERNAL = {"tissue", "skull_thickness", "name"}


def _help(capsys) -> str:
    with pytest.raises(SystemExit):
        main(["hemidisk", "--help"])
    return " ".join(capsys.readouterr().out.split())  # argparse's line breaks undone


def test_the_swelling_default_depends_on_the_case() -> None:
    """The paper's sector cases swell to Js = 1.2, its disk case to 1.3; a given value wins."""
    assert (SECTOR_SWELLING, DISK_SWELLING) == (1.2, 1.3)
    assert HemidiskCase().swelling == 1.2
    assert HemidiskCase(alpha=40.0).swelling == 1.2
    disk = HemidiskCase(disk=[0.0, 0.5, 0.15])
    assert disk.swelling == 1.3 and disk.alpha is None
    assert HemidiskCase(disk=[0.0, 0.5, 0.15], swelling=1.1).swelling == 1.1


def test_the_help_shows_the_case_defaults_and_ranges(capsys) -> None:
    text = _help(capsys)
    lo, hi = SWELLING_RANGE
    assert (f"--swelling SWELLING target swelling Js of the sector or disk (default "
            f"{SECTOR_SWELLING:g} for a sector, {DISK_SWELLING:g} for a disk; range "
            f"[{lo:g}, {hi:g}])") in text
    assert "--mesh-size MESH_SIZE element size [units of R] (default 0.05; range [0.005, 1])" \
        in text
    assert "--steps STEPS initial number of load steps (default 4; range [1, 1000])" in text
    for f in dataclasses.fields(HemidiskCase):  # every default the help states is the case's
        if f.name in INTERNAL or f.default is None or isinstance(f.default, bool):
            continue
        shown = f"{f.default:g}" if isinstance(f.default, float | int) else f.default
        assert f"default {shown}" in text, f.name


def test_every_field_is_an_option_or_internal(capsys) -> None:
    """Each field of the case is an option of ``brainbulge hemidisk`` unless it is one of the
    deliberately internal ones; each option given reaches the case."""
    flags = set(re.findall(r"\[(--[a-z-]+)", _help(capsys)))
    names = {f.name for f in dataclasses.fields(HemidiskCase)}
    expected = {"--" + n.replace("_", "-") for n in names - INTERNAL - {"R"}} | {"--radius"}
    assert expected <= flags
    assert flags - expected <= {"--out", "--overwrite", "--no-rezone"}
    assert INTERNAL <= names and not {"--" + n.replace("_", "-") for n in INTERNAL} & flags


def test_options_given_reach_the_case_and_the_others_are_its_defaults() -> None:
    from brainbulge.cli import build_parser
    from brainbulge.cli.hemidisk import config_from_args

    def case(*argv: str) -> HemidiskCase:
        return HemidiskCase(**config_from_args(build_parser().parse_args(["hemidisk", *argv])))

    assert case() == HemidiskCase()
    given = case("--radius", "2", "--mesh-size", "0.1", "--steps", "3", "--no-rezone",
                 "--contact", "noslip", "--disk", "0", "0.5", "0.1")
    assert (given.R, given.mesh_size, given.steps, given.rezone, given.contact) == (
        2.0, 0.1, 3, False, "noslip")
    assert given.disk == [0.0, 0.5, 0.1] and given.swelling == DISK_SWELLING


def test_the_run_file_tables_hold_the_case_fields() -> None:
    """``[solver]`` holds how the case is solved, ``[case]`` the rest (all other fields)."""
    from brainbulge.model.problem import case_tables

    tables = case_tables(HemidiskCase(corner_mesh_size=0.01, rim_mesh_size=0.005), SOLVER_FIELDS)
    assert set(tables["solver"]) == {"mesh_size", "corner_mesh_size", "rim_mesh_size", "steps",
                                     "element", "full_domain", "rezone"}
    assert set(tables["case"]) == {f.name for f in dataclasses.fields(HemidiskCase)} - set(
        tables["solver"]) - {"disk"}  # None: left out
    assert tables["case"]["swelling"] == SECTOR_SWELLING  # the resolved default is recorded


@pytest.mark.parametrize("value", [3.0, 0.0, -2.0])
def test_a_swelling_out_of_range_is_one_message_every_way(value, tmp_path, capsys) -> None:
    """The command line, a run file and the Python API give the same one line."""
    with pytest.raises(InputError) as err:
        HemidiskCase(swelling=value)
    api = str(err.value)
    assert "\n" not in api and api.startswith(f"swelling Js = {value!r} must be a number in "
                                              f"[{SWELLING_RANGE[0]:g}, {SWELLING_RANGE[1]:g}]")
    assert main(["hemidisk", "--swelling", str(value), "--out", str(tmp_path / "a")]) == 2
    cli = capsys.readouterr().err.strip().splitlines()
    run = tmp_path / "run.toml"
    run.write_text(f"command = 'hemidisk'\n[case]\nswelling = {value}\n")
    assert main(["run", str(run), "--out", str(tmp_path / "b")]) == 2
    toml = capsys.readouterr().err.strip().splitlines()
    assert cli == toml == [f"error: {api}"]
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
