"""The files of one command: inputs are never written, outputs are checked before any
work and written atomically.

* :class:`Outputs` collects a command's inputs (every file it reads: the scenario and
  the map, vehicle and terrain files it names; a run CSV) and checks each output path
  when it is declared: not a folder, in an existing and writable folder, and not one of
  the inputs (compared as the same file on disk, so a link or another spelling of an
  input's path is caught too). A bad path is an :class:`InputError` (exit 2) before
  the plan, the run or the diagnosis starts.
* :func:`atomic` gives a writer a temporary path in the target folder and renames it
  into place when the writer is done, so that an interrupted command leaves the old
  file or the new one, never half of one.
"""
from __future__ import annotations

import contextlib
import os
from pathlib import Path

from ..errors import InputError


def path_arg(text: str) -> Path:
    """argparse type of a path option: an empty path (``--out ""``, which Path reads as
    the current folder) is a usage error, exit 2."""
    import argparse
    if not text:
        raise argparse.ArgumentTypeError("expected a path, found an empty string")
    return Path(text)


def _is_file(p) -> bool:
    """Whether ``p`` (a path, a string such as a vehicle name, or None) names an existing
    file; a name too long for a path is not one."""
    if not isinstance(p, (str, Path)) or not str(p):
        return False
    try:
        return Path(p).is_file()
    except OSError:
        return False


def _special(path: Path) -> bool:
    """Whether ``path`` exists and is neither a regular file nor a folder (a device, a pipe)."""
    try:
        return path.exists() and not path.is_file() and not path.is_dir()
    except OSError:
        return False


def _same(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


class Outputs:
    """Output paths of a command, checked against its ``inputs`` (any values that may
    name files: existing files only are compared; missing ones cannot be overwritten)."""

    def __init__(self, inputs=()):
        self.inputs: list[Path] = []
        self.declared: list[tuple[Path, str]] = []
        self.add_inputs(inputs)

    def add_inputs(self, paths) -> None:
        """Add the inputs among ``paths``: values that name existing files (a shipped
        vehicle name, None or a missing path is skipped)."""
        for p in paths:
            if _is_file(p):
                self.inputs.append(Path(p))
                self.inputs += _bases(Path(p))
        for path, flag in self.declared:
            self._not_an_input(path, flag)

    def _not_an_input(self, path: Path, flag: str) -> None:
        for src in self.inputs:
            if _same(path, src) or path.resolve() == src.resolve():
                raise InputError(f"{flag}: '{path}' is an input of this command ({src}); "
                                 "choose another output path (inputs are never overwritten)")

    def file(self, path: Path | None, flag: str) -> Path | None:
        """Check an output file path (None: no output); returns it."""
        if path is None:
            return None
        path = Path(path)
        if path.is_dir():
            raise InputError(f"{flag}: expected a file path, found the folder '{path}'")
        if _special(path):                # /dev/null, a FIFO: written into, in a folder we need not write
            if not os.access(path, os.W_OK):
                raise InputError(f"{flag}: cannot write into '{path}' (permission denied)")
            return path
        parent = path.parent
        if not parent.exists():
            raise InputError(f"{flag}: expected a path in an existing folder, found '{path}' (no folder '{parent}')")
        if not parent.is_dir():
            raise InputError(f"{flag}: expected a path in a folder, found '{path}' ('{parent}' is a file)")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise InputError(f"{flag}: cannot write into the folder '{parent}' (permission denied)")
        if path.exists() and not os.access(path, os.W_OK):
            raise InputError(f"{flag}: cannot replace '{path}' (permission denied)")
        self._not_an_input(path, flag)
        self._not_declared(path, flag)
        self.declared.append((path, flag))
        return path

    def _not_declared(self, path: Path, flag: str) -> None:
        for other, other_flag in self.declared:
            if _same(path, other) or path.resolve() == other.resolve():
                raise InputError(f"{flag}: '{path}' is also the output of {other_flag}; give each output its own path")

    def folder(self, path: Path, flag: str, names=()) -> Path:
        """Check an output folder (created later if missing, with its parents) and the
        files ``names`` that will be written into it."""
        path = Path(path)
        if path.exists() and not path.is_dir():
            raise InputError(f"{flag}: expected a folder, found the file '{path}'")
        probe = path
        while not probe.exists():
            probe = probe.parent
        if not probe.is_dir():
            raise InputError(f"{flag}: cannot create the folder '{path}' ('{probe}' is a file)")
        if not os.access(probe, os.W_OK | os.X_OK):
            raise InputError(f"{flag}: cannot write into the folder '{probe}' (permission denied)")
        for name in names:
            f = path / name
            if f.is_dir():
                raise InputError(f"{flag}: would write '{f}', found a folder there")
            self._not_an_input(f, flag)
            self._not_declared(f, flag)
            self.declared.append((f, flag))
        return path


def _bases(path: Path, depth: int = 0) -> list[Path]:
    """The vehicle or terrain files a YAML file takes its values from (``base:``, in a
    chain): inputs too, though the command names only the first."""
    if depth > 8 or path.suffix.lower() not in (".yaml", ".yml"):
        return []
    from dynamics.params import read_yaml_text
    try:
        doc = read_yaml_text(path)
    except (OSError, ValueError):          # the loader reports it
        return []
    b = doc.get("base") if isinstance(doc, dict) else None
    if not isinstance(b, str) or not b:
        return []
    from dynamics.params import _shipped
    if b in _shipped("vehicles") or b in _shipped("terrains"):
        return []                          # the loader takes a shipped name first, as here
    cand = path.parent / b                 # (as the loader reads it: beside the file, as written)
    return [cand] + _bases(cand, depth + 1) if _is_file(cand) else []


@contextlib.contextmanager
def atomic(path: Path):
    """A temporary path beside ``path`` (same suffix, so writers that pick the format
    from it still do) that replaces ``path`` when the block ends without an error; on
    an error the temporary file is removed and ``path`` is untouched."""
    path = Path(path)
    if _special(path):      # a device or a pipe (/dev/null, a FIFO): written into, never replaced
        try:
            yield path
        except BrokenPipeError:            # (not stdout's reader, which main forgives: an output not written)
            raise InputError(f"cannot write '{path}': the reader of the pipe went away before the output "
                             "was written") from None
        return
    name = f".{path.stem}.{os.getpid()}.tmp{path.suffix}"
    tmp = path.with_name(name if len(os.fsencode(name)) <= 200 else f".sbmpc.{os.getpid()}.tmp{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()


def write_text(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def _finite(x):
    """``x`` with every NaN or infinite float as None (JSON has no NaN: Python wrote a bare
    ``NaN`` that strict readers refuse)."""
    if isinstance(x, float):
        return x if x == x and abs(x) != float("inf") else None
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    return x


def write_json(path: Path, doc) -> None:
    """Write ``doc`` as JSON (indent 1) to ``path`` atomically, a non-finite number as null."""
    import json
    write_text(path, json.dumps(_finite(doc), indent=1, allow_nan=False))


def scenario_inputs(path: Path) -> list[Path]:
    """The scenario file and every file it names (map, vehicle, terrains), read from the
    raw YAML without validating it (validation comes later and reports its own
    problems)."""
    from dynamics.params import read_yaml_text
    out = [Path(path)]
    try:
        doc = read_yaml_text(Path(path))
    except (OSError, ValueError):          # the scenario loader reports it
        return out
    if not isinstance(doc, dict):
        return out
    base = Path(path).parent
    names = []
    m = doc.get("map")
    if isinstance(m, dict) and isinstance(m.get("file"), str):
        names.append(m["file"])
    for key in ("vehicle", "terrain"):
        v = doc.get(key)
        if isinstance(v, str):
            names.append(v)
        elif isinstance(v, dict):
            names += [x for x in (v.get("default"),) if isinstance(x, str)]
            regions = v.get("regions")
            for r in regions if isinstance(regions, list) else []:
                if isinstance(r, dict) and isinstance(r.get("terrain"), str):
                    names.append(r["terrain"])
            ras = v.get("raster")
            if isinstance(ras, dict):
                names += [x for x in (ras.get("file"),) if isinstance(x, str)]
                classes = ras.get("classes")
                names += [x for x in (classes.values() if isinstance(classes, dict) else []) if isinstance(x, str)]
    for n in names:
        out += [cand for cand in (base / n, base / f"{n}.yaml", Path(n)) if _is_file(cand)]
    return out
