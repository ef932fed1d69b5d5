"""The direction of dependence of ARCHITECTURE.md: sbmpc -> (dynamics, maps); dynamics and
maps never import each other nor sbmpc."""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def imported_packages(package):
    found = set()
    for path in (ROOT / package).rglob("*.py"):
        found |= imported_packages_of(path)
    return found


@pytest.mark.parametrize("package, forbidden", [("dynamics", {"maps", "sbmpc"}), ("maps", {"dynamics", "sbmpc"})])
def test_packages_depend_in_one_direction(package, forbidden):
    assert not imported_packages(package) & forbidden


def imported_packages_of(path):
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add(node.module.split(".")[0])
    return found


def test_import_linter_contracts_hold():
    """pyproject.toml's [tool.importlinter] contracts: the layers (commands, sweep, api,
    problems, search, then dynamics and maps), a search that knows no robot (but
    numba's cache guard, dynamics._jitcache), and no import cycle among a package's modules. import-linter's graph holds
    every import, those inside functions too (the check above reads module level only)."""
    pytest.importorskip("importlinter")
    import subprocess
    import sys
    out = subprocess.run([sys.executable, "-c", "from importlinter.cli import lint_imports_command; "
                          "lint_imports_command()"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-2000:]
    assert "0 broken" in out.stdout


def test_ruff_is_clean():
    """pyflakes and bugbear (pyproject.toml [tool.ruff.lint]) over the code, the tests and
    the benchmarks."""
    pytest.importorskip("ruff")
    import subprocess
    import sys
    out = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "."], cwd=ROOT, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-3000:]
