"""Numbers that stay true (issue 63): every generated block of the docs is what
bench/report.py writes from bench/results/*.json, and the script finds every block."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("report", ROOT / "bench" / "report.py")
report = importlib.util.module_from_spec(spec)
spec.loader.exec_module(report)


@pytest.mark.parametrize("page", report.PAGES, ids=lambda p: p.name)
def test_each_generated_block_is_what_its_results_file_gives(page):
    text = page.read_text()
    assert report.updated(text) == text, f"{page.name}: run python bench/report.py (its numbers are not the files')"


def test_every_block_is_on_a_page_and_an_edit_of_a_number_is_caught():
    names = {m.group("name") for p in report.PAGES for m in report.MARK.finditer(p.read_text())}
    assert names == set(report.BLOCKS)
    text = (ROOT / "docs" / "robustness.md").read_text()
    m = report.MARK.search(text)
    edited = text[:m.start("body")] + m.group("body").replace("runs", "runs!", 1) + text[m.end("body"):]
    assert report.updated(edited) != edited
