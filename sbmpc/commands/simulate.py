"""``sbmpc simulate``: run one manoeuvre through the closed-loop (or open-loop) model."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import InputError
from .files import Outputs, atomic, path_arg, write_json


def add_parser(sub):
    p = sub.add_parser("simulate", help="simulate a manoeuvre: straight, circle, ramp, lemniscate",
                       description="Simulate a manoeuvre with the closed-loop model: straight at --v; a "
                       "circle with --radius (commanded radius, positive = left); a ramp with --slope-deg "
                       "--v0 --length; or --lemniscate (paper eqs. 29, 30).")
    p.add_argument("--vehicle", default="p3at", help="shipped vehicle name or YAML path (default p3at)")
    p.add_argument("--terrain", default="vinyl", help="shipped terrain name or YAML path (default vinyl)")
    p.add_argument("--v", type=float, help="desired speed [m/s]")
    p.add_argument("--radius", type=float, help="commanded turning radius [m], positive turns left")
    p.add_argument("--slope-deg", type=float, help="ramp grade [deg]")
    p.add_argument("--v0", type=float, help="speed entering the ramp [m/s]")
    p.add_argument("--length", type=float, help="ramp length along the slope [m]")
    p.add_argument("--lemniscate", action="store_true", help="follow the paper's lemniscate (eqs. 29, 30)")
    p.add_argument("--commands", type=path_arg, metavar="CSV", help="drive the commanded wheel speeds of a "
                   "commands CSV (sbmpc protocol's, or any with t, wl_cmd, wr_cmd), each held until the next")
    p.add_argument("--duration", type=float, help="simulated time [s] (default 10; ramp 20; lemniscate 18 + 3 s run-up)")
    p.add_argument("--dt", type=float, help="integration step [s] (default: the controller period, 1 ms)")
    p.add_argument("--open-loop", action="store_true",
                   help="drive the open-loop model (no PID, paper Fig. 16) with the current profile the closed loop applies")
    p.add_argument("--json", type=path_arg, help="write the trajectory JSON here")
    p.add_argument("--plot", type=path_arg, help="write a PNG of speeds, torques, power and path here")
    p.add_argument("--run", type=path_arg, metavar="CSV", help="write the drive as a measured run CSV (100 Hz: "
                   "commands, wheel speeds, torques, currents, pose) for sbmpc calibrate and diagnose")
    p.add_argument("--noise", type=int, metavar="SEED", help="with --run: add sensor noise drawn from SEED (the "
                   "levels of sbmpc synth)")
    p.set_defaults(func=run)
    return p


def _need(value, flag, what):
    if value is None:
        raise InputError(f"{flag}: expected {what}, found nothing")
    if not math.isfinite(value):
        raise InputError(f"{flag}: expected {what}, found {value}")
    return value


PLOT_FORMATS = ("png", "pdf", "svg", "jpg", "jpeg")


def plot_format(path) -> str | None:
    """The figure format of ``--plot PATH``: its suffix's, PNG when it has none; an
    InputError, before any work, for another suffix (the temporary file's name made
    matplotlib read a path without one as format 'tmp': exit 3 after the JSON was
    written)."""
    if path is None:
        return None
    suffix = Path(path).suffix.lower().lstrip(".")
    if not suffix:
        return "png"
    if suffix not in PLOT_FORMATS:
        raise InputError(f"--plot: expected a figure file ending in {', '.join('.' + f for f in PLOT_FORMATS)} "
                         f"(or no suffix: PNG), found '{path}'")
    return suffix


MAX_STEPS = 20_000_000     # steps of one simulation (its trajectory keeps about 200 bytes a step)


def run(args) -> int:
    from dynamics import ParameterError
    from .compiling import model_note
    from dynamics.manoeuvres import circle, lemniscate, ramp_run, straight
    from dynamics.simulate import Model, simulate

    outs = Outputs([args.vehicle, args.terrain, args.commands])
    outs.file(args.json, "--json")
    outs.file(args.run, "--run")
    if args.noise is not None and args.run is None:
        raise InputError(f"--noise: expected with --run (the measured run it adds noise to), found --noise {args.noise} alone")
    outs.file(args.plot, "--plot")
    fmt = plot_format(args.plot)
    if args.dt is not None and not (1e-5 <= args.dt <= 0.05):
        raise InputError(f"--dt: expected a step between 1e-05 and 0.05 s, found {args.dt}")
    try:
        model = Model.load(args.vehicle, args.terrain, args.dt)
    except ParameterError as exc:
        raise InputError(str(exc)) from None
    ramp = any(x is not None for x in (args.slope_deg, args.v0, args.length))
    if sum([ramp, args.radius is not None, args.lemniscate, args.commands is not None]) > 1:
        raise InputError("expected one manoeuvre (--radius, the ramp options, --lemniscate or --commands), found several")
    if args.open_loop and args.run is not None:
        raise InputError("--run: expected a closed-loop manoeuvre (the run logs commanded wheel speeds), found --open-loop")
    if ramp and args.run is not None:
        raise InputError("--run: expected a straight, circle, lemniscate or --commands manoeuvre, found a ramp")
    if args.duration is not None and not (0 < args.duration <= 3600):
        raise InputError(f"--duration: expected seconds in (0, 3600], found {args.duration}")
    steps = (args.duration or 21.0) / model.step_s
    if steps > MAX_STEPS:
        raise InputError(f"--duration / --dt: expected at most {MAX_STEPS:,} steps (about "
                         f"{MAX_STEPS * 200 // 1_000_000_000} GB of trajectory), found {steps:,.0f}; "
                         "shorten the run or use a longer step")
    if args.v is not None and abs(args.v) > 20:
        raise InputError(f"--v: expected a speed of at most 20 m/s in magnitude, found {args.v}")
    dt = model.step_s
    if args.commands is not None:
        from ..protocol import ProtocolError, held, read_commands
        try:
            t_cmd, wl_cmd, wr_cmd, cmd_meta = read_commands(args.commands)
        except ProtocolError as exc:
            raise InputError(str(exc)) from None
        end = args.duration or (t_cmd[-1] + float(np.median(np.diff(t_cmd))))
        if end / dt > MAX_STEPS:
            raise InputError(f"--commands: expected at most {MAX_STEPS:,} steps, found {end / dt:,.0f}")
    elif ramp:
        v = _need(args.v, "--v", "a desired speed in m/s")
        slope = _need(args.slope_deg, "--slope-deg", "a grade in degrees")
        v0 = _need(args.v0, "--v0", "an entry speed in m/s")
        length = _need(args.length, "--length", "a ramp length in metres")
        if not -60 < slope < 60:
            raise InputError(f"--slope-deg: expected a grade strictly between -60 and 60 degrees, found {slope}")
        if not 0 < length <= 10_000:
            raise InputError(f"--length: expected a length in (0, 10000] metres, found {length:g}")
        if abs(v0) > 20:
            raise InputError(f"--v0: expected a speed of at most 20 m/s in magnitude, found {v0}")
        if args.open_loop:
            raise InputError("--open-loop: expected a straight, circle or lemniscate manoeuvre, found a ramp")
    elif not args.lemniscate:
        v = _need(args.v, "--v", "a desired speed in m/s")
        if args.radius is not None and (args.radius == 0 or not math.isfinite(args.radius)):
            raise InputError(f"--radius: expected a non-zero radius in metres, found {args.radius}")
    model_note()             # every option checked: what follows computes
    info: dict = {}
    if args.commands is not None:
        cl, cr = held(t_cmd, wl_cmd, dt, end), held(t_cmd, wr_cmd, dt, end)
        manoeuvre = "commands"
        info = {"commands": str(args.commands)}
    elif args.lemniscate:
        dur = args.duration or 18.0
        cl, cr = lemniscate(model, duration=dur, dt=dt)
        manoeuvre = "lemniscate"
    elif ramp:
        traj, crossed, t_top = ramp_run(model, v, v0, slope, length, args.duration or 20.0, dt)
        manoeuvre = "ramp"
        info = {"slope_deg": slope, "length_m": length, "v0": v0, "crossed": crossed, "time_to_top_s": t_top}
    else:
        dur = args.duration or 10.0
        if args.radius is not None:
            cl, cr = circle(model, v, args.radius, dur, dt)
            manoeuvre = "circle"
            info = {"radius_m": args.radius}
        else:
            cl, cr = straight(model, v, dur, dt)
            manoeuvre = "straight"
    if not ramp:
        if args.open_loop:
            # Fig. 16: the open-loop model driven by the current (tau = K_tau V) that the
            # closed loop applies for the same manoeuvre.
            closed = simulate(model, cl, cr, record_dt=dt)
            cl, cr = closed.i_l[1:].copy(), closed.i_r[1:].copy()
            info["open_loop_input"] = "closed-loop current profile"
        traj = simulate(model, cl, cr, open_loop=args.open_loop, record_dt=max(dt, 0.01))
    summary = {
        "final_speed_mps": float(traj.v[-1]), "mean_speed_mps": float(np.mean(traj.v)),
        "final_yaw_rate": float(traj.yaw_rate[-1]), "final_tau_l": float(traj.tau_l[-1]),
        "final_tau_r": float(traj.tau_r[-1]), "energy_J": float(traj.energy_J[-1]),
        "distance_m": float(np.sum(np.hypot(np.diff(traj.x), np.diff(traj.y)))), "stalled": traj.stalled,
    }
    print(f"{manoeuvre} on {model.terrain.name} with {model.vehicle.name}"
          f"{' (open loop)' if args.open_loop else ''}: {traj.t[-1]:.2f} s simulated")
    for key, value in {**info, **summary}.items():
        print(f"  {key:22s} {value:.4g}" if isinstance(value, float) else f"  {key:22s} {value}")
    if manoeuvre in ("straight", "circle") and not args.open_loop and len(cl):
        short = _short_of_command(traj, cl[-1], cr[-1])
        if short:
            print(f"note: {short}")
    if args.json:
        doc = {"schema": "sbmpc.simulate/1", "manoeuvre": manoeuvre, "vehicle": model.vehicle.name,
               "terrain": model.terrain.name, "open_loop": bool(args.open_loop), "dt_s": dt,
               "stalled": traj.stalled, **info, "summary": summary, "trajectory": traj.to_json()}
        write_json(args.json, doc)
    if args.run:
        _write_measured(args, model, cl, cr, manoeuvre)
    if args.plot:
        from ..figures import plot_trajectory
        with atomic(args.plot) as tmp:
            plot_trajectory(traj, tmp, f"{manoeuvre} on {model.terrain.name}", fmt)
    return 0


def _write_measured(args, model, cl, cr, manoeuvre: str) -> None:
    """--run: the manoeuvre as a measured run CSV (dynamics.synth.measured: 100 Hz, noise from --noise)."""
    from dynamics.runs import Run, write_run
    from dynamics.synth import measured
    cols = measured(model, cl, cr, args.noise)
    note = f"sbmpc simulate {manoeuvre}" + (f" {args.commands.name}" if args.commands is not None else "")
    meta = {"vehicle": model.vehicle.name, "terrain": model.terrain.name, "slope_deg": "0",
            "note": note + (f", sensor noise seed {args.noise}" if args.noise is not None else ", no noise")}
    with atomic(args.run) as tmp:
        write_run(tmp, Run(cols, meta, str(args.run)))
    print(f"wrote {args.run} ({len(cols['t'])} rows at 100 Hz)")


def _short_of_command(traj, cmd_l: float, cmd_r: float, settle_s: float = 1.0) -> str:
    """A note when the drive stays short of the commanded wheel speeds [rad/s] (by more
    than 5 % of the larger command and 0.05 rad/s) at least ``settle_s`` after its
    rate-limited reference reached them: the command is beyond what the motors deliver
    there (the voltage or current limit, eqs. 26, 27), so the vehicle drives another
    path than the commanded one (a circle at 1 m/s on vinyl runs nearly straight); ''
    when it reaches them, or while the reference is still ramping (no verdict yet)."""
    tol = max(0.05 * max(abs(cmd_l), abs(cmd_r)), 0.05)
    at = np.nonzero((np.abs(traj.ref_l - cmd_l) <= 1e-6 * (1 + abs(cmd_l)))
                    & (np.abs(traj.ref_r - cmd_r) <= 1e-6 * (1 + abs(cmd_r))))[0]
    if not at.size or traj.t[-1] - traj.t[at[0]] < settle_s:
        return ""
    wl, wr = float(traj.wl[-1]), float(traj.wr[-1])
    short = [abs(w) < abs(c) - tol and w * c >= 0.0 or w * c < 0.0 for w, c in ((wl, cmd_l), (wr, cmd_r))]
    if not any(short):
        return ""
    sides = " and ".join(f"{name} {w:.2f} of {c:.2f} rad/s" for name, w, c, s in
                         (("left", wl, cmd_l, short[0]), ("right", wr, cmd_r, short[1])) if s)
    return (f"the drive stays short of the commanded wheel speeds ({sides}): the command is beyond what the "
            "motors deliver here (voltage or current limit), so the path driven is not the commanded one; a "
            "lower --v reaches it")
