"""One declaration per ``summary.json`` key (``results/measures/schema.py``): a real run writes
exactly the declared keys of its case, and the reports and the printout name declared keys.
(The 3D run's keys are checked on the solved toy brain in ``test_brain_outputs.py``; the
docs tables against the declarations in ``tests/test_docs.py``.)"""

from __future__ import annotations

import json
import re

import pytest

from brainbulge.cli import main
from brainbulge.results.measures import schema
from brainbulge.results.measures.extreme_sites import SITE_KEYS
from brainbulge.results.present.craniectomy_report import COMPARISON
from brainbulge.results.present.report import BRAIN_REPORT_KEYS, REPORT_KEYS
from output_files import written_fields


def test_each_key_is_declared_once_with_unit_and_meaning() -> None:
    names = [n for k in schema.KEYS for n in k.names]
    assert len(names) == len(set(names)) == len(schema.BY_NAME)
    for k in schema.KEYS:
        assert k.meaning and k.cases <= schema.BOTH and len(k.labels) <= len(k.names)
        assert not k.instead or len(k.instead) == len(k.names)
    # the families of the stretches, the strain and the shear stress: 6 extremes, 6 raw,
    # 4 argmax, 2 percentiles per extreme, 4 peaks
    assert len(schema.percentiles()) == 12 and len(schema.raws(schema.CSF)) == 6
    assert len(schema.argmaxes()) == len(schema.peaks()) == 4
    # a deprecated key names a declared key to use instead
    for old, new in {**schema.deprecated_aliases(), **schema.deprecated_derived()}.items():
        assert new in schema.BY_NAME and old in schema.BY_NAME


def test_the_reports_name_declared_keys() -> None:
    assert set(REPORT_KEYS) <= schema.declared(schema.HEMIDISK)
    brain = schema.declared(schema.BRAIN)
    assert set(BRAIN_REPORT_KEYS) | set(COMPARISON) | {k for k, _, _ in SITE_KEYS} <= brain
    assert COMPARISON["bulge_volume_ml"] == ("bulge volume", "ml")
    assert COMPARISON["max_displacement"] == ("max |u|", "mm")  # the brain's length unit


def test_check_sees_an_undeclared_and_a_missing_key() -> None:
    written = dict.fromkeys(schema.declared(schema.HEMIDISK, always=True))
    assert schema.check(written, schema.HEMIDISK) == ([], [])
    del written["max_skull_crossing"]
    written["midline_shift_mm"] = 0.0  # the brain's
    assert schema.check(written, schema.HEMIDISK) == (["midline_shift_mm"],
                                                      ["max_skull_crossing"])


@pytest.fixture(scope="module")
def hemidisk_run(tmp_path_factory) -> tuple[dict, str]:
    """A coarse sliding hemidisk through the command line: its summary and printout."""
    import contextlib
    import io

    out = tmp_path_factory.mktemp("hemidisk") / "run"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["hemidisk", "--mesh-size", "0.2", "--steps", "2", "--out", str(out)]) == 0
    return json.loads((out / "summary.json").read_text()), printed.getvalue(), out


def test_a_hemidisk_run_writes_the_declared_keys(hemidisk_run) -> None:
    summary, _, _ = hemidisk_run
    undeclared, missing = schema.check(summary, schema.HEMIDISK)
    assert not undeclared, f"keys written but not declared in the schema: {undeclared}"
    assert not missing, f"keys declared for every hemidisk run but not written: {missing}"
    assert "max_contact_pressure" in summary  # sliding: with contact


def test_the_printout_gives_declared_keys_with_their_units(hemidisk_run) -> None:
    summary, printed, _ = hemidisk_run
    line = printed.strip().splitlines()[-1]
    got = {k.strip(): v for k, v in re.findall(r"([^,=]+) = ([^ ,]+)", line)}
    assert list(got) == ["max |u|", "max lambda_n", "min lambda_n", "max lambda_t",
                         "min lambda_t", "penetration", "skull crossing"]
    assert float(got["skull crossing"]) == pytest.approx(summary["max_skull_crossing"],
                                                         rel=1e-2, abs=1e-12)
    assert float(got["max |u|"]) == pytest.approx(summary["max_displacement"], rel=1e-3)
    assert float(got["min lambda_n"]) == pytest.approx(summary["min_radial_stretch"],
                                                       abs=1e-4)
    assert float(got["max lambda_t"]) == pytest.approx(summary["max_tangential_stretch"],
                                                       abs=1e-4)
    assert f"max |u| = {summary['max_displacement']:.4g} R" in line  # the hemidisk's unit


def test_a_hemidisk_run_writes_the_declared_fields(hemidisk_run) -> None:
    """``fields.npz`` and ``fields.vtu`` have the declared fields (the contact fields as
    point data only; ``region`` as cell data)."""
    in_npz, point, cell = written_fields(hemidisk_run[2])
    assert in_npz == point == schema.field_names()
    assert cell == schema.field_names(cell=True)
