"""What the paper's model gets wrong on a real skid-steered vehicle: the Clearpath Warthog
runs of Norlab DRIVE (../shared/data/real/drive; public originals: github.com/norlab-ulaval/DRIVE).

For each terrain: read the run (windows joined into one timeline), calibrate what is not
known of the vehicle (no-load speed through the torque constant, continuous current
limit, reference acceleration) on the first 70 % in time, and the terrain's kinematic
alpha (eq. 1) from the ICP pose on the same part; then diagnose on the calibrated
vehicle and terrain: every candidate extension fitted on the same 70 % and scored on the
held-out last 30 %. Writes bench/results/warthog.json and docs/warthog.png.

    python bench/real_warthog.py [--terrains asphalt gravel sand] [--data DIR]

``--data``: the folder holding ``drive_warthog_<terrain>_windows.csv`` (default
../shared/data/real/drive beside the repository).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
import stamp  # noqa: E402  (bench/, beside this script)
DATA = ROOT.parent / "shared" / "data" / "real" / "drive"
TERRAIN = {"asphalt": "asphalt", "gravel": "packed_dirt", "sand": "grass"}   # nearest shipped terrain
FIELDS = {"torque_constant": (2.0, 8.0), "current_limit": (2.0, 80.0), "ref_accel": (0.5, 6.0)}
STARTS = 6   # the calibration from the datasheet's values and 5 points over the bounds: the lowest kept


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--terrains", nargs="*", default=list(TERRAIN))
    ap.add_argument("--data", type=Path, default=DATA, help="folder of the DRIVE windows CSVs")
    args = ap.parse_args(argv)
    if not args.data.is_dir():
        print(f"real_warthog: expected the DRIVE CSVs in {args.data}, found none", file=sys.stderr)
        return 2
    from dynamics import load_terrain, load_vehicle
    from dynamics.discrepancy import calibrate, channels, diagnose, noise_scale, pose_error, replay
    from dynamics.identify import fit_kinematics
    from sbmpc.realdata import read_drive_windows
    out = {}
    figs = []
    for name in args.terrains:
        t0 = time.perf_counter()
        run = read_drive_windows(args.data / f"drive_warthog_{name}_windows.csv", name)
        v0, ter = load_vehicle("warthog"), load_terrain(TERRAIN[name])
        t = run.t
        train = t < t[0] + 0.7 * (t[-1] - t[0])
        chans = channels(run)
        scales = {c: noise_scale(run[c]) for c in chans}
        base0 = replay(run, v0, ter)
        v1, cal, optima = calibrate(run, v0, ter, FIELDS, train, starts=STARTS)
        base1 = replay(run, v1, ter)
        # eq. 1 from the ICP pose on the training part: the ICR factor alpha of this terrain
        kin = fit_kinematics(t, run["wl"], run["wr"], run["x"], run["y"], run["yaw"], v1.wheel_radius, v1.width,
                             train, segment=run["segment"])
        ter_a = ter.replace(alpha=kin["alpha"])
        base_a = replay(run, v1, ter_a)
        pose = {"nominal": pose_error(run, base0, ~train), "calibrated": pose_error(run, base1, ~train),
                "calibrated_alpha": pose_error(run, base_a, ~train)}
        d = diagnose(run, v1, ter_a)
        rms = lambda pred, m, run=run, chans=chans: {c: float(np.sqrt(np.nanmean((run[c] - pred[c])[m] ** 2))) for c in chans}
        held = ~train
        ext = replay(run, d.extended_vehicle, d.extended_terrain or ter_a) if d.cause != "none" else base_a
        res = {"samples": len(run), "segments": len(run.segments()), "noise_scales": scales,
               "calibrated": cal, "calibration_optima": optima, "kinematics": kin, "assumed_alpha": ter.alpha,
               "heldout_pose_error": pose | {"extended": d.pose.get("extended")},
               "heldout_rmse_rad_s": {"nominal": rms(base0, held), "calibrated": rms(base1, held),
                                      "extended": rms(ext, held)},
               "candidates": [{"effect": c.effect, "params": c.params, "gain": c.gain, "bic_delta": c.bic_delta}
                              for c in d.candidates],
               "cause": d.cause, "gain": d.gain, "share": d.share, "hint": d.hint, "where": d.where, "xcorr": d.xcorr,
               "time_s": time.perf_counter() - t0}
        out[name] = res
        print(name, json.dumps({k: res[k] for k in ("calibrated", "calibration_optima", "kinematics", "heldout_rmse_rad_s",
                                                     "heldout_pose_error", "cause", "gain")}), flush=True)
        figs.append((name, run, base0, base1, ext, d.cause))
    (ROOT / "bench" / "results").mkdir(parents=True, exist_ok=True)
    stamp.write(ROOT / "bench" / "results" / "warthog.json", out)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(len(figs), 1, figsize=(11, 2.8 * len(figs)), squeeze=False)
    for a, (name, run, b0, b1, ext, cause) in zip(ax[:, 0], figs):
        t = run.t
        m = (t > t[0] + 0.75 * (t[-1] - t[0])) & (t < t[0] + 0.75 * (t[-1] - t[0]) + 40)
        a.plot(t[m], run["wl_cmd"][m], color="0.8", lw=1, label="command (left)")
        a.plot(t[m], run["wl"][m], "k.", ms=2, label="measured")
        a.plot(t[m], b0["wl"][m], lw=1, label="nominal model")
        a.plot(t[m], b1["wl"][m], lw=1.2, label="calibrated")
        if cause != "none":
            a.plot(t[m], ext["wl"][m], lw=1.2, label=f"extended ({cause})")
        a.set_ylabel(f"{name}: left wheel [rad/s]")
    ax[0, 0].legend(fontsize=7, ncol=5, loc="upper left")
    ax[-1, 0].set_xlabel("t [s] (held-out part of each run)")
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "warthog.png", dpi=100)
    print("wrote bench/results/warthog.json, docs/warthog.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
