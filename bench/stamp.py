"""Where a benchmark's numbers come from: the measured code's commit, the date, the
machine. Every bench script writes its results file through ``write``, so a rerun is
never undated."""
from __future__ import annotations

import json
import platform
import subprocess
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


CODE = ("sbmpc", "dynamics", "maps", "bench/*.py", "scenarios")


def commit() -> str:
    """The short hash of HEAD, with '+' where the code (not the results or the docs) has
    changed since. Call it when the benchmark starts: the code it loaded. '' where there
    is no git (or no repository: a copy of the working tree)."""
    def run(*a):
        try:
            return subprocess.run(["git", *a], cwd=ROOT, capture_output=True, text=True).stdout.strip()
        except OSError:
            return ""
    head = run("rev-parse", "--short", "HEAD")
    return head + ("+" if head and run("status", "--porcelain", "--untracked-files=no", "--", *CODE) else "")


STARTED = commit()      # taken when a benchmark first imports this module: the code it loaded


def stored(path) -> dict:
    """{"date", "commit"} of the last commit that stored ``path`` (a results file written
    before its script stamped it: rewritten from its own rows, it keeps when they were
    measured, not today's date); {} where git does not know the file."""
    try:
        out = subprocess.run(["git", "log", "-1", "--format=%cs %h", "--", str(path)], cwd=ROOT,
                             capture_output=True, text=True).stdout.split()
    except OSError:
        return {}
    return {"date": out[0], "commit": out[1]} if len(out) == 2 else {}


def write(path, doc: dict, *, started: str | None = None, newline: bool = False, **dumps) -> Path:
    """Write the results ``doc`` to ``path`` as JSON (``dumps``: json.dumps's keywords,
    indent=1 unless given; ``newline``: end the file with one), stamped with what the
    doc does not say itself: "date" (today), "commit" (``started``, the commit a script
    took at its start, else this module's STARTED), "machine" and "python". The stamps
    come first in the file; the doc's own values are kept (a "date" of its own is not
    overwritten). ``doc`` gets the stamps too, for a caller that goes on using it.
    Returns the path."""
    doc.setdefault("date", time.strftime("%Y-%m-%d"))
    doc.setdefault("commit", started or STARTED)
    doc.setdefault("machine", platform.processor() or platform.machine())
    doc.setdefault("python", platform.python_version())
    first = {k: doc[k] for k in ("date", "commit", "machine", "python")}
    dumps.setdefault("indent", 1)
    path = Path(path)
    path.write_text(json.dumps({**first, **doc}, **dumps) + ("\n" if newline else ""))
    return path
