"""``report.html`` next to a ``report.md``: the same report as one self-contained page.

The Markdown is rendered by markdown-it-py (CommonMark and tables: any report's tables,
e.g. a paper-claims table, render alike and sort by a click on a column header), its local
PNG/JPEG/SVG figures are embedded as data URIs, and an HTML comment
``<!-- brainbulge-3d: FOLDER -->`` (invisible in Markdown) becomes the interactive 3D views
of the scenarios below ``FOLDER`` (relative to the report; :func:`~brainbulge.results.
webview.study_views_html`); other comments ``<!-- brainbulge-3d-NAME -->`` take the HTML
blocks a writer passes (the plan's head). A report without a marker whose folder holds 3D
scenarios gets their views at the end. The page requests nothing: it opens offline.
"""

from __future__ import annotations

import base64
import itertools
import mimetypes
import re
from collections.abc import Mapping
from pathlib import Path

#: a marker of the scenario views below a folder
VIEWS_MARKER = re.compile(r"<!--\s*brainbulge-3d:\s*(.+?)\s*-->")
#: a marker of a writer's own block
BLOCK_MARKER = re.compile(r"<!--\s*brainbulge-3d-([\w-]+)\s*-->")
#: how deep below a report's folder :func:`write_missing_html` looks for reports
REPORT_DEPTH = 2
INTRO = ("<p class=\"bbnote\">Interactive 3D views: drag to rotate, wheel to zoom, "
         "shift-drag to pan, double-click to reset; pick the field and what to show (the "
         "surface, or cut open at a section) above each view. Click a table's header to sort "
         "it.</p>\n")


def views_marker(folder: str = ".") -> str:
    """The Markdown line that :func:`write_report_html` replaces by the 3D views of the
    scenarios below ``folder`` (relative to the report)."""
    return f"<!-- brainbulge-3d: {folder} -->"


def block_marker(name: str) -> str:
    """The Markdown line that :func:`write_report_html` replaces by ``blocks[name]``."""
    return f"<!-- brainbulge-3d-{name} -->"


def _renderer():
    """CommonMark with tables and without raw HTML: any ``<`` in the Markdown (a scenario
    name, a note, an error message, a path) is shown as text, never read as a tag."""
    from markdown_it import MarkdownIt

    return MarkdownIt("commonmark", {"html": False}).enable("table")


def _keep_markers(tokens: list) -> list:
    """The parsed Markdown with each paragraph that is exactly one of our markers
    (:func:`views_marker`, :func:`block_marker`) turned back into that HTML comment, for
    :func:`markdown_html` to replace; a marker inside other text stays escaped text."""
    out: list = []
    i = 0
    while i < len(tokens):
        tok = tokens[i]
        if (tok.type == "paragraph_open" and i + 2 < len(tokens)
                and tokens[i + 2].type == "paragraph_close"
                and (VIEWS_MARKER.fullmatch(tokens[i + 1].content)
                     or BLOCK_MARKER.fullmatch(tokens[i + 1].content))):
            tok.type, tok.tag, tok.nesting = "html_block", "", 0
            tok.content, tok.children = tokens[i + 1].content + "\n", None
            out.append(tok)
            i += 3
            continue
        out.append(tok)
        i += 1
    return out


def _embed_images(tokens, root: Path) -> None:
    """Point the images of the parsed Markdown at data URIs of their local files (a missing
    file keeps its path and shows its alt text)."""
    for tok in tokens:
        for child in tok.children or ():
            if child.type != "image":
                continue
            src = str(child.attrGet("src") or "")
            path = root / src
            if re.match(r"^[a-z]+:", src) or not path.is_file():
                continue
            mime = mimetypes.guess_type(path.name)[0] or "application/octet-stream"
            data = base64.b64encode(path.read_bytes()).decode("ascii")
            child.attrSet("src", f"data:{mime};base64,{data}")
            child.attrSet("loading", "lazy")


def markdown_html(md_path: Path, blocks: Mapping[str, str] | None = None) -> str:
    """The body of ``report.html`` for the Markdown file ``md_path`` (module docstring)."""
    from brainbulge.results.present.webview import study_views_html

    md_path = Path(md_path)
    root = md_path.parent
    md = _renderer()
    tokens = _keep_markers(md.parse(md_path.read_text(encoding="utf-8")))
    _embed_images(tokens, root)
    body = md.renderer.render(tokens, md.options, {})
    body = body.replace("<table>", '<table class="sortable">')
    found = False
    count = itertools.count()

    def views(m: re.Match) -> str:
        nonlocal found
        found = True
        return study_views_html((root / m.group(1)).resolve(), f"v{next(count)}")

    def block(m: re.Match) -> str:
        nonlocal found
        found = True
        return (blocks or {}).get(m.group(1), "")

    body = VIEWS_MARKER.sub(views, body)
    body = BLOCK_MARKER.sub(block, body)
    if not found:
        extra = "".join(study_views_html(d, f"v{next(count)}") for d in (
            sorted({p.parent.parent for p in root.glob("**/surface.npz")
                    if 2 <= len(p.relative_to(root).parts) <= REPORT_DEPTH + 1})))
        if extra:
            body += "<h2>3D views</h2>\n" + extra
    if "bbview" not in body:
        return body
    return body.replace("</h1>\n", "</h1>\n" + INTRO, 1) if "</h1>" in body else INTRO + body


def write_report_html(md_path: Path, blocks: Mapping[str, str] | None = None) -> Path:
    """Write ``report.html`` next to ``md_path`` (:func:`markdown_html`); return its path."""
    from brainbulge.results.present.webview import write_page

    md_path = Path(md_path)
    text = md_path.read_text(encoding="utf-8")
    title = next((line[2:].strip() for line in text.splitlines() if line.startswith("# ")),
                 "brainbulge report")
    return write_page(md_path.with_suffix(".html"), title, markdown_html(md_path, blocks))


def write_missing_html(folder: Path) -> list[Path]:
    """``report.html`` for each ``report.md`` in ``folder`` or up to :data:`REPORT_DEPTH`
    levels below it that has none, or an older one (reports written without one)."""
    out = []
    for md in sorted(Path(folder).glob("**/report.md")):
        if len(md.relative_to(folder).parts) > REPORT_DEPTH + 1:
            continue
        target = md.with_suffix(".html")
        if not target.is_file() or target.stat().st_mtime < md.stat().st_mtime:
            out.append(write_report_html(md))
    return out
