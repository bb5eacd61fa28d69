"""``report.html`` and ``view.html``: colour ranges from the data, decimation, the Markdown
page (figures inline, sortable tables, 3D views where the report asks for them), and the
demo's page in a real headless Chromium, offline: it loads without a JavaScript error,
requests nothing from the network, every 3D view draws, and switching the field or cutting the
brain open changes the picture."""

from __future__ import annotations

import base64
import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from brainbulge.results.present.html_report import (
    markdown_html,
    views_marker,
    write_missing_html,
    write_report_html,
)
from brainbulge.results.present.views3d import Cut, Surface, shared_ranges
from brainbulge.results.present.webview import MAX_VIEW_FACES, decimate
from headless_browser import chromium_binary


def sphere(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``n`` random points on a sphere of radius 50 mm and their outward hull triangles."""
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    p = 50 * p / np.linalg.norm(p, axis=1, keepdims=True)
    hull = ConvexHull(p)
    faces = hull.simplices.copy()
    n_out = np.einsum("ij,ij->i", np.cross(p[faces[:, 1]] - p[faces[:, 0]],
                                           p[faces[:, 2]] - p[faces[:, 0]]), p[faces[:, 0]])
    faces[n_out < 0] = faces[n_out < 0][:, [0, 2, 1]]
    return p, faces


def toy_surface(scale: float = 1.0, off_surface: int = 0) -> Surface:
    """A sphere bulging on +x: |u| = 5 scale mm at the pole, stretches about 1; plus
    ``off_surface`` points inside (in no face) whose fields are 0, as the CSF's nodes of a
    brain's ``surface.npz``."""
    p, faces = sphere(400)
    bump = np.clip(p[:, 0] / 50, 0, None) ** 2
    u = 5 * scale * bump[:, None] * p / 50
    fields = {"u_magnitude": np.linalg.norm(u, axis=1), "max_principal_strain": 0.1 * bump,
              "lambda_n": 1 + 0.2 * scale * bump, "lambda_t": 1 - 0.1 * scale * bump,
              "Je": 1 + 0.01 * bump}
    if off_surface:
        p = np.vstack([p, np.zeros((off_surface, 3))])
        u = np.vstack([u, np.zeros((off_surface, 3))])
        fields = {k: np.concatenate([v, np.zeros(off_surface)]) for k, v in fields.items()}
    flap = p[faces].mean(axis=1)[:, 0] > 35
    cut_pts = np.array([[0, 0, 0], [40, 0, 0], [0, 40, 0.0]])
    cut = Cut(cut_pts, np.array([[0, 1, 2]]), np.zeros((3, 3)),
              {k: np.ones(3) for k in fields})
    return Surface(p, faces, u, fields, flap, np.array([1.0, 0, 0]), cuts={"transverse": cut},
                   cut_centre=np.zeros(3))


def scenes(page: str) -> list[dict]:
    return [json.loads(m) for m in re.findall(
        r'<script type="application/json" id="[^"]+">(.*?)</script>', page, re.S)]


def decoded(layer: dict, key: str, dtype=np.float32) -> np.ndarray:
    return np.frombuffer(base64.b64decode(layer[key]), dtype=dtype)


# --- colour ranges ---------------------------------------------------------------------
def test_stretch_ranges_centre_on_one_from_the_surface_values_alone() -> None:
    """The surfaces PNGs' stretch panels were almost white: the 0 of the points off the
    surface (CSF nodes) set their range to 0-2. Now only surface vertices count, and the
    range is symmetric about 1, reaching the farther percentile of the data."""
    a, b = toy_surface(1.0, off_surface=50), toy_surface(2.0, off_surface=50)
    r = shared_ranges([a, b])
    used = np.unique(b.faces)
    lo, hi = r["lambda_n"]
    assert lo + hi == pytest.approx(2.0)
    assert hi == pytest.approx(np.percentile(b.fields["lambda_n"][used], 99.5))
    assert 1.3 < hi < 1.4  # 1 + 0.4 at the pole; not 2
    assert r["lambda_t"][0] == pytest.approx(np.percentile(b.fields["lambda_t"][used], 0.5))
    assert r["u_magnitude"] == pytest.approx((0.0, np.percentile(
        b.fields["u_magnitude"][used], 99.5)))


# --- decimation ------------------------------------------------------------------------
def test_decimation_keeps_small_surfaces_and_bounds_large_ones() -> None:
    p, faces = sphere(3000)
    keep, tri = decimate(p, faces, max_faces=len(faces))
    assert np.array_equal(p[keep][tri], p[faces])  # untouched, compacted
    keep, tri = decimate(p, faces, max_faces=1000)
    assert 300 < len(tri) <= 1000
    assert tri.max() == len(keep) - 1 and set(keep) <= set(range(len(p)))
    # still a closed sphere: every kept point on it, the area about the same
    assert np.allclose(np.linalg.norm(p[keep], axis=1), 50)
    q = p[keep][tri]
    area = 0.5 * np.linalg.norm(np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), axis=1).sum()
    assert area == pytest.approx(4 * np.pi * 50**2, rel=0.1)
    assert MAX_VIEW_FACES >= 25_000  # a 21k-tet brain's surface is shown whole


def test_a_page_of_six_paper_sized_scenarios_stays_small() -> None:
    """A 1.4M-tet brain's surface has ~200k triangles and its sections ~40k each: decimated,
    six scenarios' views take under 15 MB (the page's budget is about 20 MB with figures)."""
    from scipy.spatial import Delaunay

    from brainbulge.results.present.webview import MAX_CUT_FACES, brain_scene, views_html

    p, faces = sphere(60_000)
    rng = np.random.default_rng(1)
    disk = rng.uniform(-45, 45, size=(25_000, 2))
    disk = disk[np.linalg.norm(disk, axis=1) < 45]
    tri = Delaunay(disk).simplices
    cut_pts = np.column_stack([disk, np.zeros(len(disk))])
    fields = {k: 1 + 0.01 * p[:, 0] for k in ("u_magnitude", "lambda_n", "lambda_t", "Je",
                                               "max_principal_strain")}
    cut = Cut(cut_pts, tri, np.zeros_like(cut_pts), {k: np.ones(len(disk)) for k in fields})
    big = Surface(p, faces, 0.01 * p, fields, np.zeros(len(faces), bool), np.array([1.0, 0, 0]),
                  cuts={"transverse": cut, "sagittal": cut}, cut_centre=np.zeros(3))
    assert len(faces) > 100_000 and len(tri) > 2 * MAX_CUT_FACES
    scene = brain_scene(big, shared_ranges([big]))
    n_tri = {L["name"]: len(decoded(L, "T", np.uint32)) // 3 for L in scene["layers"] if "T" in L}
    assert 10_000 < n_tri["surface"] <= MAX_VIEW_FACES
    assert n_tri["transverse section"] <= MAX_CUT_FACES
    page = views_html([scene] * 6, "big")
    assert len(page) < 15e6


# --- the Markdown page -----------------------------------------------------------------
@pytest.fixture
def report_folder(tmp_path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for name, scale in (("a", 1.0), ("b", 2.0)):
        (tmp_path / "brain" / name).mkdir(parents=True)
        toy_surface(scale).save(tmp_path / "brain" / name / "surface.npz")
    fig = plt.figure(figsize=(1, 1))
    fig.savefig(tmp_path / "fig.png")
    plt.close(fig)
    (tmp_path / "report.md").write_text(
        "# A report\n\n![figure](fig.png)\n\n![gone](missing.png)\n\n"
        "| claim | paper | here |\n|---|---|---|\n| bulge | 1.2 | 1.25 |\n| shift | 3 | 2.5 |\n\n"
        f"{views_marker('brain')}\n\nThe end.\n")
    return tmp_path


def test_the_page_embeds_figures_sorts_tables_and_puts_the_views_at_the_marker(
        report_folder: Path) -> None:
    path = write_report_html(report_folder / "report.md")
    page = path.read_text()
    assert path.name == "report.html" and page.startswith("<!DOCTYPE html>")
    assert "<title>A report</title>" in page
    srcs = re.findall(r'src="([^"]*)"', page)
    assert srcs[0].startswith("data:image/png;base64,") and srcs[1] == "missing.png"
    assert '<table class="sortable">' in page and "<td>1.25</td>" in page
    assert "http://" not in page.replace("http://www.w3.org", "") and "https://" not in page
    assert page.index('class="bbview"') < page.index("The end.")  # at the marker
    found = scenes(page)
    assert [s["title"] for s in found] == ["a", "b"]
    ranges = shared_ranges([Surface.load(report_folder / "brain" / n / "surface.npz")
                            for n in "ab"])
    for s in found:  # one colour range per field for both scenarios, said in the legend
        assert list(s["fields"]) == list(ranges)
        for k, info in s["fields"].items():
            assert info["range"] == pytest.approx(list(ranges[k]))
            assert "shared by the scenarios" in info["note"]
        layers = {L["name"]: L for L in s["layers"]}
        assert {"surface", "undeformed surface", "flap rim", "transverse section"} <= set(layers)
        n = len(decoded(layers["surface"], "X")) // 3
        assert len(decoded(layers["surface"]["values"], "lambda_n")) == n
        assert s["clip"]["transverse"] == [0, 0, 1, 0]


def test_reports_without_a_page_get_one_with_the_views_at_the_end(report_folder: Path) -> None:
    md = report_folder / "report.md"
    md.write_text("# Without a marker\n\nText.\n")
    (report_folder / "sub").mkdir()
    (report_folder / "sub" / "report.md").write_text("# Sub\n")
    written = write_missing_html(report_folder)
    assert sorted(p.relative_to(report_folder).as_posix() for p in written) == [
        "report.html", "sub/report.html"]
    assert markdown_html(md).index("Text.") < markdown_html(md).index('class="bbview"')
    assert write_missing_html(report_folder) == []  # up to date


# --- the demo's page in a browser --------------------------------------------------------
needs_chromium = pytest.mark.skipif(
    chromium_binary() is None and not os.environ.get("CI"),
    reason="no chromium on this machine (`apt-get install chromium`; .ci/run installs it)")


@needs_chromium
def test_demo_report_opens_offline_and_every_view_draws_in_chromium(quick_demo) -> None:
    from headless_browser import Browser

    code, out = quick_demo
    assert code == 0
    page = (out / "report.html").read_text()
    brain = sorted(p.parent for p in (out / "brain").glob("*/surface.npz"))
    assert len(brain) == 2 and all((d / "view.html").is_file() for d in brain)
    assert len(scenes(page)) == len(brain)
    with Browser() as b:
        b.open(out / "report.html")
        n = b.evaluate("document.querySelectorAll('.bbview').length")
        assert n == len(brain)
        ids = b.evaluate("Array.from(document.querySelectorAll('.bbview'), e => e.id)")
        for i, view in enumerate(f"#{v}" for v in ids):
            # a view starts when it scrolls near the screen
            b.evaluate(f"document.querySelector('{view}').scrollIntoView()")
            assert b.wait_for(f"brainbulgeViews.filter(v => v.frames > 0).length > {i}")
            first = b.screenshot(view + " canvas.bbcanvas")
            # drawn: most of the brain's pixels are coloured (not the white background)
            painted = (first.min(axis=2) < 0.9).mean()
            assert painted > 0.15, f"view {i} is blank ({painted:.1%} painted)"
            assert len(np.unique((first * 255).astype(int).reshape(-1, 3), axis=0)) > 100
            b.evaluate(f"(() => {{ const s = document.querySelector('{view} select.bbfield');"
                       " s.value = 'lambda_t'; s.dispatchEvent(new Event('change')); })()")
            other = b.screenshot(view + " canvas.bbcanvas")
            assert np.abs(other - first).mean() > 0.02, "the field did not change the picture"
            b.evaluate(f"(() => {{ const s = document.querySelector('{view} select.bbmode');"
                       " s.value = 'transverse'; s.dispatchEvent(new Event('change')); })()")
            cut = b.screenshot(view + " canvas.bbcanvas")
            assert np.abs(cut - other).mean() > 0.01, "cutting open did not change the picture"
            b.evaluate(f"document.querySelector('{view} input.bbundeformed').click()")
            undeformed = b.screenshot(view + " canvas.bbcanvas")
            assert np.abs(undeformed - cut).mean() > 0.002, "no undeformed outline"
        # a click on a header sorts a table by that column
        order = b.evaluate(
            "(() => { const t = document.querySelectorAll('table.sortable')[0];"
            " t.tHead.rows[0].cells[1].click();"
            " return Array.from(t.tBodies[0].rows, r => parseFloat(r.cells[1].textContent)); })()")
        numbers = [x for x in order if x is not None]
        assert numbers == sorted(numbers) and len(numbers) >= 2
        assert not [v for v in b.evaluate("brainbulgeViews.map(v => v.error)") if v]
        assert b.errors() == []
        remote = [u for u in b.requests() if not u.startswith(("file:", "data:"))]
        assert remote == [], f"the page requested {remote}"
        # a scenario's own page draws too
        b.open(brain[0] / "view.html")
        b.evaluate("document.querySelector('.bbview').scrollIntoView()")
        assert b.wait_for("brainbulgeViews.length && brainbulgeViews[0].frames > 0")
        assert (b.screenshot("canvas.bbcanvas").min(axis=2) < 0.9).mean() > 0.15
        assert b.errors() == []
