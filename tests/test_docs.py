"""The documentation cannot drift from the code.

- Every ```python block of the pages in ``PYTHON_PAGES`` runs: the blocks of a page in order,
  sharing one namespace, in a temporary folder. They run as a module named ``docs_example``
  (not ``__main__``), so code under ``if __name__ == "__main__":`` (a full study on a Dask
  cluster, in docs/studies.md) is compiled but not run.
- Every ``brainbulge ...`` command in the ```console / ```bash / ```sh blocks of README.md and
  docs/*.md parses with the real CLI parser and selects a command.
- ```json blocks of the pages parse; label maps among them are accepted by ``read_label_map``.
- Relative links between the pages point to existing files and headings.
- Code names in backticks in the pages and in the CLI's help texts (Python files such as
  ``solver/linear/amg.py``, dotted names such as ``results.summary.exceeded_in``, UPPER_CASE
  constants) name files, modules, attributes and constants that exist.
- The tables of ``summary.json`` keys in docs/outputs.md are the declarations of
  ``results/measures/schema.py`` (:func:`~.schema.markdown_table`): the same keys,
  units and meanings. ``python tests/test_docs.py`` writes them into the page.
"""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import pytest

from brainbulge.cli import build_parser
from brainbulge.geometry.brain.labels import read_label_map
from brainbulge.results.measures import schema

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]
PYTHON_PAGES = ["own-mri.md", "studies.md"]
SHELL_LANGS = {"console", "bash", "sh", "shell"}
#: pages that must show at least this many ``brainbulge`` commands (guards the extractor)
MIN_COMMANDS = {"own-mri.md": 5, "studies.md": 4, "README.md": 5}

FENCE = re.compile(r"^```([\w+-]*)[^\n]*\n(.*?)^```", re.S | re.M)


def blocks(page: Path, langs: set[str]) -> list[tuple[int, str]]:
    """``(line number of the first code line, code)`` of the fenced blocks in ``langs``."""
    text = page.read_text(encoding="utf-8")
    out = []
    for m in FENCE.finditer(text):
        if m.group(1).lower() in langs:
            out.append((text.count("\n", 0, m.start(2)) + 1, m.group(2)))
    return out


def brainbulge_commands(page: Path) -> list[tuple[int, list[str]]]:
    """``(line, argv without the program name)`` of every ``brainbulge`` command in the
    shell blocks of ``page``: prompts (``$``), comments, continuation lines, environment
    assignments and ``&&``/``;``/``|`` chains are handled."""
    found = []
    for first, code in blocks(page, SHELL_LANGS):
        logical: list[tuple[int, str]] = []  # (offset of the first physical line, line)
        pending = None
        for offset, raw in enumerate(code.splitlines()):
            start, text = pending if pending else (offset, "")
            text += raw
            if text.endswith("\\"):
                pending = (start, text[:-1] + " ")
                continue
            pending = None
            logical.append((start, text))
        for offset, line in logical:
            line = line.strip()
            if line.startswith("$ "):
                line = line[2:]
            try:
                tokens = shlex.split(line, comments=True)
            except ValueError as err:  # unbalanced quotes
                pytest.fail(f"{page.name}:{first + offset}: cannot split {line!r}: {err}")
            segment: list[str] = []
            for tok in [*tokens, ";"]:
                if tok in ("&&", "||", ";", "|"):
                    while segment and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*=.*", segment[0]):
                        segment.pop(0)  # VAR=value before the command
                    if segment and segment[0] == "brainbulge":
                        found.append((first + offset, segment[1:]))
                    segment = []
                else:
                    segment.append(tok)
    return found


COMMANDS = [(page, line, argv) for page in PAGES for line, argv in brainbulge_commands(page)]


@pytest.mark.parametrize(
    "page,line,argv",
    COMMANDS,
    ids=[f"{p.name}:{line}" for p, line, _ in COMMANDS],
)
def test_command_parses(page: Path, line: int, argv: list[str], capsys) -> None:
    parser = build_parser()
    if {"-h", "--help", "--version"} & set(argv):
        with pytest.raises(SystemExit) as exc:
            parser.parse_args(argv)
        assert exc.value.code == 0
        return
    try:
        args = parser.parse_args(argv)
    except SystemExit:
        err = capsys.readouterr().err.strip().splitlines()
        pytest.fail(
            f"{page.name}:{line}: `brainbulge {shlex.join(argv)}` does not parse: "
            f"{err[-1] if err else ''}"
        )
    assert callable(getattr(args, "func", None)), f"{page.name}:{line}: no command selected"


@pytest.mark.parametrize("name,least", MIN_COMMANDS.items())
def test_pages_show_commands(name: str, least: int) -> None:
    page = ROOT / name if name == "README.md" else DOCS / name
    assert len(brainbulge_commands(page)) >= least


@pytest.mark.parametrize("name", PYTHON_PAGES)
def test_python_examples_run(name: str, tmp_path: Path, monkeypatch) -> None:
    page = DOCS / name
    code_blocks = blocks(page, {"python"})
    assert code_blocks, f"{name} has no python block"
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "docs_example"}
    for first, code in code_blocks:
        # pad so that tracebacks give the line numbers of the Markdown page
        exec(compile("\n" * (first - 1) + code, str(page), "exec"), namespace)


@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_json_blocks(page: Path) -> None:
    for first, code in blocks(page, {"json"}):
        try:
            data = json.loads(code)
        except ValueError as err:
            pytest.fail(f"{page.name}:{first}: invalid JSON: {err}")
        if isinstance(data, dict) and "gray" in data:
            read_label_map(data)


def _slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading."""
    text = heading.strip().lower().replace("`", "")
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    text = FENCE.sub("", page.read_text(encoding="utf-8"))
    return {_slug(h) for h in re.findall(r"^#{1,6} (.+)$", text, re.M)}


@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_relative_links(page: Path) -> None:
    text = FENCE.sub("", page.read_text(encoding="utf-8"))
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target):
            continue  # https:, mailto:
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        assert dest.is_file(), f"{page.name}: link to missing {target}"
        if anchor and dest.suffix == ".md":
            assert anchor in _anchors(dest), f"{page.name}: no heading for #{anchor}"


# --- names of the code that the docs mention ----------------------------------------------

SRC = ROOT / "src" / "brainbulge"
SPAN = re.compile(r"`+([^`\n]+?)`+")
PY_FILE = re.compile(r"[\w*/.-]*\w\.py\b")
DOTTED = re.compile(r"[a-z_][a-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)+")
CONSTANT = re.compile(r"[A-Z][A-Z0-9]*(?:_[A-Z0-9]+)+")
#: endings of file names, not of Python names (``brainbulge.log``, ``summary.json``)
FILE_ENDINGS = {
    "csv",
    "gz",
    "h5",
    "html",
    "json",
    "log",
    "md",
    "mgz",
    "npz",
    "png",
    "py",
    "toml",
    "txt",
    "vtu",
    "xdmf",
}


def help_texts() -> dict[str, str]:
    """``brainbulge [command] --help`` of every command, by ``brainbulge [command]``."""
    import argparse

    parser = build_parser()
    texts = {"brainbulge": parser.format_help()}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                texts[f"brainbulge {name}"] = sub.format_help()
    return texts


def code_names(text: str) -> set[str]:
    """The code names in backticks of ``text`` (Markdown without its fenced blocks, or a
    help text): Python files (``solver/linear/amg.py``, in a command too), dotted names
    whose first part is ``brainbulge`` or one of its modules, and UPPER_CASE constants."""
    modules = {p.stem for p in SRC.iterdir() if p.suffix == ".py" or (p / "__init__.py").is_file()}
    names = set()
    for span in SPAN.findall(FENCE.sub("", text)):
        names.update(PY_FILE.findall(span))
        span = span.strip()
        parts = span.split(".")
        if DOTTED.fullmatch(span) and parts[0] in {"brainbulge", *modules}:
            if parts[-1] not in FILE_ENDINGS:
                names.add(span)
        if CONSTANT.fullmatch(span):
            names.add(span)
    return names


def _source_files() -> list[Path]:
    return [p for d in ("src", "tests", "benchmarks") for p in (ROOT / d).rglob("*.py")]


def missing_name(name: str) -> bool:
    """True when ``name`` (see :func:`code_names`) names nothing in the repository."""
    import importlib

    if name.endswith(".py"):
        rel = name.removeprefix("src/brainbulge/")
        from_root = rel.split("/")[0] in ("src", "tests", "benchmarks")  # else: a path's tail
        return not any(
            (p.relative_to(ROOT) if from_root else p).match(rel) for p in _source_files()
        )
    if CONSTANT.fullmatch(name):
        pattern = re.compile(rf"\b{name}\b")
        return not any(pattern.search(p.read_text(encoding="utf-8")) for p in SRC.rglob("*.py"))
    parts = name.split(".")
    if parts[0] != "brainbulge":
        parts.insert(0, "brainbulge")
    for n in range(len(parts), 0, -1):  # the longest importable module, then attributes
        try:
            obj = importlib.import_module(".".join(parts[:n]))
        except ImportError:
            continue
        for attr in parts[n:]:
            if not hasattr(obj, attr):
                return True
            obj = getattr(obj, attr)
        return False
    return True


NAMED = [(page.name, page.read_text(encoding="utf-8")) for page in PAGES]


@pytest.mark.parametrize("source,text", NAMED, ids=[n for n, _ in NAMED])
def test_docs_name_existing_code(source: str, text: str) -> None:
    stale = sorted(n for n in code_names(text) if missing_name(n))
    assert not stale, f"{source} names code that does not exist: {stale}"


def test_help_texts_name_existing_code() -> None:
    for command, text in help_texts().items():
        stale = sorted(n for n in code_names(text) if missing_name(n))
        assert not stale, f"`{command} --help` names code that does not exist: {stale}"


def test_stale_names_are_found() -> None:
    """The check above sees a removed module, constant and attribute."""
    text = (
        "`solver/linear.py` and `solver/krylov.py`, `COARSE_TETS`, "
        "`results.measures.summary.exceeded_at`, "
        "`python benchmarks/bench_nothing.py --x 1`; these exist: `solver/linear/amg.py`, "
        "`krylov.py`, `LARGE_TETS`, `brainbulge.heap`, `results.measures.summary.exceeded_in`, "
        "`summary.json`, `brainbulge.log`, `OMP_NUM_THREADS`"
    )
    names = code_names(text)
    assert {n for n in names if missing_name(n)} == {
        "solver/linear.py",
        "solver/krylov.py",
        "COARSE_TETS",
        "results.measures.summary.exceeded_at",
        "benchmarks/bench_nothing.py",
    }


# --- the tables of summary.json keys: the declarations of results/measures/schema.py ---

OUTPUTS = DOCS / "outputs.md"
#: the line before each key table of docs/outputs.md -> the table (of the keys written by
#: those cases)
KEY_TABLES = {
    "Both kinds of run:": schema.markdown_table(schema.BOTH),
    "Hemidisk only:": schema.markdown_table(frozenset({schema.HEMIDISK})),
    "Brain only (lengths mm, volumes ml, areas cm²):": schema.markdown_table(
        frozenset({schema.BRAIN})),
    "element's values at its vertices, averaged over the elements sharing a vertex):":
        schema.markdown_table(schema.BOTH, schema.FIELDS, "field"),
}


def key_tables(text: str) -> dict[str, tuple[int, int]]:
    """``(start, end)`` character offsets in ``text`` of the table after each line of
    ``KEY_TABLES`` (its ``|`` lines, after one blank line)."""
    out = {}
    for intro in KEY_TABLES:
        m = re.search(rf"^{re.escape(intro)}\n\n((?:\|.*\n)+)", text, re.M)
        assert m, f"outputs.md has no table after {intro!r}"
        out[intro] = m.span(1)
    return out


def written_key_tables(text: str) -> str:
    """``text`` (docs/outputs.md) with its key tables made the schema's."""
    for intro, (a, b) in sorted(key_tables(text).items(), key=lambda kv: -kv[1][0]):
        text = text[:a] + KEY_TABLES[intro] + "\n" + text[b:]
    return text


def test_summary_key_tables_are_the_schemas() -> None:
    """Every key and field, unit and meaning of the tables is declared in
    ``results/measures/schema.py``, and every declared one is in a table."""
    text = OUTPUTS.read_text(encoding="utf-8")
    for intro, (a, b) in key_tables(text).items():
        assert text[a:b].rstrip("\n") == KEY_TABLES[intro], (
            f"outputs.md, the table after {intro!r}, is not the schema's: run "
            "`python tests/test_docs.py` to write it")
    assert {k.cases for k in schema.KEYS} == {schema.BOTH, *(frozenset({c}) for c in schema.BOTH)}
    assert {k.cases for k in schema.FIELDS} == {schema.BOTH}


def test_a_changed_key_table_is_seen() -> None:
    """The check above sees a unit and a meaning that differ from the declarations."""
    text = OUTPUTS.read_text(encoding="utf-8")
    for old, new in (("| `bulge_volume_ml` | ml |", "| `bulge_volume_ml` | mm³ |"),
                     ("largest \\|u\\|", "largest u")):
        assert old in text
        changed = text.replace(old, new, 1)
        assert written_key_tables(changed) == text != changed


if __name__ == "__main__":
    OUTPUTS.write_text(written_key_tables(OUTPUTS.read_text(encoding="utf-8")), encoding="utf-8")
