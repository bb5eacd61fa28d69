"""Interactive 3D views in self-contained HTML: ``view.html`` of a 3D scenario and the 3D
sections of ``report.html`` (:mod:`brainbulge.results.present.html_report`).

A *scene* is a JSON object that the page's viewer (``assets/viewer.js``, plain WebGL 1, no
library: docs/design.md) draws: triangle-mesh and line layers with reference positions ``X``,
displacements ``U`` [mm] and per-vertex field values, base64-encoded float32/uint32 arrays.
Everything is inline: a page opens offline from disk and requests nothing.

A scenario's scene (:func:`brain_scene`) holds the deformed parenchyma surface coloured by a
field of :data:`~brainbulge.results.present.views3d.VIEW_FIELDS` (colour maps as in the PNGs, ranges
from :func:`~brainbulge.results.present.views3d.shared_ranges`, shared by the scenarios of a page),
the flap's rim, the transverse and sagittal sections (shown alone, or with the surface
clipped at their plane), and the undeformed surface and section outlines on demand. Surfaces
over :data:`MAX_VIEW_FACES` triangles (sections over :data:`MAX_CUT_FACES`) are decimated
(:func:`decimate`) so that a page of six scenarios stays small.
"""

from __future__ import annotations

import base64
import html
import json
import re
from collections.abc import Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from brainbulge.atomic import atomic_output
from brainbulge.results.present.figures import CMAPS, range_note
from brainbulge.results.present.sections import PLANES, boundary_edges
from brainbulge.results.present.views3d import VIEW_FIELDS, Surface, shared_ranges, view_frame

#: the most triangles of a surface (and of a section) in a view; larger ones are decimated
#: by vertex clustering (a 21k-tet brain's parenchyma surface has 5.6k, its sections 1-2k),
#: so that six scenarios of a paper-sized mesh take about 2 MB each
MAX_VIEW_FACES = 30_000
MAX_CUT_FACES = 8_000
#: what a scenario's view can show: (mode, label, the preset view it turns to); a layer
#: names the modes it shows in. The transverse cut takes away the tissue above its plane,
#: the sagittal cut that on the patient's right ("other half": the other side)
MODES = (("surface", "surface", ""),
         ("transverse", "cut at the transverse section", "from above"),
         ("sagittal", "cut at the sagittal section", "from the right"),
         ("sections", "the two sections", ""))
#: colours of the fixed-colour layers (RGB in 0-1)
RIM_COLOUR = (0.0, 0.0, 0.0)
UNDEFORMED = {"color": (0.35, 0.35, 0.35), "alpha": 0.28}


def asset(name: str) -> str:
    """The text of ``assets/<name>`` (viewer, table sorter, style sheet)."""
    return resources.files("brainbulge.results.present").joinpath("assets", name).read_text("utf-8")


def _b64(a: np.ndarray, dtype: Any) -> str:
    return base64.b64encode(np.ascontiguousarray(a, dtype=dtype).tobytes()).decode("ascii")


def plain_label(label: str) -> str:
    """A matplotlib label without TeX: ``r"$\\lambda_n$"`` -> ``"λn"``."""
    return re.sub(r"\$\\lambda_(\w)\$", r"λ\1", label).replace("$", "")


def decimate(points: np.ndarray, faces: np.ndarray, max_faces: int = MAX_VIEW_FACES
             ) -> tuple[np.ndarray, np.ndarray]:
    """The vertices to keep (indices into ``points``) and the triangles (into them) of a
    surface with at most ``max_faces`` triangles: all of it if small enough, else vertex
    clustering (the vertices of a grid cell merge into its first one; collapsed and repeated
    triangles go), the cell growing until few enough remain."""
    f = np.asarray(faces, dtype=np.int64)
    if len(f) > max_faces:
        X = np.asarray(points, dtype=float)
        used = np.unique(f)
        area = 0.5 * np.linalg.norm(np.cross(X[f[:, 1]] - X[f[:, 0]], X[f[:, 2]] - X[f[:, 0]]),
                                    axis=1).sum()
        h = np.sqrt(4 * area / (np.sqrt(3) * max_faces))  # equilateral triangles of that count
        while len(f) > max_faces:
            _, first, inverse = np.unique(np.floor(X[used] / h).astype(np.int64), axis=0,
                                          return_index=True, return_inverse=True)
            rep = np.full(len(X), -1, dtype=np.int64)
            rep[used] = used[first][inverse.ravel()]
            g = rep[np.asarray(faces)]
            g = g[(g[:, 0] != g[:, 1]) & (g[:, 1] != g[:, 2]) & (g[:, 0] != g[:, 2])]
            _, once = np.unique(np.sort(g, axis=1), axis=0, return_index=True)
            f = g[np.sort(once)]
            h *= 1.25
    keep, local = np.unique(f, return_inverse=True)
    return keep, local.reshape(-1, 3)


def mesh_layer(X: np.ndarray, U: np.ndarray | None, T: np.ndarray,
               values: Mapping[str, np.ndarray] | None = None,
               max_faces: int = MAX_VIEW_FACES, **spec: Any) -> dict[str, Any]:
    """A triangle layer of the used vertices (decimated to ``max_faces``); ``spec``: the
    viewer's ``modes``, ``clip``, ``undeformed``, ``color``, ``alpha``."""
    keep, tri = decimate(X, T, max_faces)
    layer = {"X": _b64(np.asarray(X)[keep], np.float32), "T": _b64(tri, np.uint32),
             "values": {k: _b64(np.asarray(v)[keep], np.float32)
                        for k, v in (values or {}).items()}, **spec}
    if U is not None:
        layer["U"] = _b64(np.asarray(U)[keep], np.float32)
    return layer


def line_layer(X: np.ndarray, U: np.ndarray | None, E: np.ndarray, **spec: Any
               ) -> dict[str, Any]:
    """A layer of line segments ``E`` (e, 2) between the points ``X`` (moved by ``U``)."""
    keep, seg = np.unique(np.asarray(E, dtype=np.int64), return_inverse=True)
    layer = {"X": _b64(np.asarray(X)[keep], np.float32),
             "E": _b64(seg.reshape(-1, 2), np.uint32), **spec}
    if U is not None:
        layer["U"] = _b64(np.asarray(U)[keep], np.float32)
    return layer


def colour_maps(names: Sequence[str]) -> dict[str, str]:
    """256 RGB bytes (base64) of each matplotlib colour map in ``names``."""
    import matplotlib

    return {n: _b64(np.round(255 * matplotlib.colormaps[n](np.linspace(0, 1, 256))[:, :3]),
                    np.uint8) for n in dict.fromkeys(names)}


def field_info(ranges: Mapping[str, tuple[float, float]], labels: Mapping[str, str],
               notes: Mapping[str, str], cmaps: Mapping[str, str] | None = None
               ) -> dict[str, Any]:
    """The scene's ``fields``: label, colour range, colour map and how the range was
    chosen (``notes``), per field of ``ranges`` (in their order)."""
    cmaps = cmaps or {}
    return {k: {"label": plain_label(labels.get(k, k)), "range": [float(lo), float(hi)],
                "cmap": cmaps.get(k) or CMAPS.get(k, "viridis"), "note": notes.get(k, "")}
            for k, (lo, hi) in ranges.items()}


def ribbons(X: np.ndarray, edges: np.ndarray, centre: np.ndarray, width: float,
            lift: float) -> tuple[np.ndarray, np.ndarray]:
    """Points (4 e, 3) and triangles (2 e, 3) of flat strips ``width`` mm wide along the
    ``edges`` (e, 2) of a closed surface around ``centre``, raised ``lift`` mm off it: lines
    that stay visible at any zoom (WebGL draws lines one pixel wide)."""
    a, b = np.asarray(X, float)[edges[:, 0]], np.asarray(X, float)[edges[:, 1]]
    out = 0.5 * (a + b) - centre
    out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)
    side = np.cross(b - a, out)
    side *= 0.5 * width / np.maximum(np.linalg.norm(side, axis=1, keepdims=True), 1e-12)
    a, b = a + lift * out, b + lift * out
    points = np.stack([a - side, a + side, b + side, b - side], axis=1).reshape(-1, 3)
    base = 4 * np.arange(len(edges))[:, None]
    tris = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
    return points, tris


def frame(points: np.ndarray) -> dict[str, Any]:
    """``centre`` and ``radius`` (mm) of a scene from its points' bounding box."""
    lo, hi = np.min(points, axis=0), np.max(points, axis=0)
    return {"centre": (0.5 * (lo + hi)).tolist(), "radius": float(0.5 * (hi - lo).max())}


def presets(flap_direction: np.ndarray | None = None) -> dict[str, list]:
    """The buttons' views (rows: screen right, screen up, view direction)."""
    out = {}
    if flap_direction is not None:
        out["from the flap"] = view_frame("flap", flap_direction).tolist()
    out["from above"] = view_frame("above", np.zeros(3)).tolist()
    for name, d in (("from the left", (-1.0, 0.0, 0.0)), ("from the right", (1.0, 0.0, 0.0)),
                    ("from the front", (0.0, 1.0, 0.0))):
        out[name] = view_frame("side", np.array(d)).tolist()
    return out


def brain_scene(s: Surface, ranges: Mapping[str, tuple[float, float]], title: str = "",
                shared: bool = False) -> dict[str, Any]:
    """The scene of one scenario (module docstring) with the colour ``ranges``."""
    fields = [k for k in ranges if k in s.fields]
    surface_modes = ["surface", *[p for p in s.cuts]]
    layers = [
        mesh_layer(s.points, s.u, s.faces, {k: s.fields[k] for k in fields}, name="surface",
                   modes=surface_modes, clip=True),
        {"like": 0, "name": "undeformed surface", "modes": surface_modes, "clip": True,
         "undeformed": True, **UNDEFORMED},
    ]
    if len(s.rim):
        layers.append(line_layer(s.points, s.u, s.rim, name="flap rim", modes=surface_modes,
                                 clip=True, color=RIM_COLOUR))
    clip = {}
    for plane, c in s.cuts.items():
        if not len(c.triangles):
            continue
        layers.append(mesh_layer(c.points, c.u, c.triangles,
                                 {k: c.fields[k] for k in fields if k in c.fields},
                                 MAX_CUT_FACES, name=f"{plane} section",
                                 modes=[plane, "sections"]))
        layers.append(line_layer(c.points, None, boundary_edges(c.triangles),
                                 name=f"{plane} section, undeformed outline",
                                 modes=[plane, "sections"], undeformed=True, color=RIM_COLOUR))
        normal = np.eye(3)[PLANES[plane][0]]
        clip[plane] = [*normal.tolist(), float(normal @ np.asarray(s.cut_centre, float))]
    modes = [m for m in MODES if m[0] == "surface" or m[0] in clip
             or (m[0] == "sections" and clip)]
    shared_note = ", shared by the scenarios of this page" if shared else ""
    notes = {k: range_note(k, from_zero=True) + shared_note for k in fields}
    return {"title": title, "fields": field_info({k: ranges[k] for k in fields},
                                                 VIEW_FIELDS, notes),
            "cmaps": colour_maps([CMAPS.get(k, "viridis") for k in fields]),
            "layers": layers, "modes": modes, "clip": clip,
            "views": presets(s.flap_direction), **frame(s.points[np.unique(s.faces)])}


def scene_html(scene: Mapping[str, Any], sid: str) -> str:
    """A view's ``<div>`` with its scene as inline JSON (``</`` escaped)."""
    data = json.dumps(scene, separators=(",", ":")).replace("</", "<\\/")
    title = f"<h3>{html.escape(scene['title'])}</h3>" if scene.get("title") else ""
    return (f'<div class="bbview" id="view-{sid}" data-scene="{sid}">{title}</div>\n'
            f'<script type="application/json" id="{sid}">{data}</script>\n')


def views_html(scenes: Sequence[Mapping[str, Any]], prefix: str) -> str:
    """The views of ``scenes`` in a grid; ``prefix`` makes their ids unique on the page."""
    return ('<div class="bbviews">\n'
            + "".join(scene_html(sc, f"{prefix}-{i}") for i, sc in enumerate(scenes))
            + "</div>\n")


def study_views_html(folder: Path, prefix: str) -> str:
    """The views of the scenarios below ``folder`` (each a subfolder with a
    ``surface.npz``), with colour ranges shared by them; empty if there are none."""
    surfaces = {p.parent.name: Surface.load(p) for p in sorted(Path(folder).glob("*/surface.npz"))}
    if not surfaces:
        return ""
    ranges = shared_ranges(list(surfaces.values()))
    return views_html([brain_scene(s, ranges, name, shared=len(surfaces) > 1)
                       for name, s in surfaces.items()], prefix)


def page(title: str, body: str) -> str:
    """A complete HTML page: ``body`` with the style sheet, the viewer and the table sorter
    inline."""
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
            f"<title>{html.escape(title)}</title>\n<style>\n{asset('report.css')}</style>\n"
            f"</head>\n<body>\n<main>\n{body}</main>\n<script>\n{asset('viewer.js')}</script>\n"
            f"<script>\n{asset('tables.js')}</script>\n</body>\n</html>\n")


def write_page(path: Path, title: str, body: str) -> Path:
    """Write :func:`page` to ``path`` atomically."""
    with atomic_output(Path(path)) as tmp:
        Path(tmp).write_text(page(title, body), encoding="utf-8")
    return Path(path)


def write_view_html(s: Surface, path: Path, title: str = "") -> Path:
    """``view.html`` of a scenario: its interactive view, colour ranges from its data."""
    body = (f"<h1>{html.escape(title or 'brainbulge 3D view')}</h1>\n"
            "<p>Drag to rotate, wheel to zoom, shift-drag to pan, double-click to reset. "
            "Pick the field and what to show above the view.</p>\n"
            + views_html([brain_scene(s, shared_ranges([s]))], "view"))
    return write_page(path, title or "brainbulge 3D view", body)
