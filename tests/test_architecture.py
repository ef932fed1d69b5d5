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


def sbmpc_imports(path):
    """The sbmpc modules a file imports, as dotted names below ``sbmpc`` (relative
    imports resolved)."""
    rel = path.relative_to(ROOT / "sbmpc").with_suffix("")
    here = list(rel.parts[:-1])
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[:len(here) - (node.level - 1)] if node.level > 1 else here
                mod = ".".join(base + ([node.module] if node.module else []))
                names = [mod + "." + a.name if not node.module else mod for a in node.names]
                found |= {n.strip(".") for n in names}
            elif node.module and node.module.startswith("sbmpc"):
                found.add(node.module[len("sbmpc."):])
        elif isinstance(node, ast.Import):
            found |= {a.name[len("sbmpc."):] for a in node.names if a.name.startswith("sbmpc.")}
    return found


# LAYOUT: commands -> plan/receding -> check -> problem -> world/heuristics -> problems -> search; the search
# knows no robot, no map and no model; nothing below the commands imports them
RULES = [
    ("search", {"problems", "commands", "plan", "world", "heuristics", "receding", "problem", "check",
                "trajectory"}, {"dynamics", "maps"}),
    ("problems", {"commands", "plan", "world", "heuristics", "receding", "problem", "check"}, set()),
    ("world.py", {"commands", "plan", "heuristics", "receding", "problem", "check"}, set()),
    ("heuristics.py", {"commands", "plan", "receding", "problem", "check"}, set()),
    ("problem.py", {"commands", "plan", "receding", "check"}, set()),
    ("check.py", {"commands", "plan", "receding"}, set()),
    ("trajectory.py", {"commands", "plan", "receding", "problem", "check", "search", "problems"}, set()),
    ("plan.py", {"commands", "receding"}, set()),
]


@pytest.mark.parametrize("where, inside, outside", RULES)
def test_sbmpc_layers_point_down(where, inside, outside):
    target = ROOT / "sbmpc" / where
    files = [target] if target.is_file() else sorted(target.rglob("*.py"))
    assert files
    for path in files:
        bad = {m for m in sbmpc_imports(path) if m.split(".")[0] in inside}
        assert not bad, f"{path.relative_to(ROOT)} imports {sorted(bad)}"
        ext = imported_packages_of(path) & outside
        assert not ext, f"{path.relative_to(ROOT)} imports {sorted(ext)}"


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
    problems, search, then dynamics and maps, then _jitcache), a search that knows no
    robot, and no import cycle among a package's modules. import-linter's graph holds
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
