"""numba's cache kept consistent across files (dynamics._jitcache)."""
import ast
from pathlib import Path

from dynamics import _jitcache as C


def _tree(root: Path) -> dict:
    (root / "dynamics" / "__pycache__").mkdir(parents=True)
    (root / "sbmpc" / "search" / "__pycache__").mkdir(parents=True)
    (root / "dynamics" / "kernels.py").write_text("NS = 30\n")
    (root / "sbmpc" / "search" / "loop.py").write_text("def f(): pass\n")
    (root / "sbmpc" / "plan.py").write_text("x = 1\n")        # not compiled code
    return {"kernels": root / "dynamics" / "__pycache__", "loop": root / "sbmpc" / "search" / "__pycache__"}


def _entries(dirs: dict) -> list[Path]:
    """Cache entries named as numba names them (module stem, function, line, version)."""
    made = []
    for stem, d in dirs.items():
        d.mkdir(parents=True, exist_ok=True)
        for name in (f"{stem}._step-341.py311.nbi", f"{stem}._step-341.py311.1.nbc"):
            (d / name).write_bytes(b"x")
            made.append(d / name)
    return made


def test_a_changed_source_clears_the_cache_of_every_compiled_file(tmp_path, monkeypatch):
    """The hazard: kernels.py's state layout changes, loop.py's does not; numba would
    keep loop's compiled code (built against the old layout). A refresh clears both
    files' entries once, leaves the byte code and foreign entries alone, and then keeps
    the cache while nothing changes."""
    from numba.core import config
    monkeypatch.setattr(config, "CACHE_DIR", "")
    dirs = _tree(tmp_path)
    pyc = dirs["kernels"] / "kernels.cpython-311.pyc"
    pyc.write_bytes(b"x")
    other = dirs["kernels"] / "elsewhere.f-1.py311.nbi"          # not one of the sources
    other.write_bytes(b"x")
    made = _entries(dirs)
    assert C.refresh(tmp_path) is True                # no stamp: what they were built from is unknown
    assert not any(p.exists() for p in made) and pyc.exists() and other.exists()
    made = _entries(dirs)
    assert C.refresh(tmp_path) is False               # unchanged: kept
    assert all(p.exists() for p in made)
    (tmp_path / "sbmpc" / "plan.py").write_text("x = 2\n")
    assert C.refresh(tmp_path) is False               # plain Python changed: kept
    (tmp_path / "dynamics" / "kernels.py").write_text("NS = 33\n")
    assert C.refresh(tmp_path) is True                # one compiled source changed: every entry goes
    assert not any(p.exists() for p in made)
    assert (dirs["kernels"] / C.STAMP).read_text().strip() == C.digest(C.sources(tmp_path), tmp_path)


def test_a_fresh_checkout_stamps_the_folder_numba_is_about_to_fill(tmp_path, monkeypatch):
    """No __pycache__ yet (a fresh clone, or a tree whose byte code went elsewhere): the
    first refresh creates the folder numba will cache in and stamps it, so the entries
    this run writes are kept by the next one (in __pycache__ and under a fresh
    $NUMBA_CACHE_DIR alike). Without it, the next run found entries
    without a stamp, deleted them and compiled everything again."""
    from numba.core import config
    monkeypatch.setattr(config, "CACHE_DIR", "")
    root = tmp_path / "src"
    (root / "dynamics").mkdir(parents=True)
    (root / "dynamics" / "kernels.py").write_text("NS = 35\n")
    assert C.refresh(root) is False
    made = _entries({"kernels": root / "dynamics" / "__pycache__"})      # what the run compiles
    assert C.refresh(root) is False and all(p.exists() for p in made)
    # the same with $NUMBA_CACHE_DIR pointing at a folder that does not exist yet
    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path / "fresh-cache"))
    assert C.refresh(root) is False
    made = _entries({"kernels": C.cache_dirs(root / "dynamics" / "kernels.py")[1]})
    assert C.refresh(root) is False and all(p.exists() for p in made)


def test_numba_cache_dir_is_refreshed_on_its_own_stamp(tmp_path, monkeypatch):
    """With $NUMBA_CACHE_DIR numba keeps every entry there, in its own layout; a stamp
    written elsewhere (a run without the variable) must not vouch for it."""
    from numba.core import config
    monkeypatch.setattr(config, "CACHE_DIR", "")
    src = tmp_path / "src"
    _tree(src)
    assert C.refresh(src) is False                    # the __pycache__ folders: stamped, nothing to delete
    cache = tmp_path / "cache"
    monkeypatch.setattr(config, "CACHE_DIR", str(cache))
    dirs = {f.stem: C.cache_dirs(f)[1] for f in C.sources(src)}
    assert all(str(d).startswith(str(cache)) for d in dirs.values())
    made = _entries(dirs)
    assert C.refresh(src) is True and not any(p.exists() for p in made)
    made = _entries(dirs)
    assert C.refresh(src) is False and all(p.exists() for p in made)


def test_every_file_with_compiled_code_is_a_source():
    """A new module with numba functions outside SOURCES would escape the refresh."""
    listed = set(C.sources())
    compiled = {p for pkg in ("dynamics", "maps", "sbmpc") for p in (C.ROOT / pkg).rglob("*.py")
                if "njit" in p.read_text() or "from ._jit import" in p.read_text()}
    assert compiled and compiled <= listed, sorted(str(p) for p in compiled - listed)


def test_the_guard_imports_no_layer_and_every_layer_calls_it_first():
    """The guard lives in dynamics (the lowest layer whose compiled code spans files) and
    imports nothing of dynamics, maps or sbmpc (relative imports included); each package
    whose compiled code spans files calls it before any of its compiled modules load.
    maps needs none: its compiled code is one file that imports nothing compiled from
    another (numba's own per-file index keeps it right)."""
    assert Path(C.__file__).parent == C.ROOT / "dynamics"
    tree = ast.parse(Path(C.__file__).read_text())
    assert not any(isinstance(n, ast.ImportFrom) and n.level > 0 for n in ast.walk(tree))
    imported = {(n.module or "").split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    imported |= {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert not imported & {"dynamics", "maps", "sbmpc"}
    for init, module in (("dynamics", "_jitcache"), ("sbmpc/search", "dynamics._jitcache"),
                         ("sbmpc/problems", "dynamics._jitcache"), ("sbmpc/planning", "dynamics._jitcache")):
        body = ast.parse((C.ROOT / init / "__init__.py").read_text()).body
        stmts = [s for s in body if not (isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant))]
        assert isinstance(stmts[0], ast.ImportFrom) and stmts[0].module == module, init
        assert ast.unparse(stmts[1]) == "refresh_once()", init
    compiled = [p for p in (C.ROOT / "maps").glob("*.py") if "njit" in p.read_text()]
    assert compiled == [C.ROOT / "maps" / "grid.py"]
    tree = ast.parse(compiled[0].read_text())
    assert {(n.module or "") for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)} <= {"__future__", "dataclasses", "numba"}
    assert {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names} <= {"math", "numpy"}


def test_a_cold_cache_is_announced_by_every_command_that_compiles(monkeypatch, capsys, tmp_path):
    """plan, compare and run said that the first run compiles; simulate, synth and
    diagnose sat silent for a minute. With numba's index file missing each says so in one
    line on stderr; with it present nothing is said."""
    from types import SimpleNamespace
    from sbmpc.commands import compiling
    from sbmpc.commands.cli import main

    def compiled(index):                                   # a function as numba's cache sees it
        return SimpleNamespace(_cache=SimpleNamespace(_cache_file=SimpleNamespace(_index_path=str(index))))
    (tmp_path / "cached.nbi").write_bytes(b"x")
    assert compiling._cold((compiled(tmp_path / "cached.nbi"),)) is False
    assert compiling._cold((compiled(tmp_path / "cached.nbi"), compiled(tmp_path / "missing.nbi"))) is True
    assert compiling._cold((object(),)) is False           # numba's internals moved: nothing is said
    monkeypatch.setattr(compiling, "_cold", lambda functions: True)
    csv = tmp_path / "run.csv"
    for argv in (["simulate", "--v", "0.5", "--duration", "1"],
                 ["synth", "--effect", "none", "--seed", "1", "--duration", "5", "--out", str(csv)]):
        assert main(argv) == 0
        err = capsys.readouterr().err
        assert err.count("compiling the vehicle model (first run only") == 1, (argv, err)
    monkeypatch.setattr(compiling, "_cold", lambda functions: False)
    assert main(["simulate", "--v", "0.5", "--duration", "1"]) == 0
    assert "compiling" not in capsys.readouterr().err


def test_a_bad_option_is_refused_before_the_compile_note(monkeypatch, capsys):
    """simulate checks every option before it says it compiles (a bad --length printed
    the note, then the error: two lines; a ramp with --open-loop was refused only after
    the ramp was simulated)."""
    from sbmpc.commands import compiling
    from sbmpc.commands.cli import main
    monkeypatch.setattr(compiling, "_cold", lambda functions: True)
    for argv in (["simulate", "--v", "1", "--slope-deg", "10", "--v0", "1", "--length", "1e300"],
                 ["simulate", "--v", "1", "--slope-deg", "10", "--v0", "1", "--length", "2", "--open-loop"],
                 ["simulate", "--v", "1", "--radius", "0"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert "compiling" not in err and "\n" not in err, (argv, err)


def test_the_models_step_compiles_once_for_the_simulator_and_the_planner():
    """numba compiles a function once per distinct argument type, and a literal True or
    False, or a read-only array, is a type of its own: the model's step compiled four
    times (87 s of a fresh clone's first compile). Driven by the simulator closed and
    open loop, at the controller rate and at a coarse step (the checked one), and by the
    planner's edges, it has one signature."""
    import numpy as np

    from dynamics import kernels as K
    from dynamics.params import load_terrain, load_vehicle
    from dynamics.simulate import Model, simulate
    from sbmpc.api import load_world
    from sbmpc.planning import plan as PL
    v, t = load_vehicle("p3at"), load_terrain("vinyl")
    cmd = np.full(200, 4.0)
    simulate(Model(v, t, 0.001), cmd, cmd)
    simulate(Model(v, t, 0.001), cmd, cmd, open_loop=True)
    simulate(Model(v, t, 0.05), cmd[:20], -cmd[:20])
    assert PL.plan(load_world(str(C.ROOT / "scenarios" / "flat.yaml")), "time").found
    # (a callee compiled inside a caller numba loaded from its cache is not in the
    # callee's own dispatcher: its overloads are the ones numba's cache index lists)
    for fn in (K._step, K.step_slope):
        sigs = [key[0] for key in fn._cache._cache_file._load_index()]
        assert len(sigs) == 1, (fn.__name__, sigs)
