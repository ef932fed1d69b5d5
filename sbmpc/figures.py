"""Matplotlib figures (headless, Agg)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def plot_trajectory(traj, path, title: str = "", fmt: str | None = None) -> None:
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
    fig.savefig(path, dpi=110, format=fmt)
    plt.close(fig)


PLAN_COLOURS = {"time": "tab:orange", "energy": "tab:purple"}   # (the terrain map is green)


def _relief(ax, emap):
    """The map as shaded relief with height contours; returns the image."""
    import numpy as np
    from matplotlib.colors import LightSource
    H = emap.heights
    x0, x1, y0, y1 = emap.extent
    ls = LightSource(azdeg=315, altdeg=45)
    span = max(float(np.ptp(H)), 1e-6)
    rgb = ls.shade(H, cmap=plt.get_cmap("terrain"), vert_exag=max(1.0, 3.0 / span) * emap.resolution,
                   blend_mode="soft", vmin=H.min() - 0.3 * span, vmax=H.max() + 0.3 * span)
    if emap.terrain_layer is not None and len(emap.terrain_names) > 1:
        tint = plt.get_cmap("Set2")(emap.terrain_layer % 8)[..., :3]
        rgb[..., :3] = 0.6 * rgb[..., :3] + 0.4 * tint
    h = (x1 - x0) / max(H.shape[1] - 1, 1) / 2
    ax.imshow(rgb, origin="lower", extent=(x0 - h, x1 + h, y0 - h, y1 + h), interpolation="bilinear")
    if span > 0.05:
        xs = np.linspace(x0, x1, H.shape[1])
        ys = np.linspace(y0, y1, H.shape[0])
        cs = ax.contour(xs, ys, H, levels=10, colors="k", linewidths=0.4, alpha=0.6)
        ax.clabel(cs, fontsize=6, fmt="%.1f m")
    ax.set_xlabel("x [m] (east)")
    ax.set_ylabel("y [m] (north)")
    ax.set_aspect("equal")


def _map_and_panels(emap, scenario, n: int, size, ratio: float):
    """A figure with the map (relief, start, goal disc) on the left and ``n`` stacked
    panels on the right: (fig, map axes, [panel axes])."""
    fig = plt.figure(figsize=size)
    gs = fig.add_gridspec(n, 2, width_ratios=[ratio, 1.0])
    ax = fig.add_subplot(gs[:, 0])
    _relief(ax, emap)
    s, g = scenario.start, scenario.goal
    ax.plot(s["x"], s["y"], "ko", ms=6)
    ax.add_patch(plt.Circle((g["x"], g["y"]), g["radius"], fill=False, ec="k", lw=1.5))
    return fig, ax, [fig.add_subplot(gs[i, 1]) for i in range(n)]


def plot_compare(emap, plans: dict, scenario, path, title: str = "") -> None:
    """PNG comparing plans ({label: Plan}): the map with the paths, and speed, battery
    power and cumulative energy along each path."""
    import numpy as np
    fig, ax, axes = _map_and_panels(emap, scenario, 3, (13, 7.2), 1.25)
    for label, p in plans.items():
        if not p.found:
            continue
        tr = p.trajectory
        c = PLAN_COLOURS.get(label, "tab:blue")
        ax.plot(tr["x"], tr["y"], color=c, lw=2.2,
                label=f"{label}-optimal: {p.travel_time_s:.1f} s, {p.energy_J:.0f} J, {p.length_m:.1f} m")
        d = np.r_[0.0, np.cumsum(np.hypot(np.diff(tr["x"]), np.diff(tr["y"])))]
        axes[0].plot(d, tr["v"], color=c, label=label)
        axes[1].plot(d, tr["power_W"], color=c, lw=0.8)
        axes[2].plot(d, tr["energy_J"] - tr["energy_J"][0], color=c)
    found = [p for p in plans.values() if p.found]
    if found:
        ax.legend(loc="upper left", fontsize=8, framealpha=0.85)
        axes[0].legend(fontsize=8)
    else:
        reason = next(iter(plans.values())).reason or ""
        ax.text(0.5, 0.5, "no path\n" + reason[:80], transform=ax.transAxes, ha="center", va="center",
                fontsize=10, bbox=dict(facecolor="white", alpha=0.85))
    ax.set_title(title)
    for a, lab in zip(axes, ("speed [m/s]", "battery power [W]", "energy used [J]")):
        a.set_ylabel(lab)
        a.grid(alpha=0.3)
    axes[-1].set_xlabel("distance along the path [m]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


RUN_COLOURS = ("tab:red", "tab:blue", "tab:purple", "tab:olive")


def plot_runs(emap, runs: dict, scenario, path, title: str = "") -> None:
    """PNG comparing receding-horizon runs ({label: RunResult}): the map with each run's
    first plan (dashed), executed path (solid) and re-plan points (dots); and predicted
    vs executed travel time and energy of each run as bars."""
    import numpy as np
    fig, ax, bars = _map_and_panels(emap, scenario, 2, (13, 6.4), 1.35)
    labels = list(runs)
    for i, (label, r) in enumerate(runs.items()):
        c = RUN_COLOURS[i % len(RUN_COLOURS)]
        first = r.plans[0].plan if r.plans else None
        if first is not None and first.found:
            ax.plot(first.trajectory["x"], first.trajectory["y"], "--", color=c, lw=1.2, alpha=0.8)
        tr = r.trajectory
        if len(tr.get("x", ())):
            ax.plot(tr["x"], tr["y"], color=c, lw=2.2,
                    label=f"{label}: {r.status}, {r.replans} re-plans")
        pts = np.array([(p.x, p.y) for p in r.plans[1:]])
        if len(pts):
            ax.plot(pts[:, 0], pts[:, 1], "o", color=c, ms=4, mec="k", mew=0.5)
        pred = r.predicted
        for a, key in zip(bars, ("travel_time_s", "energy_J")):
            ex = getattr(r, key)
            a.bar(i - 0.18, pred[key] or 0.0, 0.36, color=c, alpha=0.45, label="predicted" if i == 0 else None)
            a.bar(i + 0.18, ex or 0.0, 0.36, color=c, label="executed" if i == 0 else None)
    for a, lab in zip(bars, ("travel time [s]", "energy [J]")):
        a.set_xticks(range(len(labels)), labels, fontsize=8)
        a.set_ylabel(lab)
        a.grid(alpha=0.3, axis="y")
    bars[0].legend(fontsize=8)
    ax.legend(loc="upper left", fontsize=8, framealpha=0.85)
    ax.set_title("dashed: first plan; solid: executed; dots: re-plans", fontsize=9)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
