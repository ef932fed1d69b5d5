"""Speed of the vehicle model. Writes bench/results/dynamics.json and prints a summary.

    python bench/bench_dynamics.py [--quick]

Measures, in one run (ratios are what to compare across machines):
* closed-loop steps per second, one long rollout and a batch of short rollouts;
* the cost of one closed-loop step relative to a bare unicycle Euler step in numba;
* the fast (tabulated) resistance against the exact quadrature: speed ratio and error;
* numba compile time with a cold cache and with a warm cache (fresh processes).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from numba import njit

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from dynamics import Model, load_terrain, load_vehicle  # noqa: E402
from dynamics import kernels as K  # noqa: E402
from dynamics.resistance import steady_resistance, unit_friction_fast  # noqa: E402
import stamp  # noqa: E402  (bench/, beside this script)


@njit(cache=True)
def unicycle_steps(state, v, w, dt, n):
    for _ in range(n):
        state[0] += v * np.cos(state[2]) * dt
        state[1] += v * np.sin(state[2]) * dt
        state[2] += w * dt
    return state


@njit(cache=True)
def fast_resistance_loop(table, wl, wr):
    acc = 0.0
    for i in range(wl.shape[0]):
        acc += unit_friction_fast(table, wl[i], wr[i])[1]
    return acc


def best_of(fn, repeat=5):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


COLD_SNIPPET = (
    "import time; t0 = time.perf_counter();"
    "from dynamics import Model, simulate; from dynamics.manoeuvres import straight;"
    "m = Model.load(); simulate(m, *straight(m, 0.5, 0.01));"
    "print(time.perf_counter() - t0)")


def compile_times():
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(ROOT))
        run = lambda: float(subprocess.run([sys.executable, "-c", COLD_SNIPPET], env=env, cwd=ROOT,
                                           capture_output=True, text=True, check=True).stdout.strip())
        return run(), run()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "dynamics.json")
    args = ap.parse_args()
    m = Model.load("p3at", "vinyl")
    P, table = m.P, m.table
    res = {"machine": {"python": sys.version.split()[0], "cpu_count": os.cpu_count()}}

    # one long closed-loop rollout (circle, 1 ms steps, no recording)
    n = 20000 if args.quick else 100000
    wl, wr = 3.0, 4.0
    S0 = m.state()
    batch = np.tile(S0, (1, 1))
    cmds = np.array([[wl, wr]])
    K.rollout_batch(P, table, batch, cmds, 10, 0.0, 0.001)
    t = best_of(lambda: K.rollout_batch(P, table, batch, cmds, n, 0.0, 0.001))
    res["closed_loop_steps_per_s_single"] = n / t
    # a batch of short rollouts with different commands (as a planner's expansion)
    nb, steps = 1000, 100
    rng = np.random.default_rng(0)
    cmds_b = rng.uniform(-8, 8, (nb, 2))
    S0b = np.tile(m.state(2.0, 2.0), (nb, 1))
    t = best_of(lambda: K.rollout_batch(P, table, S0b, cmds_b, steps, 0.05, 0.01))
    res["closed_loop_steps_per_s_batch"] = nb * steps / t
    # bare unicycle Euler step
    st = np.zeros(3)
    unicycle_steps(st, 1.0, 0.1, 0.001, 10)
    t_uni = best_of(lambda: unicycle_steps(st, 1.0, 0.1, 0.001, n))
    res["unicycle_steps_per_s"] = n / t_uni
    res["step_cost_vs_unicycle"] = res["unicycle_steps_per_s"] / res["closed_loop_steps_per_s_single"]

    # fast vs exact resistance
    veh, ter = load_vehicle(), load_terrain("vinyl")
    psi = rng.uniform(-np.pi, np.pi, 200)
    wls, wrs = 2 * np.cos(psi), 2 * np.sin(psi)
    t_exact = best_of(lambda: [steady_resistance(a, b, veh, ter) for a, b in zip(wls, wrs)], repeat=2) / len(psi)
    big = np.repeat(wls, 500), np.repeat(wrs, 500)
    fast_resistance_loop(table, big[0][:10], big[1][:10])
    t_fast = best_of(lambda: fast_resistance_loop(table, big[0], big[1])) / len(big[0])
    res["resistance_exact_s_per_eval"] = t_exact
    res["resistance_fast_s_per_eval"] = t_fast
    res["resistance_speedup"] = t_exact / t_fast
    grid = np.linspace(-np.pi, np.pi, 721)
    el, er = steady_resistance(2 * np.cos(grid), 2 * np.sin(grid), veh, ter, n_long=300, n_lat=20)
    from dynamics.resistance import steady_resistance_fast
    fl, fr = steady_resistance_fast(2 * np.cos(grid), 2 * np.sin(grid), veh, ter)
    full = veh.wheel_radius * veh.mass * 9.81 / 2 * ter.mu_sa
    res["resistance_fast_max_abs_error_Nm"] = float(max(np.abs(fl - el).max(), np.abs(fr - er).max()))
    res["resistance_fast_max_error_of_full_scale"] = res["resistance_fast_max_abs_error_Nm"] / full

    cold, warm = compile_times()
    res["numba_import_and_first_run_cold_cache_s"] = cold
    res["numba_import_and_first_run_warm_cache_s"] = warm

    args.out.parent.mkdir(parents=True, exist_ok=True)
    stamp.write(args.out, res)
    for k, v in res.items():
        print(f"{k:45s} {v:.4g}" if isinstance(v, float) else f"{k:45s} {v}")


if __name__ == "__main__":
    main()
