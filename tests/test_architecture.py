"""The direction of dependence of ARCHITECTURE.md: sbmpc -> (dynamics, maps); dynamics and
maps never import each other nor sbmpc."""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def imported_packages(package):
    found = set()
    for path in (ROOT / package).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(node.module.split(".")[0])
    return found


@pytest.mark.parametrize("package, forbidden", [("dynamics", {"maps", "sbmpc"}), ("maps", {"dynamics", "sbmpc"})])
def test_packages_depend_in_one_direction(package, forbidden):
    assert not imported_packages(package) & forbidden
