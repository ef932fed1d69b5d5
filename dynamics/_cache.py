"""numba's on-disk cache, kept consistent across files.

numba keys a cached function on its own file only: a compiled function keeps the
module constants and the inlined callees of *other* files it was compiled with. After
an update that changes ``dynamics/kernels.py`` (say, the state layout ``NS``) but not
``sbmpc/problems/skidsteer.py``, the search would load a skid-steer expansion compiled
against the old layout and plan silently wrong (seen once: no path on a 2 % grade).
So the first import of a package with compiled code (``dynamics``, ``maps``,
``sbmpc.search``, ``sbmpc.problems``) calls :func:`refresh`: it hashes the sources of
every file the compiled code is built from and, where that differs from the stamp
left by the last refresh, deletes those files' cache entries (numba then compiles
them again, once) and writes the new stamp. A clean checkout or a fresh install has
no cache and loses nothing.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# the files the compiled code is built from (the compiled functions and the constants
# and helpers they read), relative to ROOT
SOURCES = ("dynamics", "maps", "sbmpc/search", "sbmpc/problems", "sbmpc/heuristics.py")
STAMP = "sbmpc-numba-sources.sha1"

_done = False


def sources(root: Path = ROOT) -> list[Path]:
    """The Python files of :data:`SOURCES` under ``root``, sorted."""
    out = []
    for rel in SOURCES:
        p = root / rel
        out.extend(sorted(p.glob("*.py")) if p.is_dir() else ([p] if p.is_file() else []))
    return out


def digest(files: list[Path], root: Path = ROOT) -> str:
    """SHA-1 over the files' paths (relative to ``root``) and contents."""
    h = hashlib.sha1()
    for f in files:
        h.update(str(f.relative_to(root)).encode())
        h.update(b"\0")
        h.update(f.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


def cache_dirs(py_file: Path) -> list[Path]:
    """Where numba may keep the cache of the functions of ``py_file``: the file's own
    ``__pycache__``, ``$NUMBA_CACHE_DIR`` and numba's user-wide cache (for a source
    folder it cannot write to), in numba's layout."""
    dirs = [py_file.parent / "__pycache__"]
    try:
        from numba.core.caching import _SourceFileBackedLocatorMixin
        from numba.misc.appdirs import AppDirs
        sub = _SourceFileBackedLocatorMixin.get_suitable_cache_subpath(str(py_file))
        if os.environ.get("NUMBA_CACHE_DIR"):
            dirs.append(Path(os.environ["NUMBA_CACHE_DIR"]) / sub)
        dirs.append(Path(AppDirs(appname="numba", appauthor=False).user_cache_dir) / sub)
    except (ImportError, AttributeError):       # numba's private layout moved: its own folder only
        pass
    return dirs


def _writable(d: Path) -> bool:
    try:
        d.mkdir(parents=True, exist_ok=True)
        probe = d / f".probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
        return True
    except OSError:
        return False


def refresh(root: Path = ROOT) -> bool:
    """Delete the numba cache entries of :data:`SOURCES` where their sources changed
    since the last call (the stamp differs or is missing while entries exist); True
    when entries were deleted. Quiet where nothing can be written (numba cannot cache
    there either)."""
    files = sources(root)
    if not files:
        return False
    new = digest(files, root)
    anchor = files[0]
    stamp = next((d / STAMP for d in cache_dirs(anchor) if _writable(d)), None)
    if stamp is None:
        return False
    try:
        if stamp.read_text().strip() == new:
            return False
    except OSError:
        pass
    deleted = False
    for f in files:
        for d in cache_dirs(f):
            if not d.is_dir():
                continue
            for entry in list(d.glob(f"{f.stem}.*.nbi")) + list(d.glob(f"{f.stem}.*.nbc")):
                try:
                    entry.unlink()
                    deleted = True
                except OSError:                 # another process got there first
                    pass
    try:
        stamp.write_text(new + "\n")
    except OSError:
        pass
    return deleted


def refresh_once() -> None:
    """:func:`refresh`, once per process."""
    global _done
    if not _done:
        _done = True
        refresh()
