"""docs/paper.md's claims table lists every claim of the paper's sections 3-5 that
``benchmarks/paper_claims.toml`` holds, each with the paper's values and a verdict."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from paper_claims import rules_text
from paper_run import BAND, VERDICTS, band

ROOT = Path(__file__).resolve().parents[1]
CLAIMS = ROOT / "benchmarks" / "paper_claims.toml"
PAGE = ROOT / "docs" / "paper.md"

#: the numbers of the paper's sections 3-5 (trends (i)-(v) and every stated value) that the
#: claims must carry: a claim list that drops one fails here
PAPER_NUMBERS = {"1.7", "1.2", "1.3", "0.7", "30 %", "1,108", "1,673", "0.252", "190", "0.9",
                 "256", "1,275,808", "241,845", "4,279", "2,494", "0.28", "333", "56", "28",
                 "5 %", "25 %", "22", "18 %", "19 %", "21 %", "50-150", "27-127", "10 %",
                 "80", "60", "twice"}
TRENDS = {"(i)", "(ii)", "(iii)", "(iv)", "(v)"}


def _claims() -> list[dict]:
    return tomllib.loads(CLAIMS.read_text())["claim"]


def _table() -> dict[str, list[str]]:
    """id -> cells of the claims table (the first table of docs/paper.md)."""
    rows: dict[str, list[str]] = {}
    text = PAGE.read_text(encoding="utf-8")
    section = text.split("## Claims", 1)[1].split("\n## ", 1)[0]
    for line in section.splitlines():
        if line.startswith("| ") and not line.startswith("| id ") and "---" not in line:
            cells = [c.strip() for c in line.strip().strip("|").split(" | ")]
            rows[cells[0]] = cells
    return rows


def test_the_claim_list_covers_the_papers_numbers_and_trends() -> None:
    claims = _claims()
    ids = [c["id"] for c in claims]
    assert len(ids) == len(set(ids))
    values = {v for c in claims for v in c["values"]}
    assert PAPER_NUMBERS <= values, sorted(PAPER_NUMBERS - values)
    stated = " ".join(c["paper"] for c in claims)
    assert all(f"{t} " in stated for t in TRENDS)
    assert {c["section"].split(".")[0] for c in claims} == {"3", "4", "5", "abstract"}


def test_docs_paper_lists_every_claim_with_its_values_and_a_verdict() -> None:
    table = _table()
    claims = _claims()
    assert set(table) == {c["id"] for c in claims}
    for c in claims:
        cells = table[c["id"]]
        assert len(cells) == 6, cells
        _, said, values, ours, verdict, why = cells
        assert said == c["paper"]
        assert values == ", ".join(c["values"])
        assert verdict in VERDICTS, verdict
        assert ours, c["id"]
        if verdict in ("differs", "singular", "by construction", "not measured",
                       "not modelled"):
            assert why, f"{c['id']}: a {verdict} without its reason"


def test_docs_paper_states_the_verdict_rules_above_the_table() -> None:
    text = PAGE.read_text(encoding="utf-8")
    assert rules_text() in text.split("## Claims", 1)[0]
    for verdict in VERDICTS:
        assert f"**{verdict}**" in rules_text() or verdict in ("same setup", "other setup")


@pytest.mark.parametrize(("value", "paper", "stretch", "where"), [
    (1.3, 1.3, True, "within"), (1.3 + 0.3 * BAND * 0.99, 1.3, True, "within"),
    (1.3 - 0.3 * BAND * 0.99, 1.3, True, "within"), (1.15, 1.3, True, "below"),
    (1.6, 1.3, True, "above"),  # twice the paper's excess
    (0.7, 0.7, True, "within"), (0.91, 0.7, True, "below"), (0.4, 0.7, True, "above"),
    (0.30, 0.30, False, "within"), (0.612, 0.30, False, "above"), (0.2, 0.30, False, "below"),
])
def test_up_to_is_two_sided_and_never_passes_twice_the_papers_value(
        value: float, paper: float, stretch: bool, where: str) -> None:
    assert band(value, paper, stretch) == where
