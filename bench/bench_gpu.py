"""The GPU backend: does the physics compile for the GPU, and how fast does it plan.

    python bench/bench_gpu.py --compile-only   # no GPU needed: a CUDA toolkit (numba-cuda[cu12|cu13])
    python bench/bench_gpu.py [--deadline S]   # on a machine with an NVIDIA GPU
    NUMBA_ENABLE_CUDASIM=1 python bench/bench_gpu.py --smoke   # the script itself, on the simulator

``--compile-only`` compiles the edge kernel of ``sbmpc.problems.skidsteer_cuda`` (one
thread per edge running ``skidsteer.edge_cost``: the closed-loop step of
``dynamics.kernels`` and everything it calls, from the same source the CPU runs) to
PTX for sm_90 (H100/H200) without a device, and reports the time and the size. On a
GPU it measures, in one run: edges per second of the kernel (three thread layouts:
a node's edges side by side or one control's, blocks of 128 or 32 threads) against the
CPU batch expander on every core, on the same batches of 1 024, 16 384 and 131 072
edges, with the largest cost difference; then planning time on every shipped
scenario and both costs, one CPU core (batch 1) against ``device: cuda`` at batch 64
and 256 (with the fastest layout), with the plans' costs and the time spent in GPU
calls. No plan is started after ``--deadline`` seconds (the rest are listed as
skipped). Results go to ``bench/results/gpu.json`` (or ``gpu_compile.json``), written
after every step, and to ``$OUT`` when that is set.
"""
from __future__ import annotations

import json
import os
import platform
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import stamp  # noqa: E402  (bench/, beside this script)


def compile_only() -> dict:
    if _version("numba-cuda") == "not installed":
        raise SystemExit("bench_gpu --compile-only: expected numba-cuda with a CUDA toolkit "
                         "(pip install 'sbmpc[gpu]'), found none")
    import numba.cuda.dispatcher as dispatcher
    from numba import cuda, types

    class _Device:                     # compile for sm_90 with no device present
        compute_capability = (9, 0)
    dispatcher.get_current_device = lambda: _Device()
    from sbmpc.problems import skidsteer_cuda as SC
    a1, a2 = types.float64[::1], types.float64[:, ::1]
    t0 = time.perf_counter()
    ptx, _ = cuda.compile_ptx(SC.kernel().py_func, (a1, a1, a2, types.int64[::1], a2, types.int64[::1], a2, a1), cc=(9, 0))
    return {"target": "sm_90", "compile_s": round(time.perf_counter() - t0, 1), "ptx_bytes": len(ptx),
            "functions": ptx.count(".func "), "numba_cuda": _version("numba-cuda")}


def _version(name: str) -> str:
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version(name)
    except PackageNotFoundError:
        return "not installed"


CONFIGS = {"cpu_serial": dict(device="cpu", threads=1, batch=1),     # issue 14's goal: 1 s on one core
           "cuda_b64": dict(device="cuda", batch=64),                   # 0.1 s on one H100/H200
           "cuda_b256": dict(device="cuda", batch=256)}


def _save(res: dict, out: Path) -> None:
    """Write the results so far (a run cut short by its time limit keeps them)."""
    stamp.write(out, res)
    extra = os.environ.get("OUT")                   # the device machine's return folder
    if extra:
        stamp.write(Path(extra, out.name), res)     # the same stamps: res has them now


def on_gpu(out: Path, deadline_s: float, smoke: bool = False) -> dict:
    import numba
    from numba import cuda
    from sbmpc import scenario as SC_
    from sbmpc.planning import plan as PL, problem as PB, world as WO
    from sbmpc.problems import skidsteer as SS
    from sbmpc.problems import skidsteer_cuda as SCU
    why = SCU.unavailable()
    if why:
        raise SystemExit(f"bench_gpu: {why}")
    t_start = time.perf_counter()
    name = cuda.get_current_device().name if hasattr(cuda, "get_current_device") else "CUDA simulator"
    res: dict = {"device": name.decode() if isinstance(name, bytes) else str(name), "machine": platform.machine(),
                 "cpu_cores": numba.config.NUMBA_NUM_THREADS, "numba": numba.__version__,
                 "numba_cuda": _version("numba-cuda"), "numpy": np.__version__, "configs": CONFIGS,
                 "edges": [], "plans": {}, "skipped": []}
    made = []

    class Counted(SCU.CudaEdges):               # keeps each plan's CudaEdges for its counters
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            made.append(self)
    SCU.CudaEdges = Counted

    world = WO.resolve(SC_.load(ROOT / "scenarios" / "hills_field.yaml"))
    prob = PB.problem(world, "energy")
    rng = np.random.default_rng(0)
    variants = {"cuda": dict(by_control=False, threads=128), "cuda_by_control": dict(by_control=True, threads=128),
                "cuda_by_control_t32": dict(by_control=True, threads=32)}
    call_s = {k: 0.0 for k in variants}
    for n in ((32,) if smoke else (1024, 16384, 131072)):
        parents = np.repeat(prob.start[None, :], 64, axis=0)
        parents[:, 0] += rng.uniform(0, 20, 64)
        parents[:, 1] += rng.uniform(0, 20, 64)
        owner = np.sort(rng.integers(0, 64, n))                 # a node's edges together, as the search gives them
        controls = prob.controls[rng.integers(0, len(prob.controls), n)].copy()
        t, first, costs = {}, {}, {}
        fns = {k: Counted(prob.params, prob.data, **v) for k, v in variants.items()}
        fns["cpu"] = SS.expand_batch
        for dev, fn in fns.items():
            ch, co = np.zeros((n, prob.start.size)), np.zeros(n)
            t0 = time.perf_counter()
            fn(prob.params, prob.data, parents, owner, controls, ch, co)            # compile / warm
            first[dev] = round(time.perf_counter() - t0, 1)
            reps = 5
            t0 = time.perf_counter()
            for _ in range(reps):
                fn(prob.params, prob.data, parents, owner, controls, ch, co)
            t[dev] = (time.perf_counter() - t0) / reps
            costs[dev] = co.copy()
            if dev in call_s and n <= 16384:
                call_s[dev] += t[dev]
        res["edges"].append({"edges": n, "cpu_edges_per_s": round(n / t["cpu"]),
                             **{f"{k}_edges_per_s": round(n / t[k]) for k in variants},
                             **{f"{k}_call_ms": round(1e3 * t[k], 3) for k in variants},
                             "ratio_best_cuda_to_cpu": round(t["cpu"] / min(t[k] for k in variants), 1),
                             "first_call_s": first,
                             "max_cost_difference": max(float(np.max(np.abs(costs[k] - costs["cpu"]))) for k in variants),
                             "edges_off_by_1e-6": max(int(np.sum(np.abs(costs[k] - costs["cpu"]) > 1e-6)) for k in variants)})
        print(res["edges"][-1], flush=True)
        _save(res, out)
    best = min(call_s, key=call_s.get)                  # the planner's batches: 1 024-4 096 edges
    SCU.BY_CONTROL = variants[best]["by_control"]
    SCU.THREADS_PER_BLOCK = variants[best]["threads"]
    res["plans_use"] = {"variant": best, **variants[best]}
    flat = SC_.load(ROOT / "scenarios" / "flat.yaml")
    t0 = time.perf_counter()
    for cfg in CONFIGS.values():                   # compile / load the caches
        for cost in ("time", "energy"):
            PL.search_plan(WO.resolve(replace(flat, planner=replace(flat.planner, **cfg))), cost)
    res["warmup_s"] = round(time.perf_counter() - t0, 1)
    order = ["flat", "runup_ramp", "hill_tradeoff", "mixed_terrain", "narrow_pass", "hills_field", "steep_hill"]
    paths = {p.stem: p for p in (ROOT / "scenarios").glob("*.yaml")}
    for stem in (["flat"] if smoke else order + sorted(set(paths) - set(order))):
        scn = SC_.load(paths[stem])
        row: dict = {}
        for cost in ("time", "energy"):
            for key, cfg in CONFIGS.items():
                if time.perf_counter() - t_start > deadline_s:
                    res["skipped"].append(f"{stem} {cost} {key}")
                    continue
                made.clear()
                p = PL.search_plan(WO.resolve(replace(scn, planner=replace(scn.planner, **cfg))), cost)
                r = {"status": p.status, "planning_time_s": round(p.planning_time_s, 3),
                     "expansions": p.nodes_expanded, "edges": p.edges_simulated,
                     "cost": p.travel_time_s if cost == "time" else p.energy_J}
                gpu = [e for e in made if e.launches]
                if gpu:
                    r["gpu_calls"] = sum(e.launches for e in gpu)
                    r["gpu_call_s"] = round(sum(e.seconds for e in gpu), 3)
                row[f"{cost}_{key}"] = r
        res["plans"][stem] = row
        print(stem, json.dumps(row), flush=True)
        _save(res, out)
    return res


def main() -> int:
    if "--compile-only" in sys.argv:
        res = compile_only()
        out = ROOT / "bench" / "results" / "gpu_compile.json"
    else:
        out = (Path(tempfile.gettempdir()) / "gpu_smoke.json" if "--smoke" in sys.argv
               else ROOT / "bench" / "results" / "gpu.json")
        deadline = float(sys.argv[sys.argv.index("--deadline") + 1]) if "--deadline" in sys.argv else 1e9
        res = on_gpu(out, deadline, smoke="--smoke" in sys.argv)
    _save(res, out)
    print(json.dumps(res, indent=1) if "--compile-only" in sys.argv else f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
