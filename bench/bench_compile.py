"""The first compile: how long numba takes to compile the kernels a first plan and a
first simulation need, on a fresh cache, and what compiles more than once.

A child process with its own empty ``NUMBA_CACHE_DIR`` runs ``sbmpc compare
scenarios/flat.yaml`` (both costs) and one 1 kHz model rollout, with numba's compile
events recorded (``numba.core.event``): the wall time, the compile time per function
(exclusive of the functions it compiles inside it), and every function whose cache
index then holds more than one overload (numba compiles once per distinct argument
type: a literal True or a read-only array is a type of its own). One core.

    taskset -c 0 python bench/bench_compile.py

Writes bench/results/compile.json.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import stamp  # noqa: E402  (bench/, beside this script)
OUT = ROOT / "bench" / "results" / "compile.json"

CHILD = r'''
import collections, json, pickle, sys, time
from pathlib import Path
import numba.core.event as E
excl = collections.defaultdict(float)

class Exclusive(E.Listener):
    def __init__(self):
        self.stack = []
    def on_start(self, e):
        self.stack.append([time.perf_counter(), 0.0])
    def on_end(self, e):
        t0, inner = self.stack.pop()
        d = time.perf_counter() - t0
        f = e.data.get("dispatcher")
        name = f"{getattr(getattr(f, 'py_func', None), '__module__', '')}.{getattr(f, '__qualname__', f)}"
        excl[name] += d - inner
        if self.stack:
            self.stack[-1][1] += d

E.register("numba:compile", Exclusive())
t0 = time.perf_counter()
import numpy as np
from sbmpc import api
from dynamics.params import load_terrain, load_vehicle
from dynamics.simulate import Model, simulate
api.compare_scenario("scenarios/flat.yaml")
simulate(Model(load_vehicle("p3at"), load_terrain("grass"), 0.001), np.full(1000, 3.0), np.full(1000, 4.0), pitch=0.1)
wall = time.perf_counter() - t0
twice = {}
for f in sorted(Path(sys.argv[1]).rglob("*.nbi")):
    with open(f, "rb") as fh:
        pickle.load(fh)
        n = len(pickle.loads(fh.read())[1])
    if n > 1:
        twice[f.name.split(".py")[0]] = n
top = sorted(excl.items(), key=lambda kv: -kv[1])
print(json.dumps({"wall_s": wall, "compile_s": sum(excl.values()), "per_function_s": dict(top[:12]),
                  "more_than_one_overload": twice}))
'''


def main() -> int:
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        out = subprocess.run([sys.executable, "-c", CHILD, cache], cwd=ROOT, env=env, capture_output=True, text=True)
    if out.returncode != 0:
        print(out.stderr, file=sys.stderr)
        return 1
    doc = {"what": "numba's first compile on a fresh cache: compare on flat (both costs) and one 1 kHz rollout "
                   "(bench/bench_compile.py)", **json.loads(out.stdout.strip().splitlines()[-1])}
    stamp.write(OUT, doc)
    print(json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
