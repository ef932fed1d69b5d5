"""The one line a command prints on stderr before numba compiles what it runs (a fresh
install, or sources changed since numba cached them on disk): the first run of a
command then sits silent for a minute or two otherwise."""
from __future__ import annotations

import os
import sys


def _cold(functions) -> bool:
    """Whether numba's on-disk cache lacks any of the compiled ``functions`` (False where
    numba's cache internals moved: then nothing is said)."""
    try:
        return any(not os.path.exists(f._cache._cache_file._index_path) for f in functions)
    except Exception:
        return False


def compile_note(quiet: bool = False) -> None:
    """The line for ``plan``, ``compare`` and ``run``: the search and the skid-steer's
    edges compile for about 75 s (73 s on one core for `compare` on flat with a model rollout,
    bench/bench_compile.py, 2026-12-07; 117 s before the model's step compiled once)."""
    if quiet:
        return
    from ..problems.skidsteer import expand_batch
    from ..search.loop import run_search
    if _cold((run_search, expand_batch)):
        print("compiling the planner (first run only, about 75 s, mostly before the search: the planning "
              "time printed shows part of it) ...", file=sys.stderr, flush=True)


def model_note() -> None:
    """The line for ``simulate``, ``synth`` and ``diagnose``: the closed-loop model's
    rollout compiles for about a minute."""
    from dynamics import kernels as K
    if _cold((K.rollout,)):
        print("compiling the vehicle model (first run only, about a minute) ...", file=sys.stderr, flush=True)
