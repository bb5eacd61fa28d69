"""The Python API: one call per job, the command line's code path, a result object.

``brainbulge.hemidisk(...)``, ``brainbulge.brain(...)`` and ``brainbulge.study(name, ...)``
take the options of ``brainbulge hemidisk``, ``brain`` and ``study`` as keyword arguments
(the case dataclasses' field names: ``alpha``, ``beta``, ``mesh_size``, ``tets``, ``flap``,
...; each checked by the same rules, an unknown name refused with the nearest valid one)
and run exactly what the command runs: the runtime tuning, the checks of every input, the
output folder (claimed, recorded in ``run.toml``/``run.json``/``status.json``, a temporary
folder when ``out`` is not given), the solve and every output file. They return a
:class:`Result`::

    import brainbulge
    r = brainbulge.hemidisk(alpha=80, beta=60)
    r.summary["max_displacement"]

A run that stops before full load returns its partial result with ``converged`` false (the
command would exit 4); bad input raises :class:`~brainbulge.errors.InputError` (exit 2).
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from brainbulge.errors import ConvergenceError, InputError, StudyIncomplete

#: the figure :meth:`Result.plot` shows for each command
FIGURES = {"hemidisk": "fields.png", "brain": "sections.png", "study": "comparison.png"}


@dataclass
class Result:
    """A finished job: ``summary`` (``summary.json``: the keys of docs/outputs.md; for a
    study, scenario name -> its summary), ``converged`` (every load step reached),
    ``folder`` (the run's files: the ``out`` given, or a temporary folder), ``command``."""

    command: str
    folder: Path
    summary: dict[str, Any]
    converged: bool
    _fields: dict[str, Any] | None = field(default=None, repr=False)

    @property
    def fields(self) -> dict[str, Any]:
        """The fields at the mesh vertices (``fields.npz``): ``points`` (n, dim) reference
        coordinates [mm or R], ``cells`` (simplices), and every output of docs/model.md
        section 3 by name (``u``, ``u_magnitude``, ``max_principal_strain``, ``lambda_n``,
        ``lambda_t``, ``J``, ``Je``, ``Js``, ``pressure``, ...), NumPy arrays. A study has
        none (its scenarios' folders hold them)."""
        if self._fields is None:
            path = self.folder / "fields.npz"
            if not path.is_file():
                raise InputError(f"{self.folder} holds no fields.npz (a {self.command} "
                                 "writes none); open a scenario's folder instead")
            from brainbulge.results.export.writers import load_vertex_fields

            vf = load_vertex_fields(path)
            self._fields = {"points": vf.points, "cells": vf.cells, **vf.point_data}
        return self._fields

    def save(self, folder: str | Path) -> Path:
        """Copy the run's files into ``folder`` (created; refused if it exists and is not
        empty: nothing is overwritten); returns it."""
        folder = Path(folder)
        if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
            raise InputError(f"{folder} exists and is not empty: give a new folder")
        shutil.copytree(self.folder, folder, dirs_exist_ok=True,
                        ignore=shutil.ignore_patterns(".*"))  # not the folder's lock
        return folder

    def plot(self):
        """The run's figure (``fields.png`` of a hemidisk, ``sections.png`` of a brain,
        ``comparison.png`` of a study) as a Matplotlib figure."""
        import matplotlib.image as mpimg
        import matplotlib.pyplot as plt

        image = mpimg.imread(self.folder / FIGURES[self.command])
        fig, ax = plt.subplots(figsize=(image.shape[1] / 100, image.shape[0] / 100), dpi=100)
        ax.imshow(image)
        ax.set_axis_off()
        fig.subplots_adjust(0, 0, 1, 1)
        return fig


def hemidisk(out: str | Path | None = None, overwrite: bool = False, **options: Any) -> Result:
    """A 2D hemidisk case (``brainbulge hemidisk``): ``options`` as
    :class:`~brainbulge.model.hemidisk.HemidiskCase`'s fields."""
    from brainbulge.cli.checks import hemidisk_case
    from brainbulge.cli.hemidisk import run_case

    case = hemidisk_case(_case_table("hemidisk", options))
    return _run("hemidisk", lambda args: run_case(args, case), out, overwrite)


def brain(out: str | Path | None = None, overwrite: bool = False, **options: Any) -> Result:
    """A 3D craniectomy scenario (``brainbulge brain``): ``options`` as
    :class:`~brainbulge.model.brain_case.CraniectomyCase`'s fields (``tets``, ``mesh``,
    ``labels``, ``label_map``, ``flap``, ``swell``, ...). Its folder holds ``maps/``, the
    NIfTI maps on the label image's grid."""
    from brainbulge.cli.brain import run_case
    from brainbulge.cli.checks import brain_case

    case = brain_case(_case_table("brain", options))
    return _run("brain", lambda args: run_case(args, case), out, overwrite)


def study(name: str, out: str | Path | None = None, overwrite: bool = False,
          **options: Any) -> Result:
    """A study (``brainbulge study NAME``: ``hemidisk-sector``, ``hemidisk-disk``,
    ``craniectomy``) with the command's options (``steps``, ``alphas``, ``betas``,
    ``mesh_size``, ``tets``, ``scheduler``, ``workers``, ...); ``summary``: scenario name ->
    its summary."""
    from brainbulge.cli import study as study_cli
    from brainbulge.studies.suites import STUDIES

    if name not in STUDIES:
        raise InputError(f"study {name!r} unknown: choose one of {', '.join(STUDIES)}")
    allowed = {*study_cli.HEMIDISK_OPTIONS, *study_cli.CRANIECTOMY_OPTIONS, "steps", "alphas",
               "betas", "scheduler", "workers"}
    unknown = sorted(set(options) - allowed)
    if unknown:
        raise InputError(f"unknown study option(s) {', '.join(unknown)}; valid: "
                         f"{', '.join(sorted(allowed))}")
    given = {"alphas": None, "betas": None, "scheduler": None, "workers": None, **options}

    def run(args: argparse.Namespace) -> int:
        for key, value in given.items():
            setattr(args, key, value)
        args.name = name
        return study_cli.run_command(args)

    return _run("study", run, out, overwrite)


def _case_table(command: str, options: dict[str, Any]) -> dict[str, Any]:
    """``options`` checked as a run file's ``[case]`` table of ``command`` (unknown names
    refused with the nearest valid one)."""
    from brainbulge.cli.run import schema
    from brainbulge.results.records.config_file import check_keys

    config = {"command": command, "case": dict(options)}
    check_keys(config, schema(command, config), f"brainbulge.{command}()")
    return dict(options)


def _run(command: str, func, out: str | Path | None, overwrite: bool) -> Result:
    """Run ``func(args)`` as the command line runs a parsed command
    (:func:`brainbulge.cli.run_parsed`), into ``out`` or a new temporary folder."""
    from brainbulge.cli import run_parsed

    folder = (Path(out) if out is not None else
              Path(tempfile.mkdtemp(prefix=f"brainbulge-{command}-")) / "run")
    args = argparse.Namespace(out=folder, overwrite=overwrite, verbose=0, debug=True,
                              func=func)
    converged = True
    try:
        run_parsed(args)
    except (ConvergenceError, StudyIncomplete):
        converged = False
    return Result(command, folder, _summary(command, folder), converged)


def _summary(command: str, folder: Path) -> dict[str, Any]:
    if command != "study":
        return json.loads((folder / "summary.json").read_text())
    study = json.loads((folder / "study.json").read_text())
    names = [sc["name"] for sc in study.get("scenarios", [])]
    return {name: json.loads((folder / name / "summary.json").read_text())
            for name in names if (folder / name / "summary.json").is_file()}
