"""Every result file is written atomically: a full disk mid-write leaves the previous file
(or none), never a 0-byte or truncated one, and no temporary file behind.

The full disk is a file-size limit (``RLIMIT_FSIZE``): every write past a few bytes fails
with EFBIG, as a write to a full disk fails with ENOSPC, whatever library does the writing.
"""

from __future__ import annotations

import os
import resource
import signal
import stat
from contextlib import contextmanager
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest

from brainbulge.results.export.writers import VertexFields, write_vtu
from brainbulge.results.present import figures
from brainbulge.results.records.output_folder import folder_files
from brainbulge.results.records.run_record import atomic_write_text
from brainbulge.studies.hemidisk import load_vertex_fields, save_vertex_fields, write_study_table

OLD = b"results of an earlier run"


@contextmanager
def full_disk(limit: int = 8):
    """Writes beyond ``limit`` bytes of any file fail with OSError (EFBIG)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    old_handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, old_handler)


def fields() -> VertexFields:
    points = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    cells = np.array([[0, 1, 2], [1, 3, 2]])
    u = np.array([[0.0, 0.0], [0.1, 0.0], [0.0, 0.1], [0.1, 0.1]])
    return VertexFields(points, cells, np.zeros(2, int), ["brain"], {"u": u},
                        {"J": np.array([1.1, 1.2])})


def write_png(path: Path) -> None:
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    figures._save(fig, path)


WRITERS = {
    "fields.vtu": lambda p: write_vtu(p, fields()),
    "fields.npz": lambda p: save_vertex_fields(p, fields()),
    "fields.png": write_png,
    "table.csv": lambda p: write_study_table(
        [{"complete": True, "max_displacement": 0.1}] * 2,
        [{"name": "a", "alpha": 80, "beta": 30}, {"name": "b", "alpha": 60, "beta": 30}], p),
    "report.md": lambda p: atomic_write_text(p, "# Report\n" + "line\n" * 100),
}


@pytest.mark.parametrize("name", WRITERS)
def test_a_full_disk_leaves_the_previous_file_and_no_temporary(tmp_path, name) -> None:
    path = tmp_path / name
    path.write_bytes(OLD)
    with full_disk(), pytest.raises(OSError):
        WRITERS[name](path)
    assert path.read_bytes() == OLD
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


@pytest.mark.parametrize("name", WRITERS)
def test_a_full_disk_leaves_no_empty_or_partial_new_file(tmp_path, name) -> None:
    with full_disk(), pytest.raises(OSError):
        WRITERS[name](tmp_path / name)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", WRITERS)
def test_results_are_complete_and_readable_as_the_umask_allows(tmp_path, name) -> None:
    old = os.umask(0o027)
    try:
        WRITERS[name](tmp_path / name)
    finally:
        os.umask(old)
    path = tmp_path / name
    assert stat.S_IMODE(path.stat().st_mode) == 0o640
    assert sorted(folder_files(tmp_path)) == [name]  # no temporary left
    if name == "fields.npz":
        np.testing.assert_array_equal(load_vertex_fields(path).point_data["u"],
                                      fields().point_data["u"])
