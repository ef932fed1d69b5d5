"""Reliability of the command line (issue 16): no input is ever replaced, output paths
are checked before the work, and every bad file or value ends in one line and exit 2
(an internal error in one line and exit 3), never a traceback. Each case asserts the
exit code, the single line and that the input files are unchanged."""
import hashlib
import shutil
from pathlib import Path

import pytest

from sbmpc.commands.cli import main

ROOT = Path(__file__).resolve().parents[1]
SCEN = ROOT / "scenarios"


def digest(folder: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.fixture()
def work(tmp_path):
    """A folder with the flat scenario, a vehicle file and a short synthetic run."""
    shutil.copy(SCEN / "flat.yaml", tmp_path / "s.yaml")
    (tmp_path / "t.yaml").write_text("base: p3at\nname: heavy\nmass: 40.0\n")
    assert main(["synth", "--effect", "none", "--duration", "5", "--out", str(tmp_path / "r.csv")]) == 0
    return tmp_path


def one_line_error(capsys, code, rc):
    err = capsys.readouterr().err.strip()
    assert rc == code, err
    assert "\n" not in err and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("argv, flag", [
    (["plan", "{w}/s.yaml", "--json", "{w}/s.yaml"], "--json"),
    (["plan", "{w}/s.yaml", "--rrd", "{w}/s.yaml"], "--rrd"),
    (["plan", "{w}/s.yaml", "--json", "{w}/./sub/../s.yaml"], "--json"),
    (["run", "{w}/s.yaml", "--json", "{w}/s.yaml"], "--json"),
    (["run", "{w}/s.yaml", "--truth", "{w}/t.yaml", "--json", "{w}/t.yaml"], "--json"),
    (["diagnose", "{w}/r.csv", "--json", "{w}/r.csv"], "--json"),
    (["diagnose", "{w}/r.csv", "--vehicle-out", "{w}/r.csv"], "--vehicle-out"),
    (["diagnose", "{w}/r.csv", "--vehicle", "{w}/extended_vehicle.yaml", "--json", "{w}/d.json"], "--json"),
    (["simulate", "--vehicle", "{w}/t.yaml", "--v", "0.5", "--json", "{w}/t.yaml"], "--json"),
    # a file reached through 'base:' is an input too (it was replaced)
    (["simulate", "--vehicle", "{w}/t2.yaml", "--v", "0.5", "--json", "{w}/t.yaml"], "--json"),
    (["run", "{w}/s.yaml", "--truth", "{w}/t2.yaml", "--json", "{w}/t.yaml"], "--json"),
])
def test_an_output_that_is_an_input_is_refused_before_any_work(work, capsys, argv, flag):
    (work / "t2.yaml").write_text("base: t.yaml\nname: heavier\nmass: 45.0\n")
    (work / "sub").mkdir()
    shutil.copy(work / "t.yaml", work / "extended_vehicle.yaml")
    before = digest(work)
    rc = main([a.format(w=work) for a in argv])
    err = one_line_error(capsys, 2, rc)
    assert flag in err and "is an input" in err
    assert digest(work) == before


@pytest.mark.parametrize("argv, says", [
    (["plan", "{s}", "--json", "{root}/README.md/x.json"], "is a file"),
    (["plan", "{s}", "--json", "{root}/docs"], "found the folder"),
    (["plan", "{s}", "--json", "{w}/no/such/x.json"], "no folder"),
    (["compare", "{s}", "--out", "{root}/README.md/x"], "is a file"),
    (["compare", "{s}", "--out", "{root}/README.md"], "expected a folder"),
    (["diagnose", "{w}/r.csv", "--report", "{root}/README.md"], "expected a folder"),
    (["diagnose", "{w}/r.csv", "--json", "{root}/docs"], "found the folder"),
    (["synth", "--effect", "none", "--out", "{root}/docs"], "found the folder"),
])
def test_bad_output_paths_end_in_one_line_before_the_work(work, capsys, argv, says):
    before = digest(ROOT)
    rc = main([a.format(w=work, s=work / "s.yaml", root=ROOT) for a in argv])
    assert says in one_line_error(capsys, 2, rc)
    assert digest(ROOT) == before and not (ROOT / "extended_vehicle.yaml").exists()


def test_two_outputs_on_one_path_and_an_empty_path_are_refused(work, capsys):
    """--json and --rrd on the same path (the recording replaced the JSON, exit 0), and an
    empty path (`--out ""` wrote into the current folder) end before any work."""
    rc = main(["plan", str(work / "s.yaml"), "--json", str(work / "x.json"), "--rrd", str(work / "x.json")])
    assert "--rrd: '" in one_line_error(capsys, 2, rc) and not (work / "x.json").exists()
    with pytest.raises(SystemExit) as exc:
        main(["compare", str(work / "s.yaml"), "--out", ""])
    assert exc.value.code == 2 and "--out: expected a path, found an empty string" in capsys.readouterr().err
    rc = main(["plan", str(work / "s.yaml"), "--goal="])
    assert "--goal: expected X,Y" in one_line_error(capsys, 2, rc)


def test_a_pipe_is_written_into_and_a_reader_that_leaves_changes_nothing(work):
    """An output that is a FIFO (or /dev/null) is written into, not replaced by a file
    (the atomic rename replaced /dev/null when run as root); a reader of stdout that
    goes away (`| true`) leaves the exit code and the files as they would be: an
    unreachable goal is exit 1 with its JSON (it was exit 0 and no file)."""
    import os
    import stat
    import subprocess
    import sys
    import threading
    fifo = work / "f.json"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_text()))
    reader.start()
    assert main(["simulate", "--v", "0.5", "--duration", "1", "--json", str(fifo)]) == 0
    reader.join(30)
    assert stat.S_ISFIFO(fifo.stat().st_mode) and '"schema": "sbmpc.simulate/1"' in got[0]
    from sbmpc.commands.files import Outputs, atomic
    assert Outputs().file(fifo, "--json") == fifo          # a pipe needs no writable folder, as /dev/null
    Outputs().file(Path(os.devnull), "--json")
    from sbmpc.errors import InputError
    with pytest.raises(InputError, match="the reader of the pipe went away"):   # a failed write is exit 2, not
        with atomic(fifo):                                                       # stdout's reader leaving (exit 0)
            raise BrokenPipeError(32, "Broken pipe")
    out = work / "u.json"
    p = subprocess.Popen([sys.executable, "-m", "sbmpc", "plan", str(SCEN / "unreachable.yaml"), "--json", str(out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()
    _, err = p.communicate(timeout=300)
    assert p.returncode == 1, err
    assert out.exists() and '"status": "no_path"' in out.read_text()
    q = subprocess.Popen([sys.executable, "-m", "sbmpc", "plan", str(work / "none.yaml")],       # `2>&1 | true`
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    q.stdout.close()
    assert q.wait(timeout=300) == 2              # bad input (it was 1: the error line could not be printed)


def test_every_json_output_is_strict_json(work, capsys):
    """A one-second run leaves a candidate's standard error undefined: the diagnosis JSON
    held a bare NaN, which strict JSON readers refuse; every number that is not finite is
    written as null."""
    import json
    from sbmpc.commands.files import _finite
    assert _finite({"a": [1.0, float("nan"), {"b": float("-inf")}], "c": "x"}) == {"a": [1.0, None, {"b": None}], "c": "x"}
    assert main(["synth", "--effect", "none", "--duration", "1", "--out", str(work / "short.csv")]) == 0
    assert main(["diagnose", str(work / "short.csv"), "--json", str(work / "d.json")]) == 0

    def refuse(c):
        raise ValueError(c)
    doc = json.loads((work / "d.json").read_text(), parse_constant=refuse)
    assert doc["cause"] == "none"
    assert "wrote " in capsys.readouterr().out


def test_an_unwritable_output_folder_is_refused(work, capsys):
    import os
    if os.geteuid() == 0:
        pytest.skip("root writes anywhere")
    ro = work / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        rc = main(["plan", str(work / "s.yaml"), "--json", str(ro / "p.json")])
        assert "permission denied" in one_line_error(capsys, 2, rc)
    finally:
        ro.chmod(0o700)


BILLION_LAUGHS = """\
name: laughs
a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]
b: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]
c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b]
d: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c]
e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d]
f: &f [*e, *e, *e, *e, *e, *e, *e, *e, *e]
g: &g [*f, *f, *f, *f, *f, *f, *f, *f, *f]
h: &h [*g, *g, *g, *g, *g, *g, *g, *g, *g]
description: *h
"""


FLAT = (SCEN / "flat.yaml").read_text()


@pytest.mark.parametrize("text, says", [
    (BILLION_LAUGHS, "aliases are not accepted"),
    (FLAT.replace("x: 2.0, y: 2.0", "x: " + "9" * 400 + ", y: 2.0"), "integer of 400 digits"),
    (FLAT.replace("resolution: 0.25", "resolution: " + "1" * 400), "resolution: expected a number"),
    (FLAT.replace("vehicle: p3at", "vehicle: " + "v" * 5000), "expected a shipped name"),
    (FLAT.replace("terrain: vinyl", "terrain: " + "v" * 5000), "expected a shipped name"),
    (FLAT.replace("resolution: 0.25", "resolution: 1e300"), "found '1e300' (text: YAML reads an exponent"),
    (FLAT.replace("x: 2.0, y: 2.0", "x: 2e0, y: 2.0"), "start.x: expected a number, found '2e0' (text:"),
    (FLAT + "planner: {max_expansions: 1}\n", "the key 'planner' appears twice in one mapping (first on line "
                                              f"{1 + [s.split(':')[0] for s in FLAT.splitlines()].index('planner')})"),
    (FLAT.replace("x: 2.0, y: 2.0", "x: 2.0, y: 2.0, x: 3.0"), "the key 'x' appears twice"),
    (FLAT.replace("x: 2.0, y: 2.0", "x: 2.0, y: 2.0, 1: 3, 1.0: 4"), "the key '1.0' appears twice in one mapping "
                                                                   "(first as '1' on line"),
])
def test_hostile_scenarios_end_in_one_line(tmp_path, capsys, text, says):
    s = tmp_path / "s.yaml"
    s.write_text(text)
    before = s.read_bytes()
    rc = main(["plan", str(s)])
    err = one_line_error(capsys, 2, rc)
    assert says in err and len(err) < 400
    assert s.read_bytes() == before


def test_a_map_in_no_allowed_form_is_named_once_without_its_whole_value(tmp_path, capsys):
    """origin beside generate: one line, from the map check, which says which key is
    wrong (the schema's "fits none of the forms" for the same key is left out), and
    never the mapping's repr."""
    s = tmp_path / "s.yaml"
    s.write_text(FLAT.replace("features: []}\n", "features: []}\n  origin: [.inf, 0]\n"))
    rc = main(["plan", str(s)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "Traceback" not in err
    assert "fits none of the forms" not in err and len(err.splitlines()) == 1
    assert "map.origin: expected no key beside 'generate'" in err and "{'generate'" not in err


def test_binary_and_special_files_are_named_as_such(tmp_path, capsys):
    png = ROOT / "docs" / "model.png"
    s = tmp_path / "s.yaml"
    s.write_bytes(png.read_bytes())
    assert "binary data" in one_line_error(capsys, 2, main(["plan", str(s)]))
    assert "found a folder" in one_line_error(capsys, 2, main(["plan", str(tmp_path)]))
    if Path("/dev/null").exists():
        assert "special file" in one_line_error(capsys, 2, main(["plan", "/dev/null"]))
    rc = main(["simulate", "--vehicle", str(png), "--v", "0.5"])
    assert "binary data" in one_line_error(capsys, 2, rc)


@pytest.mark.parametrize("argv, says", [
    (["plan", str(SCEN / "flat.yaml"), "--cost", "fast"], "sbmpc plan: error: --cost: expected one of 'time', 'energy', found 'fast'"),
    (["compare", str(SCEN / "flat.yaml"), "--device", "tpu"], "--device: expected one of 'cpu', 'cuda', found 'tpu'"),
    (["frobnicate"], "sbmpc: error: command: expected one of 'simulate', 'plan'"),
])
def test_a_wrong_choice_reads_like_every_other_bad_flag(capsys, argv, says):
    """argparse's "invalid choice" in the form of the other messages: the flag, what was
    expected, what was found; one line, exit 2."""
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and says in err and "invalid choice" not in err


@pytest.mark.parametrize("message", [
    "argument --cost: invalid choice: 'fast' (choose from 'time', 'energy')",     # Python 3.11
    "argument --cost: invalid choice: 'fast' (choose from time, energy)",         # 3.12.7+ (unquoted)
    "argument -c/--cost: invalid choice: 'fast' (choose from 'time', 'energy')",  # a flag with an alias
])
def test_the_wrong_choice_message_does_not_depend_on_the_python_version(capsys, message):
    from sbmpc.commands.cli import build_parser
    with pytest.raises(SystemExit) as e:
        build_parser().error(message)
    assert e.value.code == 2
    assert capsys.readouterr().err.strip() == "sbmpc: error: --cost: expected one of 'time', 'energy', found 'fast'"


def test_a_package_shadowed_by_left_over_folders_is_named_not_a_traceback(capsys, monkeypatch):
    """After a plain ``pip install .`` and an uninstall, numba's cache files keep folders
    of the package in site-packages; a later install is then shadowed by them (Python
    takes them for a namespace package: no __init__ runs, ``__version__`` is missing)
    and building the parser fails. One line names the folders, exit 3."""
    import sbmpc
    from sbmpc.commands import cli
    def shadowed():
        raise ImportError("cannot import name '__version__' from 'sbmpc' (unknown location)")
    monkeypatch.setattr(cli, "build_parser", shadowed)
    monkeypatch.setattr(sbmpc, "__file__", None)
    monkeypatch.setattr(sbmpc, "__path__", ["/site-packages/sbmpc"])
    err = one_line_error(capsys, 3, main(["--help"]))
    assert "shadowed" in err and "/site-packages/sbmpc" in err and "remove them" in err
    monkeypatch.undo()
    monkeypatch.setattr(cli, "build_parser", shadowed)
    err = one_line_error(capsys, 3, main(["--help"]))
    assert "incomplete" in err and "pip install -e ." in err


def test_an_internal_error_is_one_line_and_exit_3_and_debug_shows_it(work, capsys, monkeypatch):
    from sbmpc.planning import plan as PL
    from sbmpc.commands import compiling
    def broken(*a, **k):
        raise ZeroDivisionError("float division by zero")
    monkeypatch.setattr(PL, "plan", broken)
    # (the plan never runs, so numba's cache of the planner may stay cold whatever ran
    # before: its one-line compile note is not the error's)
    monkeypatch.setattr(compiling, "_cold", lambda functions: False)
    rc = main(["plan", str(work / "s.yaml")])
    err = one_line_error(capsys, 3, rc)
    assert "internal error: ZeroDivisionError" in err and "--debug" in err
    with pytest.raises(ZeroDivisionError):
        main(["plan", str(work / "s.yaml"), "--debug"])


def test_outputs_are_written_whole_or_not_at_all(tmp_path):
    from sbmpc.commands.files import atomic
    target = tmp_path / "p.json"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("interrupted")
    assert target.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["p.json"]
    with atomic(target) as tmp:
        tmp.write_text("new")
    assert target.read_text() == "new" and [p.name for p in tmp_path.iterdir()] == ["p.json"]


def _run_variant(work, name, edit_rows=None, meta_extra=(), header_extra=""):
    lines = (work / "r.csv").read_text().splitlines()
    h = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    cols = lines[h].split(",")
    rows = [r.split(",") for r in lines[h + 1:]]
    if edit_rows:
        rows = edit_rows(cols, rows)
    out = work / f"{name}.csv"
    out.write_text("\n".join(lines[:h] + list(meta_extra) + [lines[h] + header_extra] + [",".join(r) for r in rows]) + "\n")
    return out


def _set(col, f):
    def edit(cols, rows):
        j = cols.index(col)
        for k, r in enumerate(rows):
            r[j] = f(k)
        return rows
    return edit


@pytest.mark.parametrize("name, kw, says", [
    ("spread", dict(edit_rows=lambda c, r: _set("t", lambda k: f"{k * 1e4:g}")(c, r[:200])), "median sample spacing"),
    ("tiny", dict(edit_rows=_set("t", lambda k: f"{k * 1e-9:.12g}")), "median sample spacing"),
    ("huge_t", dict(edit_rows=_set("t", lambda k: f"{1e300 + k * 1e290:g}")), "finite number of at most 1e12"),
    ("no_cmd", dict(edit_rows=_set("wl_cmd", lambda k: "")), "column wl_cmd: expected numbers"),
    ("nan_wl", dict(edit_rows=_set("wl", lambda k: "nan")), "column wl: expected numbers"),
    ("slope_nan", dict(meta_extra=["# slope_deg: nan"]), "slope_deg"),
    ("slope_90", dict(meta_extra=["# slope_deg: 90"]), "slope_deg"),
    ("vehicle", dict(meta_extra=["# vehicle: nosuch"]), "vehicle.csv: its '# vehicle:' line: vehicle 'nosuch'"),
    ("terrain", dict(meta_extra=["# terrain: lava"]), "terrain.csv: its '# terrain:' line: terrain 'lava'"),
    ("seg_each_row", dict(edit_rows=lambda c, r: [x + [str(k)] for k, x in enumerate(r)], header_extra=",segment"),
     "segment of at least 20 samples"),
])
def test_hostile_runs_end_in_one_line_before_any_work(work, capsys, name, kw, says):
    path = _run_variant(work, name, **kw)
    before = path.read_bytes()
    rc = main(["diagnose", str(path)])
    assert says in one_line_error(capsys, 2, rc)
    assert path.read_bytes() == before


@pytest.mark.parametrize("argv, says", [
    (["diagnose", "{w}/r.csv", "--vehicle", "nosuch"], "--vehicle: vehicle 'nosuch'"),
    (["diagnose", "{w}/r.csv", "--terrain", "lava"], "--terrain: terrain 'lava'"),
    (["synth", "--effect", "none", "--out", "{w}/s.csv", "--seed", "-3"], "--seed: expected an integer in [0, 2147483647]"),
    (["synth", "--effect", "none", "--out", "{w}/s.csv", "--vehicle", "nosuch"], "--vehicle: vehicle 'nosuch'"),
])
def test_bad_diagnose_and_synth_options_are_named(work, capsys, argv, says):
    rc = main([a.format(w=work) for a in argv])
    assert says in one_line_error(capsys, 2, rc)
    assert not (work / "s.csv").exists()


def test_awkward_but_valid_runs_are_diagnosed(work, capsys):
    """A byte-order mark (spreadsheets), the least run (50 rows), all-zero wheel signals,
    every signal zero (nothing to explain: the baseline's error is 0) and a segment column
    with gaps: diagnosed, exit 0, no traceback."""
    bom = work / "bom.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + (work / "r.csv").read_bytes())
    short = _run_variant(work, "short", edit_rows=lambda c, r: r[:50])
    zeros = _run_variant(work, "zeros", edit_rows=lambda c, r: _set("wl", lambda k: "0")(c, _set("wr", lambda k: "0")(
        c, _set("wl_cmd", lambda k: "0")(c, _set("wr_cmd", lambda k: "0")(c, r)))))
    allzero = _run_variant(work, "allzero", edit_rows=lambda c, r: [[x[0]] + ["0"] * (len(x) - 1) for x in r])
    gaps = _run_variant(work, "gaps", edit_rows=lambda c, r: [x + ["" if k % 7 else "1"] for k, x in enumerate(r)],
                        header_extra=",segment")
    for path in (bom, short, zeros, allzero, gaps):
        rc = main(["diagnose", str(path)])
        out = capsys.readouterr()
        assert rc == 0 and "Traceback" not in out.err, (path.name, out.err)
        if path is allzero:
            assert "cause: none" in out.out, out.out
    from dynamics.runs import read_run
    assert len(read_run(gaps).segments()) == 1           # gaps in the column continue the segment


# ---- fuzzing: random mutations of a valid scenario and run CSV -------------------------
from hypothesis import HealthCheck, given, settings, strategies as st  # noqa: E402

_VALUES = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6), st.integers(-10**400, 10**400),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
                    st.lists(st.integers(-5, 30), max_size=5), st.dictionaries(st.text(max_size=5), st.integers(), max_size=3))
_PATHS = st.sampled_from([("name",), ("map",), ("map", "generate"), ("map", "generate", "size"),
                          ("map", "generate", "resolution"), ("map", "generate", "features"), ("terrain",),
                          ("vehicle",), ("start",), ("start", "x"), ("start", "v"), ("goal",), ("goal", "radius"),
                          ("goal", "x"), ("cost",), ("planner",), ("planner", "branching"), ("planner", "dt"),
                          ("planner", "cell_xy"), ("planner", "wheel_speeds"), ("run",), ("run", "trigger"),
                          ("extra_key",)])


@pytest.fixture()
def memory_cap():
    """Each fuzzed case runs with at most 2 GiB of address space more than the test
    process already holds (soft RLIMIT_AS, never raised, restored afterwards; Linux
    only)."""
    try:
        import resource
        size = next(int(line.split()[1]) * 1024 for line in Path("/proc/self/status").read_text().splitlines()
                    if line.startswith("VmSize:"))
    except (ImportError, OSError, StopIteration):
        yield None
        return
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    cap = size + (2 << 30)
    for limit in (soft, hard):
        if limit != resource.RLIM_INFINITY:
            cap = min(cap, limit)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    try:
        yield cap
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(edits=st.lists(st.tuples(_PATHS, _VALUES), min_size=1, max_size=3))
def test_fuzzed_scenarios_never_crash(tmp_path, capsys, memory_cap, edits):
    """Random values at random keys of the flat scenario: exit 0 (still valid), 1 (no
    path) or 2 (one message naming the problems); never 3 or a traceback, and the file
    is left as it was. Plans are cut to 200 expansions and 10 s; memory is capped
    (``memory_cap``): an input that blows up memory ends in an out-of-memory line,
    which fails the test."""
    import copy
    import yaml
    doc = copy.deepcopy(yaml.safe_load((SCEN / "flat.yaml").read_text()))
    for path, value in edits:
        node = doc
        for k in path[:-1]:
            if not isinstance(node.get(k), dict):
                node[k] = {}
            node = node[k]
        node[path[-1]] = value
    s = tmp_path / "fuzz.yaml"
    try:
        s.write_text(yaml.safe_dump(doc))
    except (ValueError, OverflowError):
        return
    before = s.read_bytes()
    rc = main(["plan", str(s), "--quiet", "--max-expansions", "200", "--time-budget", "10"])
    err = capsys.readouterr().err
    assert rc in (0, 1, 2), err
    assert "Traceback" not in err and "internal error" not in err and "out of memory" not in err
    assert s.read_bytes() == before


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(row=st.integers(0, 60), col=st.sampled_from(["t", "wl_cmd", "wr_cmd", "wl", "wr", "x", "yaw"]),
       value=st.one_of(st.sampled_from(["", "nan", "inf", "-inf", "1e308", "abc", "0x10", "1,2", '"', "\x00"]),
                       st.floats(allow_nan=True, allow_infinity=True).map(repr)))
def test_fuzzed_run_csvs_never_crash(tmp_path, capsys, memory_cap, row, col, value):
    """One cell of a synthetic run replaced by junk: diagnosed (0) or one message (2)."""
    src = tmp_path / "r.csv"
    if not src.exists():
        assert main(["synth", "--effect", "none", "--duration", "3", "--out", str(src)]) == 0
        capsys.readouterr()
    lines = src.read_text().splitlines()
    h = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    cols = lines[h].split(",")
    if col not in cols:
        return
    k = min(h + 1 + row, len(lines) - 1)
    cells = lines[k].split(",")
    cells[cols.index(col)] = value
    lines[k] = ",".join(cells)
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    rc = main(["diagnose", str(bad)])
    err = capsys.readouterr().err
    assert rc in (0, 2), err
    assert "Traceback" not in err and "internal error" not in err and "out of memory" not in err


# ---- under an OS memory cap: the inputs that once took gigabytes -------------------------
MEMORY_CAP = 3 << 30          # bytes of address space (a warm plan of flat.yaml peaks at ~0.7 GB)

_CAPPED = r'''
import json, resource, sys, io, contextlib
soft, hard = resource.getrlimit(resource.RLIMIT_AS)
cap = int(sys.argv[1]) if hard == resource.RLIM_INFINITY else min(int(sys.argv[1]), hard)
resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
from sbmpc.commands.cli import main
out = []
for argv in json.loads(sys.argv[2]):
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = main(argv)
    out.append([rc, err.getvalue().strip()])
print(json.dumps(out))
'''


@pytest.mark.skipif(not hasattr(__import__("os"), "fork") or not Path("/proc").is_dir(),
                    reason="RLIMIT_AS caps need Linux")
def test_inputs_that_took_gigabytes_end_in_one_line_under_a_3_gb_cap(work):
    """Issue 16's memory cases, in a child process whose address space is capped at
    3 GiB: nested YAML aliases (2 GB and 30 s before), a 200-row run spanning 2e6 s
    (24 GB), samples 1 ns apart (a hang), a 3600 s simulation at 10 us (over 5 GB), a
    generated map of 4e8 cells. Each ends in exit 2 with one line that names the limit
    it met (not an out-of-memory message), and no input changes."""
    import json
    import subprocess
    import sys
    (work / "laughs.yaml").write_text(BILLION_LAUGHS)
    spread = _run_variant(work, "spread", edit_rows=lambda c, r: _set("t", lambda k: f"{k * 1e4:g}")(c, r[:200]))
    tiny = _run_variant(work, "tiny", edit_rows=_set("t", lambda k: f"{k * 1e-9:.12g}"))
    (work / "big.yaml").write_text(FLAT.replace("size: [20, 12], resolution: 0.25", "size: [2000, 2000], resolution: 0.1"))
    cases = [
        (["plan", str(work / "laughs.yaml")], "aliases are not accepted"),
        (["diagnose", str(spread)], "median sample spacing"),
        (["diagnose", str(tiny)], "median sample spacing"),
        (["simulate", "--duration", "3600", "--dt", "1e-5", "--v", "0.5"], "steps"),
        (["plan", str(work / "big.yaml")], "cells"),
    ]
    before = digest(work)
    r = subprocess.run([sys.executable, "-c", _CAPPED, str(MEMORY_CAP), json.dumps([a for a, _ in cases])],
                       capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
    results = json.loads(r.stdout.strip().splitlines()[-1])
    for (argv, says), (rc, err) in zip(cases, results):
        assert rc == 2 and "\n" not in err and says in err, (argv, rc, err)
        assert "memory" not in err.lower(), (argv, err)
    assert digest(work) == before
