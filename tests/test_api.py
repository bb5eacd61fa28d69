"""The one-call Python API (brainbulge/api.py): the command line's code path and result.

- ``brainbulge.hemidisk(...)`` gives the summary ``brainbulge hemidisk`` writes for the same
  case (every key but the times), its fields at the vertices and its figure;
- its folder is the command's (run record, status); ``save`` copies it and refuses to
  write into a folder that holds files;
- unknown and out-of-range options are refused with the command's messages, before any
  folder is made;
- importing ``brainbulge`` loads neither the API nor NGSolve.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import brainbulge
from brainbulge.cli import main as cli_main
from brainbulge.errors import InputError

#: a coarse hemidisk (seconds)
CASE = {"alpha": 80.0, "beta": 60.0, "mesh_size": 0.15}
#: summary keys that differ between two runs of one case: the times
def is_time(key: str) -> bool:
    return "time" in key


@pytest.fixture(scope="module")
def api_result(tmp_path_factory):
    return brainbulge.hemidisk(**CASE)


def test_the_api_summary_is_the_command_lines(api_result, tmp_path) -> None:
    out = tmp_path / "cli"
    assert cli_main(["hemidisk", "--alpha", "80", "--beta", "60", "--mesh-size", "0.15",
                     "--out", str(out)]) == 0
    cli = json.loads((out / "summary.json").read_text())
    api = api_result.summary
    assert api_result.converged and api["converged"]
    assert set(api) == set(cli)
    for key in (k for k in cli if not is_time(k)):  # to rounding: PARDISO's threads
        assert api[key] == (pytest.approx(cli[key], rel=1e-12, abs=1e-15)
                            if isinstance(cli[key], float) else cli[key]), key
    assert (api_result.folder / "run.toml").read_text() == (out / "run.toml").read_text()
    status = json.loads((api_result.folder / "status.json").read_text())
    assert status["status"] == "complete"


def test_fields_and_figure(api_result) -> None:
    f = api_result.fields
    assert f["points"].shape[1] == 2 and f["u"].shape == f["points"].shape
    np.testing.assert_allclose(f["u_magnitude"], np.linalg.norm(f["u"], axis=1))
    # the vertices' largest |u| against the summary's (over the integration points too)
    assert np.max(f["u_magnitude"]) == pytest.approx(api_result.summary["max_displacement"],
                                                     rel=0.02)
    fig = api_result.plot()
    assert fig.axes[0].images  # the run's fields.png


def test_save_copies_the_folder_and_refuses_a_full_one(api_result, tmp_path) -> None:
    saved = api_result.save(tmp_path / "kept")
    assert json.loads((saved / "summary.json").read_text()) == api_result.summary
    with pytest.raises(InputError, match="not empty"):
        api_result.save(saved)


@pytest.mark.parametrize(("options", "message"), [
    ({"alpah": 80.0}, "alpha"),  # a typo: the nearest valid name
    ({"mesh_size": 5.0}, "mesh size"),
])
def test_bad_options_are_refused_before_any_folder(options, message, tmp_path) -> None:
    with pytest.raises(InputError, match=message):
        brainbulge.hemidisk(out=tmp_path / "never", **options)
    assert not (tmp_path / "never").exists()


def test_importing_brainbulge_loads_neither_the_api_nor_ngsolve() -> None:
    code = ("import sys, brainbulge; print(sorted(m for m in ('brainbulge.api', 'ngsolve') "
            "if m in sys.modules)); print(callable(brainbulge.brain))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == ["[]", "True"]


@pytest.mark.slow
def test_the_brain_in_one_call(tmp_path) -> None:
    """``brainbulge.brain`` on a mesh file: the command's folder with its NIfTI maps; in one
    load step the toy stops short of full load (a few minutes of halved steps), and the
    result says so, its files kept, as the command's exit 4 does."""
    from toy_brain import toy_mesh

    toy_mesh(tmp_path / "mesh")
    r = brainbulge.brain(mesh=str(tmp_path / "mesh" / "brain.npz"), flap="custom", steps=1,
                         out=tmp_path / "run")
    assert r.converged == r.summary["converged"] and r.folder == tmp_path / "run"
    status = json.loads((r.folder / "status.json").read_text())["status"]
    assert status == ("complete" if r.converged else "incomplete")
    assert {"midline_shift_mm", "bulge_volume_ml"} <= set(r.summary)
    assert (r.folder / "maps" / "max_principal_strain.nii.gz").is_file()
    assert r.fields["points"].shape[1] == 3
    with pytest.raises(InputError, match="tets"):  # the command's rule: one mesh source
        brainbulge.brain(mesh=str(tmp_path / "mesh" / "brain.npz"), tets=5000)
