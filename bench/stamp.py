"""Where a benchmark's numbers come from: the measured code's commit."""
from __future__ import annotations

import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


CODE = ("sbmpc", "dynamics", "maps", "bench/*.py", "scenarios")


def commit() -> str:
    """The short hash of HEAD, with '+' where the code (not the results or the docs) has
    changed since. Call it when the benchmark starts: the code it loaded."""
    run = lambda *a: subprocess.run(["git", *a], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    return run("rev-parse", "--short", "HEAD") + ("+" if run("status", "--porcelain", "--untracked-files=no",
                                                               "--", *CODE) else "")
