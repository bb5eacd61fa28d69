"""The main job: ``brainbulge demo --quick`` writes a report whose figures and tables exist."""

from __future__ import annotations

import re


def test_demo_quick_report(quick_demo) -> None:
    rc, out = quick_demo
    assert rc == 0
    report = (out / "report.md").read_text()
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", report)
    assert len(images) >= 8
    for img in images:
        assert (out / img).is_file() and (out / img).stat().st_size > 1000, img
    assert "| headline_noslip |" in report and "failed" not in report
    assert "| left-flap_left-swelling |" in report
    for sub in ("headline", "sweep", "brain"):
        assert (out / sub / "table.csv").is_file()
        assert (out / sub / "study.json").is_file()
