"""numba's cache kept consistent across files (dynamics/_cache.py)."""
from pathlib import Path

from dynamics import _cache as C


def _tree(root: Path) -> dict:
    (root / "dynamics" / "__pycache__").mkdir(parents=True)
    (root / "sbmpc" / "search" / "__pycache__").mkdir(parents=True)
    (root / "dynamics" / "kernels.py").write_text("NS = 30\n")
    (root / "sbmpc" / "search" / "loop.py").write_text("def f(): pass\n")
    (root / "sbmpc" / "plan.py").write_text("x = 1\n")        # not compiled code
    return {"kernels": root / "dynamics" / "__pycache__", "loop": root / "sbmpc" / "search" / "__pycache__"}


def _entries(dirs: dict) -> list[Path]:
    made = []
    for stem, d in dirs.items():
        for ext in ("nbi", "nbc"):
            p = d / f"{stem}._step-341.py311.{ext}"
            p.write_bytes(b"x")
            made.append(p)
    return made


def test_a_changed_source_clears_the_cache_of_every_compiled_file(tmp_path):
    """The hazard: kernels.py's state layout changes, loop.py's does not; numba would
    keep loop's compiled code (built against the old layout). A refresh clears both
    files' entries once, leaves the byte code and foreign entries alone, and then keeps
    the cache while nothing changes."""
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


def test_every_file_with_compiled_code_is_a_source():
    """A new module with numba functions outside SOURCES would escape the refresh."""
    listed = set(C.sources())
    compiled = {p for pkg in ("dynamics", "maps", "sbmpc") for p in (C.ROOT / pkg).rglob("*.py")
                if "njit" in p.read_text() or "from ._jit import" in p.read_text()}
    assert compiled and compiled <= listed, sorted(str(p) for p in compiled - listed)
