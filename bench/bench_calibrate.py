"""Calibrate, then diagnose: how well ``sbmpc calibrate`` recovers a vehicle and names an
effect on top (``sbmpc.calibration``).

Generated runs: a P3-AT whose mass, torque constant, mu_roll, mu_sa and mu_op are each
5-15 % off the shipped one (drawn per seed, signs mixed), 90 s of the synthetic
excitation (turns both ways, speed steps; torques and currents logged with noise), with
no effect or one hidden (viscous friction, wheel radius, command delay). Per run: each
parameter's error in standard errors, the held-out error (noise units) of the shipped
model, the calibrated one and the calibrated one with the effect named, and the cause.

Real runs (``--real``): the Warthog's DRIVE runs (wheel speeds only, 600 s each),
imported as ``sbmpc import drive`` does, the same numbers. (BorealTC's Husky files log
no commands: the measured speeds stand in for them, which leaves the drive's
parameters nothing to show; not included.)

What it buys in planning (``--closed-loop``): a P3-AT 12 % heavier with a torque
constant 8 % low drives ``sbmpc run`` (energy) on three hilly scenarios, planned with the
shipped model and with the one calibrated on a 90 s drive of it: status, stalls,
re-plans, executed against predicted energy. Writes
bench/results/calibration_closed_loop.json.

Writes bench/results/calibration.json.

    taskset -c 0 python bench/bench_calibrate.py [--seeds 4] [--real]
    taskset -c 0 python bench/bench_calibrate.py --closed-loop
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import stamp  # noqa: E402  (bench/, beside this script)
OUT = ROOT / "bench" / "results" / "calibration.json"
REAL = ROOT.parent / "shared" / "data" / "real"
EFFECTS = ("none", "viscous_friction", "wheel_radius", "command_delay")


def off_vehicle(seed: int):
    from dynamics.params import load_terrain, load_vehicle
    rng = np.random.default_rng([seed, 61])
    f = rng.uniform(0.05, 0.15, 5) * rng.choice([-1.0, 1.0], 5) + 1.0
    v, t = load_vehicle("p3at"), load_terrain("vinyl")
    v = v.replace(mass=v.mass * f[0], inertia=v.inertia * f[0], torque_constant=v.torque_constant * f[1])
    t = t.replace(mu_roll=t.mu_roll * f[2], mu_sa=t.mu_sa * f[3], mu_op=t.mu_op * f[4])
    return v, t


def one(run, v0, t0, truth=None) -> dict:
    from sbmpc.calibration import calibrate, effects_on_top
    t = time.perf_counter()
    cal = calibrate([run], v0, t0)
    d = effects_on_top(cal, [run])[0]
    h = cal.heldout[run.source]
    best = d["candidates"][0] if d["candidates"] else None
    out = {"cause": d["cause"], "heldout": {"nominal": h["nominal"], "calibrated": h["calibrated"],
                                            "with_effect": best["error"] if best and d["cause"] == best["effect"]
                                            else h["calibrated"]},
           "per_channel": h["per_channel"],
           "params": cal.params, "best": best, "seconds": round(time.perf_counter() - t, 1)}
    if truth is not None:
        tv, tt = truth
        want = {"mass": tv.mass, "torque_constant": tv.torque_constant, "mu_roll": tt.mu_roll, "mu_sa": tt.mu_sa,
                "mu_op": tt.mu_op}
        src = best["base"] if best and d["cause"] == best["effect"] else {n: p["value"] for n, p in cal.params.items()}
        out["relative_error"] = {n: (src[n] - w) / w for n, w in want.items() if n in src}
        out["z"] = {n: (cal.params[n]["value"] - w) / cal.params[n]["se"] for n, w in want.items()
                    if cal.params[n]["fitted"] and cal.params[n]["se"]}
    return out


def closed_loop() -> dict:
    from dataclasses import replace

    from dynamics.params import load_terrain, load_vehicle
    from dynamics.synth import synth_run
    from sbmpc import receding as R
    from sbmpc import scenario as SC
    from sbmpc.calibration import calibrate
    from sbmpc.planning import world as WO
    v0, t0 = load_vehicle("p3at"), load_terrain("vinyl")
    truth = v0.replace(name="p3at_off", mass=v0.mass * 1.12, inertia=v0.inertia * 1.12,
                       torque_constant=v0.torque_constant * 0.92)
    run, _ = synth_run("none", 21, vehicle=truth, terrain=t0, duration=90.0)
    cal = calibrate([run], v0, t0, only=["mass", "torque_constant", "current_limit", "ref_accel"])
    calv = cal.vehicle.replace(name="p3at_calibrated")
    out = {"truth": {"mass": truth.mass, "torque_constant": truth.torque_constant},
           "calibrated": {n: cal.params[n] for n in ("mass", "torque_constant", "current_limit", "ref_accel")},
           "runs": {}}
    for name in ("steep_hill", "hill_tradeoff", "runup_ramp"):
        scn = SC.load(ROOT / "scenarios" / f"{name}.yaml")
        for label, pv in (("shipped", v0), ("calibrated", calv)):
            t = time.perf_counter()
            d = R.run(WO.resolve(replace(scn, vehicle=pv)), "energy", truth).to_json()
            pred = d["predicted"]["energy_J"]
            out["runs"][f"{name}/{label}"] = {
                "status": d["status"], "energy_J": d["energy_J"], "predicted_J": pred,
                "energy_error": (d["energy_J"] - pred) / pred if pred else None, "replans": d["replans"],
                "stalls": d["stalls"], "wall_s": round(time.perf_counter() - t, 1)}
            print(name, label, out["runs"][f"{name}/{label}"], flush=True)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--real", action="store_true")
    ap.add_argument("--closed-loop", action="store_true", help="only the closed-loop runs (module doc)")
    args = ap.parse_args()
    started = stamp.commit()    # the code this run loaded
    if args.closed_loop:
        doc = {"what": "closed-loop runs planned with the shipped and the calibrated model (bench_calibrate.py "
                       "--closed-loop)", **closed_loop()}
        path = OUT.with_name("calibration_closed_loop.json")
        stamp.write(path, doc, started=started, default=float)
        print(f"wrote {path}")
        return 0
    from dynamics.params import load_terrain, load_vehicle
    from dynamics.synth import synth_run
    rows = []
    for seed in range(args.seeds):
        v, t = off_vehicle(seed)
        eff = EFFECTS[seed % len(EFFECTS)]
        run, hidden = synth_run(eff, 30 + seed, vehicle=v, terrain=t, duration=90.0)
        r = one(run, load_vehicle("p3at"), load_terrain("vinyl"), (v, t))
        r.update(seed=seed, hidden=eff, hidden_params=hidden)
        rows.append(r)
        print(f"seed {seed} {eff:17s} -> {r['cause']:17s} held out {r['heldout']['nominal']:.2f} -> "
              f"{r['heldout']['calibrated']:.2f} -> {r['heldout']['with_effect']:.2f}  rel. errors "
              f"{ {k: round(100 * x, 1) for k, x in r['relative_error'].items()} } % ({r['seconds']} s)", flush=True)
    real = []
    if args.real:
        from sbmpc.realdata import read_drive_windows
        for terr, shipped in (("asphalt", "asphalt"), ("gravel", "packed_dirt"), ("sand", "grass")):
            p = REAL / "drive" / f"drive_warthog_{terr}_windows.csv"
            if not p.exists():
                continue
            run = read_drive_windows(p, shipped)
            r = one(run, load_vehicle("warthog"), load_terrain(shipped))
            r.update(robot="warthog", terrain=terr)
            real.append(r)
            print(f"warthog {terr}: {r['cause']} held out {r['heldout']['nominal']:.2f} -> "
                  f"{r['heldout']['calibrated']:.2f} -> {r['heldout']['with_effect']:.2f} ({r['seconds']} s)", flush=True)
    doc = {"what": __doc__.split("\n\n")[0], "generated": rows, "real": real}
    stamp.write(OUT, doc, started=started, default=float)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
