"""The mechanism benchmark: its variants name fields of the options tree, a variant reaches
every options object built in the run, and its table says which runs changed (no solve
here)."""

import dataclasses

import pytest

import bench_mechanisms as bm
from brainbulge.solver import SolverOptions


@pytest.mark.parametrize("variant", sorted(bm.VARIANTS))
def test_each_variant_sets_fields_of_the_options_tree(variant) -> None:
    for key in bm.VARIANTS[variant]:
        group, name = key.split(".")
        assert name in {f.name for f in dataclasses.fields(getattr(SolverOptions(), group))}


def test_a_variant_reaches_every_options_object_of_the_run(monkeypatch) -> None:
    from brainbulge.solver import options

    monkeypatch.setattr(options.SolverOptions, "__init__", options.SolverOptions.__init__)
    bm.override_options({"ramp.grow": 1.0, "newton.hotspot_relaxation": False})
    opt = SolverOptions(steps=2)
    assert (opt.ramp.grow, opt.ramp.steps, opt.newton.hotspot_relaxation) == (1.0, 2, False)
    again = dataclasses.replace(opt, tolerance=1e-8)  # a solver's own copy keeps it too
    assert again.ramp.grow == 1.0 and again.newton.tolerance == 1e-8


def test_the_table_names_the_runs_whose_newton_count_changed(capsys) -> None:
    rows = {"a": {"full": True, "load": 1.0, "newton": 10, "gmres": 0},
            "b": {"full": True, "load": 1.0, "newton": 7, "gmres": 0}}
    slower = {"a": {"full": True, "load": 1.0, "newton": 12, "gmres": 0},
              "b": {"full": False, "load": 0.5, "newton": 7, "gmres": 0}}
    bm.table("sector", {"baseline": {"rows": rows, "wall": 1.0},
                        "no-grow": {"rows": slower, "wall": 2.0}})
    out = capsys.readouterr().out
    assert "| baseline | 2 of 2 | 17 | 0 | - | 1 |" in out
    assert "| no-grow | 1 of 2 | 19 | 0 | a 10 -> 12; b 7 -> 7 (load 0.500) | 2 |" in out
