"""The 3D case owns its options and its run builds one skull.

``brainbulge brain``, ``brainbulge study craniectomy``, ``brainbulge plan`` and the run files
take their options, defaults, ranges and help from :class:`CraniectomyCase`; a flap request
becomes a flap by one rule; a run builds its rigid skull once and passes it on, and the
options reach what uses them in a few calls."""

from __future__ import annotations

import dataclasses
import re
import traceback
from pathlib import Path

import pytest

from brainbulge.cli import build_parser, main
from brainbulge.errors import InputError
from brainbulge.model.brain_case import SWELLING_RANGE, TETS_RANGE, CraniectomyCase

#: fields set through a run file or the Python API only, deliberately not options
INTERNAL = {"compile", "name", "extra"}
#: the most calls from the command (``run_command``) to where an option is used
MAX_HOPS = 8


def _help(capsys, *command: str) -> str:
    with pytest.raises(SystemExit):
        main([*command, "--help"])
    return " ".join(capsys.readouterr().out.split())


def test_the_help_shows_the_case_defaults_and_ranges(capsys) -> None:
    text = _help(capsys, "brain")
    lo, hi = SWELLING_RANGE
    assert f"default 1.1; range [{lo:g}, {hi:g}]" in text
    assert f"(default 30000; range [{TETS_RANGE[0]}, {TETS_RANGE[1]}])" in text
    assert "[mm] (default 8; range [0.1, 10])" in text  # --skull-edge-radius
    for f in dataclasses.fields(CraniectomyCase):
        if f.name in INTERNAL or f.default is None or isinstance(f.default, bool):
            continue
        shown = f"{f.default:g}" if isinstance(f.default, float | int) else f.default
        assert f"default {shown}" in text, f.name


def test_every_field_is_an_option_or_internal(capsys) -> None:
    flags = set(re.findall(r"(?:\[|\|) ?(--[a-z-]+)", _help(capsys, "brain")))
    expected = {f.metadata["flag"] or "--" + f.name.replace("_", "-")
                for f in dataclasses.fields(CraniectomyCase) if f.name not in INTERNAL}
    assert expected <= flags
    assert flags - expected <= {"--out", "--overwrite"}


def test_options_given_reach_the_case_and_the_others_are_its_defaults() -> None:
    from brainbulge.cli.brain import config_from_args

    def case(*argv: str) -> CraniectomyCase:
        return CraniectomyCase(**config_from_args(build_parser().parse_args(["brain", *argv])))

    assert case() == CraniectomyCase()
    given = case("--swelling", "1.05", "--skull-edge-radius", "6", "--tets", "1e5",
                 "--flap", "custom", "--flap-centre", "-60", "10", "40")
    assert (given.swelling, given.edge_radius_mm, given.tets, given.flap_centre_mm) == (
        1.05, 6.0, 100_000, (-60.0, 10.0, 40.0))


def test_the_study_takes_the_case_defaults() -> None:
    from brainbulge.cli.study import scenarios_for

    args = build_parser().parse_args(["study", "craniectomy"])
    sc = scenarios_for("craniectomy", args)[0]
    default = CraniectomyCase()
    assert (sc["tets"], sc["swelling"], sc["steps"], sc["fix"]) == (
        default.tets, default.swelling, default.steps, default.fix)
    args = build_parser().parse_args(["study", "craniectomy", "--steps", "2"])
    assert scenarios_for("craniectomy", args)[0]["steps"] == 2


@pytest.mark.parametrize("config, message", [
    ({"swelling": 2.5}, "swelling Js = 2.5 must be a number in [0.5, 2]"),
    ({"edge_radius_mm": 0.0}, "edge radius = 0.0 must be a number in [0.1, 10] mm"),
    ({"tolerance": 0.0}, "tolerance = 0.0"),
    ({"refine": 1.5}, "refine = 1.5 must be a whole number"),
    ({"flap_diameter_mm": 5.0}, "flap diameter = 5.0 must be a number in [10, 250] mm"),
])
def test_the_case_checks_its_ranges(config, message) -> None:
    """One message whichever way the case is given: the Python API as the command line."""
    with pytest.raises(InputError) as err:
        CraniectomyCase(**config)
    assert message in str(err.value)


def _consumers(monkeypatch) -> dict[str, list[list[str]]]:
    """Patch where ``--skull-edge-radius`` and ``--swelling`` are used (the rigid skull, the
    problem) to record the calls from the command to them."""
    from brainbulge.geometry.brain.skull import RigidSkull
    from brainbulge.model.problem import Problem

    seen: dict[str, list[list[str]]] = {"skull": [], "problem": []}

    def chain() -> list[str]:
        names = [f.name for f in traceback.extract_stack()[:-2]]
        return names[max(i for i, n in enumerate(names) if n == "run_command"):]

    def spy(key: str, init):
        def wrapped(self, *a, **k):
            seen[key].append(chain())
            init(self, *a, **k)
        return wrapped

    monkeypatch.setattr(RigidSkull, "__init__", spy("skull", RigidSkull.__init__))
    monkeypatch.setattr(Problem, "__init__", spy("problem", Problem.__init__))
    return seen


def _check_run(seen: dict[str, list[list[str]]]) -> None:
    assert len(seen["skull"]) == 1, seen["skull"]  # made once, passed on
    assert len(seen["problem"]) == 1
    for calls in (*seen["skull"], *seen["problem"]):
        assert len(calls) <= MAX_HOPS, calls  # run_command > ... > the user (its calls)


def test_a_brain_run_builds_its_skull_once(tmp_path: Path, monkeypatch) -> None:
    """The toy brain (docs/own-mri.md): one rigid skull for the problem, the summary, the
    free flap area and the depths of the midline measure."""
    from toy_brain import toy_mesh

    toy_mesh(tmp_path / "mesh")
    seen = _consumers(monkeypatch)
    assert main(["brain", "--mesh", str(tmp_path / "mesh" / "brain.npz"), "--steps", "2",
                 "--out", str(tmp_path / "run")]) == 0
    _check_run(seen)


@pytest.mark.slow
def test_a_brain_run_of_the_demo_size_builds_its_skull_once(tmp_path: Path,
                                                             monkeypatch) -> None:
    """The demo's 3D size (30,000 tets of the template, built here)."""
    from brainbulge.studies.suites import demo_plan

    size = demo_plan(False)["brain"]
    seen = _consumers(monkeypatch)
    assert main(["brain", "--tets", str(size["tets"]), "--steps", str(size["steps"]),
                 "--out", str(tmp_path / "run")]) == 0
    _check_run(seen)


def test_one_rule_opens_a_custom_flap_on_a_built_and_a_loaded_mesh(tmp_path: Path) -> None:
    """A custom flap is the fitting rule's whether the mesh is built with the flap's centre
    or loaded and the flap opened on it: the same faces, clipped at the superior band."""
    from brainbulge.geometry.brain import build_brain_mesh, load_tissue_image
    from brainbulge.geometry.brain.flap_fit import fit_flap
    from brainbulge.model.brain import brain_mesh_for
    from toy_brain import toy_labels, toy_mesh

    toy_mesh(tmp_path / "mesh")
    request = {"flap": "custom", "flap_centre_mm": (-40.0, 20.0, 60.0), "flap_diameter_mm": 90.0}
    loaded = brain_mesh_for(CraniectomyCase(mesh=str(tmp_path / "mesh" / "brain.npz"),
                                            **request))
    labels = str(toy_labels(tmp_path / "seg.nii.gz"))
    built = brain_mesh_for(CraniectomyCase(labels=labels, tets=1000, **request))
    image = load_tissue_image(labels, "synthseg")
    plain = build_brain_mesh(image, target_tets=1000)
    case = CraniectomyCase(mesh=str(tmp_path / "mesh" / "brain.npz"), **request)
    for bm, reference in ((loaded, loaded), (built, plain)):
        fit = fit_flap(reference, request["flap_centre_mm"], 90.0, case.superior_band())
        assert fit.fits and fit.clipped_cm2 > 0  # reaches the band: clipped there
        assert (bm.flap_faces["custom"] == fit.mask).all()
