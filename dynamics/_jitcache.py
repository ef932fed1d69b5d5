"""numba's on-disk cache, kept consistent across files (for ``dynamics`` and the compiled
parts of ``sbmpc``; it imports nothing of ``dynamics``, ``maps`` nor ``sbmpc``).

It lives in ``dynamics``, the lowest layer whose compiled code spans files. ``maps``
needs no guard: its compiled queries are one file (``maps/grid.py``, importing nothing
compiled from elsewhere), which numba's own per-file index keeps right; the compiled
code *above* it that inlines them (``sbmpc.problems``) is guarded.

numba keys a cached function on its own file only: a compiled function keeps the
module constants and the inlined callees of *other* files it was compiled with. After
an update that changes ``dynamics/kernels.py`` (say, the state layout ``NS``) but not
``sbmpc/problems/skidsteer.py``, the search would load a skid-steer expansion compiled
against the old layout and plan silently wrong (seen once: no path on a 2 % grade).
So the first import of a package with compiled code that spans files (``dynamics``,
``sbmpc.search``, ``sbmpc.problems``, ``sbmpc.planning``) calls :func:`refresh_once`: it hashes the sources
of every file the compiled code is built from and, in each folder where numba may keep
their cache (a source folder's ``__pycache__``, under ``$NUMBA_CACHE_DIR``, numba's
user-wide cache), compares that with the stamp the last refresh left there; where it
differs or is missing, it deletes those files' cache entries in that folder (numba
then compiles them again, once) and writes the new stamp. A clean checkout or a fresh
install has no cache and loses nothing. Not covered: a process that still runs the
old code (a Jupyter kernel, a Ray cluster started before the update) and compiles
after the refresh writes old entries under the new stamp; restart such processes
after an update.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

ROOT = Path(os.path.abspath(__file__)).parents[1]     # the source tree (abspath, not resolve: numba's own paths)
# the files the compiled code is built from (the compiled functions and the constants
# and helpers they read), relative to ROOT
SOURCES = ("dynamics", "maps", "sbmpc/search", "sbmpc/problems", "sbmpc/planning/heuristics.py",
           "sbmpc/planning/motions.py", "sbmpc/planning/value.py")
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
    """Where numba may keep the cache of the functions of ``py_file`` (numba's cache
    locators, in its layout): the file's own ``__pycache__``, ``$NUMBA_CACHE_DIR``'s
    folder for it when set, and numba's user-wide cache (for a source folder numba
    cannot write to)."""
    from numba.core import config
    from numba.core.caching import _CacheLocator
    from numba.misc.appdirs import AppDirs
    sub = _CacheLocator.get_suitable_cache_subpath(str(py_file))
    dirs = [py_file.parent / "__pycache__"]
    if config.CACHE_DIR:
        dirs.append(Path(config.CACHE_DIR) / sub)
    dirs.append(Path(AppDirs(appname="numba", appauthor=False).user_cache_dir) / sub)
    return dirs


def _writable(d: Path) -> bool:
    """Whether numba can cache in ``d`` (created if need be), as its locators test it."""
    try:
        d.mkdir(parents=True, exist_ok=True)
        probe = d / f".sbmpc-probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
        return True
    except OSError:
        return False


def primary(dirs: list[Path]) -> Path:
    """Of a source folder's cache folders (:func:`cache_dirs`), the one numba will cache
    in (its first locator that works): ``$NUMBA_CACHE_DIR``'s when set, else the
    ``__pycache__`` when it can be written, else numba's user-wide cache."""
    from numba.core import config
    if config.CACHE_DIR:
        return dirs[1]
    return dirs[0] if _writable(dirs[0]) else dirs[-1]


def refresh(root: Path = ROOT) -> bool:
    """In every cache folder of :data:`SOURCES`' files (those that exist, and the one
    numba is about to cache each source folder in, :func:`primary`) whose stamp differs
    from their sources' hash (or is missing), delete those files' cache entries and
    write the stamp; True when entries were deleted. A folder that cannot be written is
    left as it is (numba cannot cache there either). Without the stamp in the folder
    numba is about to fill, a first run in a fresh checkout left unstamped entries that
    the next run took for stale and compiled again (measured: 90 s twice, then 4.5 s)."""
    files = sources(root)
    if not files:
        return False
    new = digest(files, root)
    by_folder: dict = {}
    for f in files:
        by_folder.setdefault(f.parent, []).append(f)
    deleted = False
    for fs in by_folder.values():
        dirs = cache_dirs(fs[0])          # numba's cache folders depend on the source folder only
        fill = primary(dirs)              # (created, when writable: stamped even while empty, so
        for d in dirs:                    # the entries this process writes carry the right stamp)
            if not (d.is_dir() or (d == fill and _writable(d))):
                continue                  # nothing cached there, nor will be
            stamp = d / STAMP
            try:
                if stamp.read_text().strip() == new:
                    continue
            except OSError:
                pass
            for f in fs:
                for entry in list(d.glob(f"{f.stem}.*.nbi")) + list(d.glob(f"{f.stem}.*.nbc")):
                    try:
                        entry.unlink()
                        deleted = True
                    except OSError:       # another process got there first, or read-only
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
