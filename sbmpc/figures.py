"""Matplotlib figures (headless, Agg)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def plot_trajectory(traj, path, title: str = "") -> None:
    """PNG of a simulated run: speed and wheel speeds, torques, battery power and energy,
    and the path seen from above."""
    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5))
    t = traj.t
    a = ax[0, 0]
    a.plot(t, traj.v, label="v [m/s]", lw=2)
    a.set_xlabel("t [s]")
    a2 = a.twinx()
    a2.plot(t, traj.wl, "C1", lw=1, label="w_l [rad/s]")
    a2.plot(t, traj.wr, "C2", lw=1, label="w_r [rad/s]")
    a2.plot(t, traj.ref_l, "C1:", lw=1, label="ref_l")
    a2.plot(t, traj.ref_r, "C2:", lw=1, label="ref_r")
    a.set_ylabel("speed [m/s]")
    a2.set_ylabel("wheel speed [rad/s]")
    a.legend(loc="upper left")
    a2.legend(loc="lower right", fontsize=8)
    a.set_title("speeds")
    a = ax[0, 1]
    a.plot(t, traj.tau_l, label="tau_l")
    a.plot(t, traj.tau_r, label="tau_r")
    a.set_xlabel("t [s]")
    a.set_ylabel("wheel torque [N m]")
    a.legend()
    a.set_title("torques")
    a = ax[1, 0]
    a.plot(t, traj.power_W, label="battery power [W]")
    a.set_xlabel("t [s]")
    a.set_ylabel("power [W]")
    a2 = a.twinx()
    a2.plot(t, traj.energy_J, "C3", label="energy [J]")
    a2.set_ylabel("energy [J]")
    a.legend(loc="upper left")
    a2.legend(loc="lower right")
    a.set_title("power and energy")
    a = ax[1, 1]
    a.plot(traj.x, traj.y)
    a.plot(traj.x[:1], traj.y[:1], "go", label="start")
    a.plot(traj.x[-1:], traj.y[-1:], "rs", label="end")
    a.set_aspect("equal", adjustable="datalim")
    a.set_xlabel("x [m]")
    a.set_ylabel("y [m]")
    a.legend()
    a.set_title("path")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
