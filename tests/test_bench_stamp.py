"""Every benchmark stamps its own results file (bench/stamp.py): the date, the commit of
the code it measured, the machine. A rerun is never undated."""
from __future__ import annotations

import ast
import importlib.util
import json
import time
from fractions import Fraction
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("bench_stamp", ROOT / "bench" / "stamp.py")
stamp = importlib.util.module_from_spec(spec)
spec.loader.exec_module(stamp)

# json.dumps whose text is no results file: the closed-loop sweep's spec (YAML, written as JSON)
NOT_RESULTS = {("bench_closed_loop.py", "spec_text")}


def _unstamped_writes(source: str, name: str = "<snippet>") -> list[str]:
    """Where ``source`` writes JSON other than through stamp.write: a json.dump, or a
    json.dumps whose text goes anywhere but print() (into write_text directly or through
    a variable)."""
    tree = ast.parse(source)
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}

    def ancestors(node):
        while node in parents:
            node = parents[node]
            yield node

    def is_json(call, attr):
        f = call.func
        return isinstance(f, ast.Attribute) and f.attr == attr and isinstance(f.value, ast.Name) and f.value.id == "json"

    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        if is_json(node, "dump"):
            found.append(f"{name}:{node.lineno}: json.dump")
        elif is_json(node, "dumps"):
            up = list(ancestors(node))
            printed = any(isinstance(a, ast.Call) and isinstance(a.func, ast.Name) and a.func.id == "print" for a in up)
            exempt = any(isinstance(a, ast.FunctionDef) and (name, a.name) in NOT_RESULTS for a in up)
            if not (printed or exempt):
                found.append(f"{name}:{node.lineno}: json.dumps not printed (a results file not through stamp.write?)")
    return found


def test_the_check_catches_a_results_file_written_by_hand():
    assert _unstamped_writes("import json\nOUT.write_text(json.dumps(res, indent=1))\n")
    assert _unstamped_writes("import json\ntext = json.dumps(res, indent=1)\nout.write_text(text)\n")
    assert _unstamped_writes("import json\nwith open(p, 'w') as f:\n    json.dump(res, f)\n")
    assert not _unstamped_writes("import json\nprint(name, json.dumps(row), flush=True)\nstamp.write(OUT, res)\n")


def test_every_bench_script_writes_its_results_through_stamp_write():
    scripts = [p for p in sorted((ROOT / "bench").glob("*.py")) if p.name != "stamp.py"]
    assert len(scripts) > 20
    found = [f for p in scripts for f in _unstamped_writes(p.read_text(), p.name)]
    assert not found, "write results files with bench/stamp.write:\n" + "\n".join(found)


def _today_or_so(before: str) -> set[str]:
    return {before, time.strftime("%Y-%m-%d")}     # a test that runs across midnight


def test_write_stamps_date_commit_machine_first_and_keeps_the_docs_own(tmp_path):
    before = time.strftime("%Y-%m-%d")
    doc = {"what": "a benchmark", "rows": [{"a": 1}, {"a": 2}], "half": Fraction(1, 2)}
    path = stamp.write(tmp_path / "r.json", doc, default=float)
    assert path == tmp_path / "r.json"
    text = path.read_text()
    got = json.loads(text)
    assert got["date"] in _today_or_so(before)
    assert isinstance(got["commit"], str)
    if (ROOT / ".git").exists():
        assert got["commit"]
    assert got["machine"] and got["python"]
    assert list(got)[:2] == ["date", "commit"]
    assert got["what"] == "a benchmark" and got["rows"] == [{"a": 1}, {"a": 2}] and got["half"] == 0.5
    assert text.startswith("{\n \"date\"") and not text.endswith("\n")     # indent=1 by default
    assert doc["date"] == got["date"]                                       # the caller's doc has the stamps


def test_write_does_not_overwrite_the_docs_own_stamps(tmp_path):
    doc = {"machine": "cray", "date": "2020-01-02", "rows": []}
    got = json.loads(stamp.write(tmp_path / "r.json", doc, started="abc1234+", newline=True).read_text())
    assert got["date"] == "2020-01-02" and got["machine"] == "cray" and got["commit"] == "abc1234+"
    assert list(got)[:2] == ["date", "commit"]
    assert (tmp_path / "r.json").read_text().endswith("}\n")
    own = json.loads(stamp.write(tmp_path / "s.json", {"commit": "f00"}).read_text())
    assert own["commit"] == "f00"


def test_a_file_rewritten_from_its_rows_keeps_the_commit_that_stored_them():
    """stamp.stored: the date and commit of the last commit that stored a results file
    (what a --replot keeps where the file has no stamps of its own), {} for a file git
    does not know."""
    import re
    import subprocess
    path = ROOT / "bench" / "results" / "margin_curve.json"
    if not (ROOT / ".git").exists():
        pytest.skip("no git repository")
    s = stamp.stored(path)
    want = subprocess.run(["git", "log", "-1", "--format=%h", "--", str(path)], cwd=ROOT, capture_output=True,
                          text=True).stdout.strip()
    assert s["commit"] == want and re.fullmatch(r"\d{4}-\d{2}-\d{2}", s["date"])
    assert stamp.stored(ROOT / "bench" / "results" / "no_such_file.json") == {}
