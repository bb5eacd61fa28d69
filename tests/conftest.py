"""Shared fixtures: small meshes that make tests fast but able to fail."""

from __future__ import annotations

import os

from brainbulge.runtime import configure
from brainbulge.studies.runner import THREAD_VARIABLES

#: pytest-xdist runs one worker per core (pyproject.toml); each then computes on one thread,
#: as do the processes it starts: threads of several workers competing for the same cores
#: spin-wait and made the suite slower than one process on all cores
ONE_THREAD_PER_WORKER = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) > 1
if ONE_THREAD_PER_WORKER:
    for key in THREAD_VARIABLES:
        os.environ.setdefault(key, "1")

configure()  # the tuning of a brainbulge run (threads, MKL, heap, compiler cache), before NGSolve

import ngsolve as ngs  # noqa: E402
import pytest  # noqa: E402
from netgen.occ import Box, OCCGeometry, Rectangle, X, Y, Z  # noqa: E402


def unit_box_mesh(dim: int, h: float = 0.35) -> ngs.Mesh:
    """Unit square/cube, one region ``tissue``; boundaries ``xmin ymin zmin xmax``, rest
    ``free``."""
    if dim == 3:
        shape = Box((0, 0, 0), (1, 1, 1))
        shape.faces.name = "free"
        shape.faces.Min(X).name = "xmin"
        shape.faces.Min(Y).name = "ymin"
        shape.faces.Min(Z).name = "zmin"
        shape.faces.Max(X).name = "xmax"
        shape.mat("tissue")
    else:
        shape = Rectangle(1, 1).Face()
        shape.edges.name = "free"
        shape.edges.Min(X).name = "xmin"
        shape.edges.Min(Y).name = "ymin"
        shape.edges.Max(X).name = "xmax"
        shape.faces.name = "tissue"
    return ngs.Mesh(OCCGeometry(shape, dim=dim).GenerateMesh(maxh=h))


@pytest.fixture(scope="session")
def box2d() -> ngs.Mesh:
    return unit_box_mesh(2)


@pytest.fixture(scope="session")
def box3d() -> ngs.Mesh:
    return unit_box_mesh(3)


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist reads the group marks
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Under pytest-xdist's ``--dist loadgroup`` (pyproject.toml) a test module runs on one
    worker, so its module-scoped fixtures are built once, and the modules that read the quick
    demo share one worker, so its ~60 s run happens once."""
    for item in items:
        group = "quick_demo" if "quick_demo" in item.fixturenames else item.path.stem
        item.add_marker(pytest.mark.xdist_group(group))


@pytest.fixture(scope="session")
def quick_demo(tmp_path_factory):
    """The main job, ``brainbulge demo --quick``, run once: (exit code, output folder).

    Its ``brain/mesh/brain.npz`` is the ICBM152 template at 30k target tets, the default
    brain the template tests check."""
    from brainbulge.cli import main

    out = tmp_path_factory.mktemp("quick-demo") / "demo"
    return main(["demo", "--quick", "--out", str(out)]), out


@pytest.fixture(scope="module")
def swollen():
    """Form, Newton solver and the tangent/right-hand side of a Newton step at a swollen
    state of the soft inclusion (:func:`inclusion_cases.swollen_state`), once per module."""
    from inclusion_cases import swollen_state

    return swollen_state()


@pytest.fixture
def saved_figures(monkeypatch) -> list:
    """The matplotlib figures written in a test (through ``Figure.savefig``), in order, for
    a look at what a PNG shows (its axes, labels, marks) without reading pixels."""
    from matplotlib.figure import Figure

    saved = []
    savefig = Figure.savefig

    def keep(fig: Figure, *args, **kwargs) -> None:
        saved.append(fig)
        return savefig(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    return saved
