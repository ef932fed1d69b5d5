"""The vehicle model against what the paper reports: writes docs/model.png and
bench/results/model_report.json (steepest grades, Table I study, closed vs open loop).

    python bench/model_report.py
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import matplotlib  # noqa: E402
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from dynamics import Model, load_terrain, shipped_terrains  # noqa: E402
from dynamics.identify import PAPER_RADII, circle_torques, table_one_study  # noqa: E402
from dynamics.limits import steepest_grade, top_speed  # noqa: E402
from dynamics.manoeuvres import ramp_run, straight  # noqa: E402
from dynamics.resistance import steady_resistance_fast  # noqa: E402
from dynamics.kinematics import wheel_speeds  # noqa: E402
from dynamics.simulate import simulate  # noqa: E402
import stamp  # noqa: E402  (bench/, beside this script)


def main():
    out = {}
    vinyl = Model.load("p3at", "vinyl")
    veh = vinyl.vehicle
    out["steepest_grade_deg"] = {t: round(math.degrees(steepest_grade(veh, load_terrain(t))), 2) for t in shipped_terrains()}
    out["top_speed_mps"] = {t: round(top_speed(veh, load_terrain(t)), 3) for t in shipped_terrains()}
    rows = table_one_study(veh, load_terrain("vinyl"), noise=0.05, seed=0)
    out["table_one_study"] = [{"N": n, "K": f.shear_modulus, "mu_sa": f.mu_sa, "mu_op": f.mu_op, "rms_Nm": f.rms} for n, f in rows]
    # closed vs open loop (Fig. 16) with an uncertain model
    real = vinyl.with_(vehicle=veh.replace(mass=36.0), terrain=vinyl.terrain.replace(mu_roll=0.06))
    cl, cr = straight(vinyl, 0.2, 10.0)
    truth = simulate(real, cl, cr)
    closed = simulate(vinyl, cl, cr)
    i_real = np.interp(np.arange(len(cl)) * vinyl.step_s + vinyl.step_s, truth.t, truth.i_l)
    opened = simulate(vinyl, i_real, i_real, open_loop=True)
    out["closed_vs_open_loop_rmse_mps"] = {"closed": float(np.sqrt(np.mean((closed.v - truth.v) ** 2))),
                                           "open": float(np.sqrt(np.mean((opened.v - truth.v) ** 2)))}
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.3))
    a = ax[0]
    radii = np.geomspace(0.2, 1e4, 200)
    wl, wr = wheel_speeds(0.2, 1 / radii, veh.wheel_radius, veh.width, 1.0)
    fl, fr = steady_resistance_fast(wl, wr, veh, vinyl.terrain)
    el, er = circle_torques(veh, vinyl.terrain, PAPER_RADII)
    a.semilogx(radii, fl, "C0", label="left (fast form)")
    a.semilogx(radii, fr, "C1", label="right (fast form)")
    a.semilogx(PAPER_RADII, el, "C0o", ms=4, label="left (exact, paper radii)")
    a.semilogx(PAPER_RADII, er, "C1o", ms=4, label="right (exact, paper radii)")
    a.set_xlabel("commanded radius [m]")
    a.set_ylabel("steady wheel torque [N m]")
    a.set_title("Fig. 9: CCW circles on vinyl")
    a.legend(fontsize=8)
    a = ax[1]
    a.plot(truth.t, truth.v, "k", lw=2, label="'real' vehicle (+16% mass, +62% mu_roll)")
    a.plot(closed.t, closed.v, "C2--", label=f"closed-loop model, rmse {out['closed_vs_open_loop_rmse_mps']['closed']:.3f}")
    a.plot(opened.t, opened.v, "C3", label=f"open-loop model, rmse {out['closed_vs_open_loop_rmse_mps']['open']:.3f}")
    a.set_xlabel("t [s]")
    a.set_ylabel("v [m/s]")
    a.set_title("Fig. 16: closed vs open loop, 0.2 m/s command")
    a.legend(fontsize=8)
    a = ax[2]
    asph = Model.load("p3at", "asphalt")
    for model, v, v0, s, L, lab in [(asph, 0.7, 0.7, 5.4, 3.0, "5.4 deg asphalt, 0.7 m/s: held"),
                                    (vinyl, 1.2, 0.9, 17.0, 1.0, "17 deg vinyl from 0.9 m/s: crossed"),
                                    (vinyl, 1.2, 0.3, 17.0, 1.0, "17 deg vinyl from 0.3 m/s: stalls")]:
        tr, crossed, _ = ramp_run(model, v, v0, s, L, duration=6.0)
        on = tr.s <= L
        a.plot(tr.s[on], tr.v[on], label=lab)
    a.set_xlabel("distance up the ramp [m]")
    a.set_ylabel("v [m/s]")
    a.set_title("Figs. 18-20: hills")
    a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "model.png", dpi=90)
    (ROOT / "bench" / "results").mkdir(parents=True, exist_ok=True)
    stamp.write(ROOT / "bench" / "results" / "model_report.json", out)
    print(json.dumps({k: v for k, v in out.items() if k != "table_one_study"}, indent=1))
    for r in out["table_one_study"]:
        if r["N"] in (2, 3, 4, 6, 8, 11, 16, 21, 26, 31):
            print(f"N={r['N']:2d} K={r['K']*1e3:.3f} mm mu_sa={r['mu_sa']:.4f} mu_op={r['mu_op']:.4f} rms={r['rms_Nm']:.3f}")


if __name__ == "__main__":
    main()
