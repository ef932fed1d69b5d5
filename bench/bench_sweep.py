"""Sweep throughput: Ray on this machine against a serial loop, in one run.

    python bench/bench_sweep.py          # writes bench/results/sweep.json

48 tasks (flat and runup_ramp, both costs, 3 seeds, 4 vehicle variants; each plan on one
thread, as a sweep runs them). The serial loop runs them one after another in this
process (numba warm); Ray runs them on ``cores`` workers in batches (``sbmpc.sweep``),
its start-up timed apart. Also measured: Ray's overhead per task (a no-op task) and per
batch of tasks. Ratios within one run (this machine is noisy).
"""
from __future__ import annotations

import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
OUT = ROOT / "bench" / "results" / "sweep.json"
import stamp  # noqa: E402  (bench/, beside this script)

SPEC = f"""
scenarios: [{ROOT}/scenarios/flat.yaml, {ROOT}/scenarios/runup_ramp.yaml]
costs: [time, energy]
seeds: [0, 1, 2]
variants:
  - {{name: nominal}}
  - {{name: heavy, vehicle: {{mass: "+10%"}}}}
  - {{name: light, vehicle: {{mass: "-10%"}}}}
  - {{name: slippery, terrain: {{mu_sa: "-20%", mu_op: "-20%"}}}}
"""


def _noop(x):
    return x


def main() -> int:
    import ray
    from sbmpc import sweep as SW
    tmp = Path(tempfile.mkdtemp())
    (tmp / "spec.yaml").write_text(SPEC)
    tasks = SW.tasks(SW.load_spec(tmp / "spec.yaml"))
    cores = os.cpu_count() or 1
    SW.run_task(tasks[0])                                    # warm numba in this process
    t0 = time.perf_counter()
    serial = [SW.run_task(t) for t in tasks]
    t_serial = time.perf_counter() - t0
    t0 = time.perf_counter()
    import logging
    ray.init(num_cpus=cores, include_dashboard=False, log_to_driver=False, logging_level=logging.ERROR)
    t_init = time.perf_counter() - t0
    # Ray's own overhead: no-op tasks, one at a time and all at once
    f = ray.remote(num_cpus=1)(_noop)
    ray.get([f.remote(0) for _ in range(cores)])             # workers up
    t0 = time.perf_counter()
    ray.get([f.remote(i) for i in range(500)])
    per_task_s = (time.perf_counter() - t0) / 500
    # warm the workers' numba (loaded from the on-disk cache) before timing the sweep
    SW.execute(tasks[:4 * cores], tmp / "warm", workers=cores, batch_size=1)
    t0 = time.perf_counter()
    res = SW.execute(tasks, tmp / "ray", workers=cores)
    t_ray = time.perf_counter() - t0
    ray.shutdown()
    found_s = sum(r["status"] == "found" for r in serial)
    found_r = sum(r["status"] == "found" for r in res["rows"])
    same = sorted((r["task_id"], r["status"], round(r["energy_J"] or 0, 6)) for r in serial) == \
        sorted((r["task_id"], r["status"], round(r["energy_J"] or 0, 6)) for r in res["rows"])
    out = {"machine": platform.machine(), "cores": cores, "tasks": len(tasks),
           "serial_s": round(t_serial, 2), "ray_s": round(t_ray, 2), "ray_start_s": round(t_init, 2),
           "speedup": round(t_serial / t_ray, 2), "speedup_with_start": round(t_serial / (t_ray + t_init), 2),
           "mean_task_s": round(t_serial / len(tasks), 3), "ray_overhead_per_task_s": round(per_task_s, 5),
           "found": [found_s, found_r], "same_results": same}
    stamp.write(OUT, out)
    print(json.dumps(out, indent=1))
    shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
