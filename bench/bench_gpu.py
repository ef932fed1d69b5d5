"""The GPU backend: does the physics compile for the GPU, and how fast does it plan.

    python bench/bench_gpu.py --compile-only   # no GPU needed: a CUDA toolkit (numba-cuda[cu12|cu13])
    python bench/bench_gpu.py                  # on a machine with an NVIDIA GPU

``--compile-only`` compiles the edge kernel of ``sbmpc.problems.skidsteer_cuda`` (one
thread per edge running ``skidsteer.edge_cost``: the closed-loop step of
``dynamics.kernels`` and everything it calls, from the same source the CPU runs) to
PTX for sm_90 (H100/H200) without a device, and reports the time and the size. On a
GPU it measures, in one run: edges per second of the kernel against the CPU batch
expander on the same batches (1 024 and 16 384 edges), and planning time with
``device: cuda`` (batch 64) against the CPU (every core, batch 1) on every shipped
scenario and both costs, with the plans' costs. Results go to
``bench/results/gpu.json`` (or ``gpu_compile.json``).
"""
from __future__ import annotations

import json
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def compile_only() -> dict:
    import numba.cuda.dispatcher as dispatcher
    from numba import cuda, types

    class _Device:                     # compile for sm_90 with no device present
        compute_capability = (9, 0)
    dispatcher.get_current_device = lambda: _Device()
    from sbmpc.problems import skidsteer_cuda as SC
    a1, a2 = types.float64[::1], types.float64[:, ::1]
    t0 = time.perf_counter()
    ptx, _ = cuda.compile_ptx(SC.kernel().py_func, (a1, a1, a2, types.int64[::1], a2, a2, a1), cc=(9, 0))
    return {"target": "sm_90", "compile_s": round(time.perf_counter() - t0, 1), "ptx_bytes": len(ptx),
            "functions": ptx.count(".func "), "numba_cuda": _version("numba-cuda")}


def _version(name: str) -> str:
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version(name)
    except PackageNotFoundError:
        return "not installed"


def on_gpu() -> dict:
    from numba import cuda
    from sbmpc import plan as PL, scenario as SC_, world as WO
    from sbmpc.problems import skidsteer as SS
    from sbmpc.problems.skidsteer_cuda import CudaEdges, unavailable
    why = unavailable()
    if why:
        raise SystemExit(f"bench_gpu: {why}")
    res: dict = {"device": cuda.get_current_device().name.decode() if isinstance(cuda.get_current_device().name, bytes)
                 else str(cuda.get_current_device().name), "machine": platform.machine(), "edges": [], "plans": {}}
    world = WO.resolve(SC_.load(ROOT / "scenarios" / "hills_field.yaml"))
    prob = PL.problem(world, "energy")
    rng = np.random.default_rng(0)
    for n in (1024, 16384):
        parents = np.repeat(prob.start[None, :], 64, axis=0)
        parents[:, 0] += rng.uniform(0, 20, 64)
        parents[:, 1] += rng.uniform(0, 20, 64)
        owner = rng.integers(0, 64, n)
        controls = prob.controls[rng.integers(0, len(prob.controls), n)].copy()
        out = {}
        for name, fn in (("cuda", CudaEdges(prob.params, prob.data)), ("cpu", SS.expand_batch)):
            ch, co = np.zeros((n, prob.start.size)), np.zeros(n)
            fn(prob.params, prob.data, parents, owner, controls, ch, co)            # compile / warm
            t0 = time.perf_counter()
            reps = 5
            for _ in range(reps):
                fn(prob.params, prob.data, parents, owner, controls, ch, co)
            out[name] = (time.perf_counter() - t0) / reps
            out[name + "_costs"] = co.copy()
        same = float(np.max(np.abs(out["cuda_costs"] - out["cpu_costs"])))
        res["edges"].append({"edges": n, "cuda_edges_per_s": round(n / out["cuda"]), "cpu_edges_per_s": round(n / out["cpu"]),
                             "ratio": round(out["cpu"] / out["cuda"], 1), "max_cost_difference": same})
        print(res["edges"][-1], flush=True)
    for path in sorted((ROOT / "scenarios").glob("*.yaml")):
        scn = SC_.load(path)
        row = {}
        for cost in ("time", "energy"):
            for dev, batch in (("cpu", 1), ("cuda", 64)):
                w = WO.resolve(replace(scn, planner=replace(scn.planner, device=dev, batch=batch)))
                p = PL.plan(w, cost)
                row[f"{cost}_{dev}"] = {"status": p.status, "planning_time_s": round(p.planning_time_s, 3),
                                        "expansions": p.nodes_expanded,
                                        "cost": p.travel_time_s if cost == "time" else p.energy_J}
        res["plans"][path.stem] = row
        print(path.stem, row, flush=True)
    return res


def main() -> int:
    if "--compile-only" in sys.argv:
        res = compile_only()
        out = ROOT / "bench" / "results" / "gpu_compile.json"
    else:
        res = on_gpu()
        out = ROOT / "bench" / "results" / "gpu.json"
    out.write_text(json.dumps(res, indent=1))
    print(json.dumps(res, indent=1) if "--compile-only" in sys.argv else f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
