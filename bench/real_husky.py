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
NO_LOAD_CURRENT = 1.35    # A, dataset code
TRAIN_FRACTION = 0.7


def terrain_samples(folder: Path, files: list, torque_constant: float) -> dict:
    from sbmpc.realdata import read_borealtc, steady_samples
    parts = [steady_samples(read_borealtc(folder / f)) for f in files]
    return with_torques({k: np.concatenate([p[k] for p in parts]) for k in parts[0]}, torque_constant)


def with_torques(s: dict, torque_constant: float) -> dict:
    """Steady stretches with wheel torques [N m] from the (unsigned) motor currents."""
    s["tau_l"] = torque_constant * np.maximum(s["i_l"] - NO_LOAD_CURRENT, 0.0)
    s["tau_r"] = torque_constant * np.maximum(s["i_r"] - NO_LOAD_CURRENT, 0.0)
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
    args = ap.parse_args(argv)
    if not args.data.is_dir():
        print(f"real_husky: expected the BorealTC folders in {args.data}, found none", file=sys.stderr)
        return 2
    from dynamics import load_terrain, load_vehicle
    from dynamics.identify import fit_friction
    v = load_vehicle("husky")
    out = {}
    for name, nominal in NOMINAL.items():
        folder = args.data / name
        files = sorted(p.name for p in folder.glob("*.csv"))
        if len(files) < 2:
            # one long file: split it by time instead of by file
            train, held = _split_one(folder / files[0], v.torque_constant)
        else:
            k = max(1, int(round(TRAIN_FRACTION * len(files))))
            train = terrain_samples(folder, files[:k], v.torque_constant)
            held = terrain_samples(folder, files[k:], v.torque_constant)
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


def _split_one(path: Path, torque_constant: float):
    from sbmpc.realdata import read_borealtc, steady_samples
    rec = read_borealtc(path)
    t = rec["t"]
    cut = t[0] + TRAIN_FRACTION * (t[-1] - t[0])
    halves = []
    for m in (t < cut, t >= cut):
        halves.append(with_torques(steady_samples({k: a[m] for k, a in rec.items()}), torque_constant))
    return halves


if __name__ == "__main__":
    sys.exit(main())
