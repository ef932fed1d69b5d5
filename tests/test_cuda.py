"""The GPU backend (sbmpc.problems.skidsteer_cuda). CI has no GPU: the kernel runs on
numba's CUDA simulator (a subprocess with NUMBA_ENABLE_CUDASIM=1, where the same kernel
source is run by Python threads) and must give the CPU's edges bit for bit and the CPU's
plan; without a GPU, asking for one gives a one-line note and the CPU plan.
``python bench/bench_gpu.py --compile-only`` compiles the kernel for sm_90 where a CUDA toolkit is
installed."""
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from sbmpc import scenario as SC

from sbmpc.planning import plan as PL, problem as PB, world as WO
from sbmpc.commands.cli import main

ROOT = Path(__file__).resolve().parents[1]

SIMULATED = r"""
import numpy as np
from dataclasses import replace
from sbmpc import scenario as SC
from sbmpc.planning import plan as PL, problem as PB, world as WO
from sbmpc.problems import skidsteer as SS
from sbmpc.problems import skidsteer_cuda as SCU
from sbmpc.problems.skidsteer_cuda import CudaEdges
made = []
class Counted(CudaEdges):                 # every CudaEdges a plan makes, for its counters
    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        made.append(self)
SCU.CudaEdges = Counted
scn = SC.load("scenarios/hill_tradeoff.yaml")
prob = PB.problem(WO.resolve(scn), "energy")
k, nb = 3, 8
parents = np.repeat(prob.start[None, :], k, axis=0)
parents[1, 0] += 4.0          # on the hill's flank
parents[2, 1] += 2.0
owner = np.repeat(np.arange(k), nb)
controls = prob.controls[np.arange(k * nb) % len(prob.controls)].copy()
gpu = (np.zeros((k * nb, prob.start.size)), np.zeros(k * nb))
cpu = (np.zeros((k * nb, prob.start.size)), np.zeros(k * nb))
edges = CudaEdges(prob.params, prob.data)
edges(prob.params, prob.data, parents, owner, controls, *gpu)
SS.expand_batch(prob.params, prob.data, parents, owner, controls, *cpu)
assert edges.launches == 1 and edges.edges == k * nb
assert np.array_equal(gpu[0], cpu[0]) and np.array_equal(gpu[1], cpu[1])
by_control = (np.zeros((k * nb, prob.start.size)), np.zeros(k * nb))
CudaEdges(prob.params, prob.data, by_control=True, threads=8)(prob.params, prob.data, parents, owner, controls,
                                                               *by_control)
assert np.array_equal(by_control[0], cpu[0]) and np.array_equal(by_control[1], cpu[1])
assert (cpu[1] > 0).sum() >= k * nb // 2, cpu[1]
flat = SC.load("scenarios/flat.yaml")
plans = {d: PL.plan(WO.resolve(replace(flat, planner=replace(flat.planner, device=d, batch=4))), "time")
         for d in ("cpu", "cuda")}
assert PB.device_note(replace(flat.planner, device="cuda")) is None
assert plans["cuda"].found and plans["cuda"].controls == plans["cpu"].controls
assert plans["cuda"].nodes_expanded == plans["cpu"].nodes_expanded
# every edge of the cuda plan ran on the "GPU" (no CPU expander timed against it)
assert sum(e.edges for e in made) == plans["cuda"].edges_simulated, ([e.edges for e in made], plans["cuda"].edges_simulated)
print("OK", plans["cuda"].nodes_expanded)
"""


def test_the_cuda_kernel_gives_the_cpu_edges_and_plan_on_the_simulator():
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1")
    r = subprocess.run([sys.executable, "-c", SIMULATED], cwd=ROOT, env=env, capture_output=True, text=True,
                       timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.startswith("OK")


def test_asking_for_a_missing_gpu_gives_one_note_and_the_cpu_plan(capsys):
    from sbmpc.problems.skidsteer_cuda import unavailable
    if unavailable() is None:
        pytest.skip("a GPU is present")
    scn = SC.load(ROOT / "scenarios" / "flat.yaml")
    note = PB.device_note(replace(scn.planner, device="cuda"))
    assert note.startswith("device cuda: ") and note.endswith("planning on the CPU") and "\n" not in note
    cpu = PL.plan(WO.resolve(scn), "time")
    gpu = PL.plan(WO.resolve(replace(scn, planner=replace(scn.planner, device="cuda"))), "time")
    assert gpu.controls == cpu.controls
    assert main(["plan", str(ROOT / "scenarios" / "flat.yaml"), "--device", "cuda", "--quiet"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"note: {note}"]
