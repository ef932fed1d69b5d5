"""The paper's eq. 28 on a real skid-steered vehicle: terrain friction of a Clearpath Husky
from the BorealTC runs (../shared/data/real/borealtc; public originals:
github.com/norlab-ulaval/BorealTC, CC0).

BorealTC logs motor currents (unsigned) and wheel speeds at about 6.5 Hz, without
commands or pose, so the model cannot be replayed; what it can do is the paper's
identification. For each terrain: cut the files into steady stretches (both wheel
speeds constant for at least 1 s, :func:`sbmpc.realdata.steady_samples`); convert the
currents to wheel torques (k = 2.424 N m/A at the wheel, less the 1.35 A no-load
current); fit mu_roll, mu_sa and mu_op of eq. 22 (:func:`dynamics.identify.fit_friction`,
on |tau|: the currents carry no sign) on the first 70 % of the files; score the fitted
terrain and the nearest shipped terrain on the other 30 %. Writes bench/results/husky.json.

    python bench/real_husky.py [--data DIR]
    python bench/real_husky.py --calibrate [--seconds 150] [--workers 2]

``--calibrate``: the replay instead (issue 61, item 3). Each file is read as a run
(:func:`sbmpc.realdata.read_borealtc_run`: the measured wheel speeds stand in for the
commands, the currents are magnitudes, ``# currents: unsigned``, and the replay's are
compared as such); per terrain the first files up to ``--seconds`` of driving are
calibrated together (a file that would pass it cut at it) from the shipped ``husky`` on the nearest shipped terrain
(:func:`sbmpc.calibration.calibrate`: every parameter the runs excite, jointly, on the
first 70 % of each run), then the add-on effects the runs can show (:data:`EFFECTS`:
not the speed loop's delay or lag) are fitted jointly on top on the longest of them
(:func:`sbmpc.calibration.effects_on_top`). Held-out error (the last
30 % of each run, noise units) per channel: nominal, calibrated, calibrated + effect.
Writes bench/results/husky_calibrated.json.

``--data``: the folder holding BorealTC's terrain folders (ASPHALT, FLOORING, ...;
default ../shared/data/real/borealtc beside the repository).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "real" / "borealtc"
from sbmpc.realdata import BOREALTC_TERRAINS as NOMINAL  # noqa: E402  (nearest shipped terrain)
TRAIN_FRACTION = 0.7
# --calibrate's add-on effects: the measured speeds stand in for the commands, so the speed
# loop's delay and lag cannot be seen (sbmpc import borealtc says so); the others can
EFFECTS = ("wheel_radius", "viscous_friction", "no_load_current", "voltage_sag", "shear_relaxation", "grade", "turning_friction")


def terrain_samples(folder: Path, files: list, vehicle) -> dict:
    from sbmpc.realdata import read_borealtc, steady_samples
    parts = [steady_samples(read_borealtc(folder / f)) for f in files]
    return with_torques({k: np.concatenate([p[k] for p in parts]) for k in parts[0]}, vehicle)


def with_torques(s: dict, vehicle) -> dict:
    """Steady stretches with wheel torques [N m] from the (unsigned) motor currents, less
    what the motors draw turning freely (the vehicle's no_load_current)."""
    k, i0 = vehicle.torque_constant, vehicle.no_load_current
    s["tau_l"] = k * np.maximum(s["i_l"] - i0, 0.0)
    s["tau_r"] = k * np.maximum(s["i_r"] - i0, 0.0)
    return s


def rmse(vehicle, terrain, s) -> float:
    from dynamics.resistance import steady_resistance_fast
    tl, tr = steady_resistance_fast(s["wl"], s["wr"], vehicle, terrain)
    e = np.r_[np.abs(tl) - s["tau_l"], np.abs(tr) - s["tau_r"]]
    return float(np.sqrt(np.mean(e * e)))


def main(argv=None) -> int:
    import argparse

    import stamp    # bench/, beside this script (here, not above: tests/test_realdata.py loads this file bare)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA, help="folder of BorealTC's terrain folders")
    ap.add_argument("--calibrate", action="store_true", help="replay, calibrate and diagnose on top (module doc)")
    ap.add_argument("--seconds", type=float, default=150.0, help="--calibrate: driving per terrain, s")
    ap.add_argument("--workers", type=int, default=1, help="--calibrate: processes (one terrain each)")
    args = ap.parse_args(argv)
    if not args.data.is_dir():
        print(f"real_husky: expected the BorealTC folders in {args.data}, found none", file=sys.stderr)
        return 2
    if args.calibrate:
        return main_calibrated(args, stamp)
    from dynamics import load_terrain, load_vehicle
    from dynamics.identify import fit_friction
    v = load_vehicle("husky")
    out = {}
    for name, nominal in NOMINAL.items():
        folder = args.data / name
        files = sorted(p.name for p in folder.glob("*.csv"))
        if len(files) < 2:
            # one long file: split it by time instead of by file
            train, held = _split_one(folder / files[0], v)
        else:
            k = max(1, int(round(TRAIN_FRACTION * len(files))))
            train = terrain_samples(folder, files[:k], v)
            held = terrain_samples(folder, files[k:], v)
        ter0 = load_terrain(nominal)
        fit = fit_friction(v, ter0, train["wl"], train["wr"], train["tau_l"], train["tau_r"], magnitudes=True)
        turning = np.abs(train["wr"] - train["wl"]) > 1.0
        res = {"files": len(files), "steady_train": int(train["wl"].size), "steady_heldout": int(held["wl"].size),
               "turning_train": int(turning.sum()), "nominal": nominal,
               "fitted": {k: fit[k] for k in ("mu_roll", "mu_sa", "mu_op", "rms")}
               | {"stderr": [x if np.isfinite(x) else None for x in fit["stderr"]]},
               "nominal_params": {"mu_roll": ter0.mu_roll, "mu_sa": ter0.mu_sa, "mu_op": ter0.mu_op},
               "heldout_rmse_Nm": {"nominal": rmse(v, ter0, held) if held["wl"].size else None,
                                   "fitted": rmse(v, fit["terrain"], held) if held["wl"].size else None},
               "mean_torque_Nm": float(np.mean(np.r_[train["tau_l"], train["tau_r"]]))}
        out[name] = res
        print(name, json.dumps({k: res[k] for k in ("steady_train", "steady_heldout", "fitted", "heldout_rmse_Nm")}),
              flush=True)
    (ROOT / "bench" / "results").mkdir(parents=True, exist_ok=True)
    stamp.write(ROOT / "bench" / "results" / "husky.json", out)   # beside the terrains: report.py skips them
    print("wrote bench/results/husky.json")
    return 0


def calibrated(folder: str, nominal: str, seconds: float) -> dict:
    """``--calibrate`` on one terrain folder (module doc): its row."""
    import time

    from dynamics import load_terrain, load_vehicle
    from sbmpc.calibration import calibrate, effects_on_top
    from sbmpc.realdata import read_borealtc_run
    t0 = time.perf_counter()
    runs, total = [], 0.0
    for f in sorted(Path(folder).glob("*.csv")):
        r = read_borealtc_run(f, nominal)
        end = int(np.searchsorted(r.t, r.t[0] + seconds - total))      # (a long file: its first part)
        r = r.slice(0, end) if end < len(r) else r
        if len(r) < 50:
            continue                  # too short to split into a training and a held-out part
        runs.append(r)
        total += float(r.t[-1] - r.t[0])
        if total >= seconds - 1.0:
            break
    if not runs:
        raise SystemExit(f"real_husky: {folder}: no file of at least 50 samples within --seconds {seconds:g}")
    cal = calibrate(runs, load_vehicle("husky"), load_terrain(nominal))
    longest = max(runs, key=len)
    d = effects_on_top(cal, [longest], EFFECTS)[0]
    named = d["candidates"][0] if d["cause"] not in ("none", "unexplained") else None
    per = {}
    for r in runs:
        h = cal.heldout[r.source]
        per[Path(r.source).name] = {"seconds": float(r.t[-1] - r.t[0]), "nominal": h["nominal"],
                                    "calibrated": h["calibrated"], "per_channel": h["per_channel"]}
    return {"terrain": nominal, "runs": per, "seconds_driven": total,
            "params": cal.params, "excitation": cal.excitation,
            "diagnosed_run": Path(longest.source).name, "cause": d["cause"], "decided_on": d["decided_on"],
            "share": d["share"], "effect": named and {k: named[k] for k in ("effect", "params", "gain", "evidence")},
            "longest": {c: dict(cal.heldout[longest.source]["per_channel"][c], **d["per_channel"][c])
                        for c in d["per_channel"]},
            "wall_s": round(time.perf_counter() - t0, 1)}


def main_calibrated(args, stamp) -> int:
    """``--calibrate`` (module doc)."""
    import concurrent.futures as cf
    out = {"what": "calibrate, then diagnose, on BorealTC's Husky runs (bench/real_husky.py --calibrate)",
           "seconds_per_terrain": args.seconds, "terrains": {}}
    with cf.ProcessPoolExecutor(args.workers) as pool:
        futs = {name: pool.submit(calibrated, str(args.data / name), nominal, args.seconds)
                for name, nominal in NOMINAL.items() if (args.data / name).is_dir()}
        for name, f in futs.items():
            row = f.result()
            out["terrains"][name] = row
            fitted = {n: round(p["value"] / p["prior"], 3) for n, p in row["params"].items() if p["fitted"]}
            print(name, row["cause"], fitted, json.dumps(row["longest"]), f"{row['wall_s']} s", flush=True)
    stamp.write(ROOT / "bench" / "results" / "husky_calibrated.json", out, default=float)
    print("wrote bench/results/husky_calibrated.json")
    return 0


def _split_one(path: Path, vehicle):
    from sbmpc.realdata import read_borealtc, steady_samples
    rec = read_borealtc(path)
    t = rec["t"]
    cut = t[0] + TRAIN_FRACTION * (t[-1] - t[0])
    halves = []
    for m in (t < cut, t >= cut):
        halves.append(with_torques(steady_samples({k: a[m] for k, a in rec.items()}), vehicle))
    return halves


if __name__ == "__main__":
    sys.exit(main())
