"""``sbmpc diagnose`` (what the model gets wrong on a measured run, and why) and
``sbmpc synth`` (a measured-looking run with one hidden effect)."""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

from ..errors import InputError
from .compiling import model_note
from .files import Outputs, atomic, path_arg, write_json, write_text


def add_parsers(sub):
    p = sub.add_parser("diagnose", help="replay a measured run, find what the model gets wrong, name the cause",
                       description="Replay the logged commands of a measured run (CSV of docs/formats.md) through the "
                       "closed-loop model, fit every candidate model extension on the first 70 % of the run, score "
                       "it on the last 30 %, and name the cause (or 'none').")
    p.add_argument("run", type=path_arg, help="measured run CSV")
    p.add_argument("--vehicle", help="vehicle name or YAML (default: the run's '# vehicle:' or p3at)")
    p.add_argument("--terrain", help="terrain name or YAML (default: the run's '# terrain:' or vinyl)")
    p.add_argument("--json", type=path_arg, help="write the diagnosis JSON here")
    p.add_argument("--report", type=path_arg, help="write a markdown report with figures into this folder")
    p.add_argument("--vehicle-out", type=path_arg,
                   help="write the extended vehicle YAML here (default: extended_vehicle.yaml beside --json or in --report)")
    p.set_defaults(func=run_diagnose)

    s = sub.add_parser("synth", help="generate a measured-looking run with one hidden effect",
                       description="Simulate the closed-loop model with excitation commands and one effect of the "
                       "vocabulary (strength drawn from --seed), add sensor noise, write the run CSV.")
    from dynamics.synth import STRENGTHS
    s.add_argument("--effect", required=True, choices=tuple(STRENGTHS), help="the hidden effect")
    s.add_argument("--seed", type=int, default=0, help="draws the strength and the commands (default 0)")
    s.add_argument("--out", type=path_arg, required=True, help="run CSV to write")
    s.add_argument("--duration", type=float, default=90.0, help="seconds (default 90)")
    s.add_argument("--vehicle", default="p3at")
    s.add_argument("--terrain", default="vinyl")
    s.set_defaults(func=run_synth)


def _load_models(vehicle, terrain, run=None, path=None):
    """The vehicle and terrain: the options' (``--vehicle``, ``--terrain``), else the run's
    header lines (``# vehicle:``, ``# terrain:`` of the CSV at ``path``), else p3at and
    vinyl; a bad one is named with where it came from."""
    from dynamics import ParameterError, load_terrain, load_vehicle
    out = []
    for opt, key, default, load in (("--vehicle", "vehicle", "p3at", load_vehicle),
                                    ("--terrain", "terrain", "vinyl", load_terrain)):
        given = vehicle if key == "vehicle" else terrain
        header = run.meta.get(key) if run is not None else None
        try:
            if given is not None:
                out.append(load(given))
            elif header:                 # a file named in the run's header lies beside the run
                out.append(load(header, Path(path).parent if path is not None else None))
            else:
                out.append(load(default))
        except ParameterError as exc:
            where = opt if given is not None else f"{path}: its '# {key}:' line" if header else opt
            raise InputError(f"{where}: {exc}") from None
    return tuple(out)


def run_synth(args) -> int:
    from dynamics.runs import write_run
    from dynamics.synth import synth_run
    if not 1.0 <= args.duration <= 3600.0:
        raise InputError(f"--duration: expected seconds in [1, 3600], found {args.duration}")
    if not 0 <= args.seed <= 2 ** 31 - 1:
        raise InputError(f"--seed: expected an integer in [0, 2147483647], found {args.seed}")
    Outputs([args.vehicle, args.terrain]).file(args.out, "--out")
    vehicle, terrain = _load_models(args.vehicle, args.terrain)
    model_note()
    run, params = synth_run(args.effect, args.seed, vehicle, terrain, duration=args.duration)
    with atomic(args.out) as tmp:
        write_run(tmp, run)
    shown = ", ".join(f"{k} = {v:.4g}" for k, v in params.items())
    print(f"wrote {args.out}: {len(run)} samples, hidden effect {args.effect}" + (f" ({shown})" if shown else ""))
    return 0


def run_diagnose(args) -> int:
    from dynamics.discrepancy import check_run_length, diagnose, replay
    from dynamics.params import vehicle_to_yaml
    from dynamics.runs import RunError, read_run
    outs = Outputs([args.run, args.vehicle, args.terrain])
    outs.file(args.json, "--json")
    outs.file(args.vehicle_out, "--vehicle-out")
    if args.report is not None:
        outs.folder(args.report, "--report", ("report.md", "replay.png", "residuals.png")
                    + (() if args.vehicle_out else ("extended_vehicle.yaml",)))
    elif args.vehicle_out is None and args.json is not None:
        outs.file(args.json.parent / "extended_vehicle.yaml", "--json (extended_vehicle.yaml is written beside it)")
    try:
        run = read_run(args.run)
    except RunError as exc:
        raise InputError(str(exc)) from None
    outs.add_inputs([run.meta.get("vehicle"), run.meta.get("terrain")])
    try:
        check_run_length(run)
    except RunError as exc:
        raise InputError(str(exc)) from None
    vehicle, terrain = _load_models(args.vehicle, args.terrain, run, args.run)
    pitch = 0.0
    if "slope_deg" in run.meta:
        try:
            slope = float(run.meta["slope_deg"])
        except ValueError:
            slope = math.nan
        if not -45.0 <= slope <= 45.0:
            raise InputError(f"{args.run}: '# slope_deg:' expected a grade in degrees within [-45, 45], "
                             f"found {run.meta['slope_deg']!r:.40}")
        pitch = math.radians(slope)
    model_note()
    t0 = time.perf_counter()

    def progress(i, n, effect):
        if sys.stderr.isatty():
            print(f"  fitting {effect} ({i + 1}/{n}), {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    try:
        d = diagnose(run, vehicle, terrain, pitch, progress=progress)
    except RunError as exc:              # (a column with the same value in every row)
        raise InputError(str(exc)) from None
    elapsed = time.perf_counter() - t0
    out_vehicle = args.vehicle_out
    if out_vehicle is None and args.report is not None:
        out_vehicle = args.report / "extended_vehicle.yaml"
    elif out_vehicle is None and args.json is not None:
        out_vehicle = args.json.parent / "extended_vehicle.yaml"
    print(f"{args.run}: {len(run)} samples, {len(run.segments())} segment(s), channels {', '.join(d.channels)}; "
          f"diagnosed in {elapsed:.1f} s")
    print(f"baseline held-out error {d.baseline_error:.2f} (1 = sensor noise)")
    print(f"{'candidate':18s} {'held-out':>9s} {'gain':>7s} {'BIC change':>11s} {'held-out BIC':>12s}  "
          "parameters (± standard error)")
    for c in d.candidates:
        ps = ", ".join(f"{k} = {v:.4g}" + (f" ± {d_se:.2g}" if math.isfinite(d_se) else " (standard error: n/a)")
                       + _at(c, k)
                       for (k, v), d_se in zip(c.params.items(), c.stderr.values()))
        pose = (f"  [fitted to the pose: held-out pose gain {c.pose_gain:.2f}]" if c.fitted_on == "pose" else
                "  [fitted on the held-out part: the training part cannot test it]" if c.fitted_on == "heldout" else "")
        ev = ("n/a (pose)" if c.fitted_on == "pose" else "n/a") if not math.isfinite(c.evidence) else f"{c.evidence:.0f}"
        print(f"{c.effect:18s} {c.heldout_error:9.2f} {c.gain:7.3f} {c.bic_delta:11.0f} {ev:>12s}  {ps}{pose}")
    print(cause_line(d))
    for line in caveats(d):
        print(f"caveat: {line}")
    pose_line = _pose_line(d.pose)
    if pose_line:
        print(pose_line)
    if out_vehicle is not None:
        note = f"extended by sbmpc diagnose from {args.run}: cause {d.cause}"
        if d.cause == "grade":
            on = ("" if d.extended_toward_deg is None else
                  f" rising towards heading {d.extended_toward_deg:.0f} deg")
            note += f" (the run was on a {d.extended_pitch_deg:.2f} deg grade{on}; the vehicle is unchanged)"
        if d.cause == "turning_friction":
            note += (f" (the terrain's mu_sa, mu_op are {d.extended_terrain.mu_sa:.3f}, {d.extended_terrain.mu_op:.3f};"
                     " the vehicle is unchanged)")
        out_vehicle.parent.mkdir(parents=True, exist_ok=True)
        write_text(out_vehicle, vehicle_to_yaml(extended_named(d.extended_vehicle, vehicle, d.cause), note))
    doc = d.to_json(str(out_vehicle) if out_vehicle else None)
    doc["run"] = str(args.run)
    doc["diagnosis_time_s"] = elapsed
    wrote = [out_vehicle] if out_vehicle is not None else []
    if args.json:
        write_json(args.json, doc)
        wrote.append(args.json)
    if args.report:
        args.report.mkdir(parents=True, exist_ok=True)
        write_report(args.report, run, vehicle, terrain, pitch, d, doc, replay)
        wrote += [args.report / name for name in ("report.md", "replay.png", "residuals.png")]
    if wrote:
        print("wrote " + ", ".join(map(str, wrote)))
    return 0


def cause_line(d) -> str:
    """'cause: NAME (why)': the verdict and what it rests on, as the terminal and the
    report both say it."""
    from dynamics.discrepancy import EVIDENCE, MARGIN, SHARE_MIN, TRAINING_EVIDENCE
    named = next((c for c in d.candidates if c.effect == d.cause), None)
    in_pose = named is not None and named.fitted_on == "pose"
    if d.cause == "unexplained":
        r = d.residual
        sides = r.get("sides", {})
        side = ""
        if len(sides) == 2 and max(sides.values()) > 1.5 * min(sides.values()):
            side = f", most on the {max(sides, key=sides.get)} side"
        return (f"cause: unexplained (the model misses {r['excess']:.1f} noise units over the noise (held-out error "
                f"{r['heldout_error']:.1f}) that no candidate explains: the best, {d.hint}, explains "
                f"{100 * (d.share or 0.0):.0f} % of it, under the {100 * SHARE_MIN:.0f} % that names a cause; "
                f"it sits most in {r.get('most_in') or 'the whole run'}{side})")
    if d.cause == "none":
        why = (f" (no candidate gains {100 * MARGIN:.0f} % on held-out data with very strong evidence (BIC "
               f"falls by more than {EVIDENCE:g} on both parts, or by more than {TRAINING_EVIDENCE:g} on the one "
               "part that sees it), nor halves the pose error)")
    elif d.decided_on == "training":
        why = (f" (the held-out part cannot test it: its prediction there moves by {named.reach:.3f} noise units; "
               f"training evidence {named.train_evidence:.0f})")
    elif d.decided_on == "heldout_only":
        why = (f" (the training part cannot test it: its prediction there moves by {named.train_reach:.3f} noise "
               f"units; fitted on the held-out part: gain there {d.gain:.2f}, BIC change there "
               f"{named.evidence:.0f})")
    elif in_pose:
        why = (f" (fitted to and decided on the pose: held-out pose gain {d.gain:.2f}; its wheel-speed and "
               f"current gain {named.gain:.2f})")
    else:
        ev = f"{named.evidence:.0f}" if math.isfinite(named.evidence) else "n/a"
        why = f" (held-out gain {d.gain:.2f}, held-out BIC change {ev})"
    return f"cause: {d.cause}{why}"


def caveats(d) -> list:
    """What weakens the named cause: its fit ended at a bound of the candidate's range,
    or other candidates explain the held-out data within noise of it."""
    out = []
    named = next((c for c in d.candidates if c.effect == d.cause), None)
    if named is not None and named.at_bound:
        from dynamics.discrepancy import bound_side
        sides = [bound_side(d.cause, k, named.params[k]) for k in named.at_bound]
        ends = ", ".join(f"the {side} bound of {k}" for k, side in zip(named.at_bound, sides))
        want = {frozenset({"lower"}): "less than", frozenset({"upper"}): "more than"}.get(
            frozenset(sides), "values beyond what")
        out.append(f"the {d.cause} fit ended at {ends} (the data may want {want} the candidate allows, or the "
                   "cause is another effect it imitates)")
    if d.rivals:
        out.append(f"{', '.join(d.rivals)} explain{'s' if len(d.rivals) == 1 else ''} the held-out data within "
                   f"noise of {d.cause} (gains within 0.02): the data cannot tell them apart")
    return out


def extended_named(extended, vehicle, cause: str):
    """The extended vehicle named after the one it extends and the cause
    (``p3at+wheel_radius``) where any of its parameters differs from it, so that a run
    driven by it does not read as one driven by the model it corrects; else as it is
    (grade and turning_friction leave the vehicle unchanged)."""
    from dataclasses import fields, replace
    same = all(getattr(extended, f.name) == getattr(vehicle, f.name) for f in fields(vehicle)
               if f.name not in ("name", "description", "sources"))
    return extended if same else replace(extended, name=f"{vehicle.name}+{cause}")


def _at(c, k: str) -> str:
    """' (at its lower bound)' or ' (at its upper bound)' where candidate c's parameter k
    ended at a bound of its range (``Candidate.at_bound``), else ''."""
    if k not in c.at_bound:
        return ""
    from dynamics.discrepancy import bound_side
    return f" (at its {bound_side(c.effect, k, c.params[k])} bound)"


def _n(x: float, fmt: str) -> str:
    """A number for the report, 'n/a' where it is not finite (too few samples)."""
    return format(x, fmt) if math.isfinite(x) else "n/a"


def _pose_line(pose: dict) -> str:
    """One line on the held-out relative pose error, baseline -> extended (or '')."""
    b, e = pose.get("baseline"), pose.get("extended")
    if not b:
        return ""
    line = (f"pose (relative error over {b['window_s']:g} s windows, held-out): translation "
            f"{b['trans_rmse_m']:.3f} m, heading {b['rot_rmse_rad']:.3f} rad")
    if e and e is not b:
        line += f" -> extended {e['trans_rmse_m']:.3f} m, {e['rot_rmse_rad']:.3f} rad"
    return line


def write_report(folder: Path, run, vehicle, terrain, pitch, d, doc, replay) -> None:
    """report.md with figures: measured vs baseline vs extended, residuals, the ranking."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from dynamics.discrepancy import MARGIN, TRAIN_FRACTION
    base = replay(run, vehicle, terrain, pitch)
    ext = replay(run, d.extended_vehicle, d.extended_terrain or terrain, pitch + d.extended_pitch(run))
    t = run.t
    fig, ax = plt.subplots(len(d.channels), 1, figsize=(11, 2.2 * len(d.channels)), sharex=True)
    for a, c in zip(np.atleast_1d(ax), d.channels):
        a.plot(t, run[c], ".", ms=1.5, color="0.5", label="measured")
        a.plot(t, base[c], lw=1, label="baseline model")
        if d.cause not in ("none", "unexplained"):
            a.plot(t, ext[c], lw=1, label=f"extended ({d.cause})")
        a.set_ylabel(c)
        a.axvline(t[0] + TRAIN_FRACTION * (t[-1] - t[0]), color="k", ls=":", lw=1)
    np.atleast_1d(ax)[0].legend(fontsize=8, loc="upper right")
    np.atleast_1d(ax)[-1].set_xlabel("t [s] (dotted: training | held-out)")
    fig.tight_layout()
    fig.savefig(folder / "replay.png", dpi=100)
    plt.close(fig)
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.2))
    for c in d.channels[:2]:
        ax[0].plot(t, (run[c] - base[c]) / d.scales[c], lw=0.6, label=f"{c} baseline")
        if d.cause not in ("none", "unexplained"):
            ax[0].plot(t, (run[c] - ext[c]) / d.scales[c], lw=0.6, label=f"{c} extended")
    ax[0].set_ylabel("residual [noise units]")
    ax[0].set_xlabel("t [s]")
    ax[0].legend(fontsize=7)
    names = [c.effect for c in d.candidates]
    ax[1].barh(names[::-1], [c.gain for c in d.candidates][::-1], color="tab:blue")
    ax[1].axvline(MARGIN, color="r", ls="--", lw=1)
    ax[1].set_xlabel("held-out gain (red: margin)")
    fig.tight_layout()
    fig.savefig(folder / "residuals.png", dpi=100)
    plt.close(fig)
    lines = [f"# Diagnosis of `{doc['run']}`", "",
             f"**{cause_line(d).replace('cause: ', 'Cause: ', 1)}**", "",
             *[f"Caveat: {line}." for line in caveats(d)], *([""] if caveats(d) else []),
             f"Baseline held-out error: {d.baseline_error:.2f} noise units (1 = explained within the sensor noise). "
             f"Ljung-Box Q of the wheel-speed residuals (20 lags): {_n(d.baseline_whiteness_q, '.0f')}.", "",
             "Where the baseline errs (noise units): " + ", ".join(f"{k} {v:.2f}" for k, v in d.where.items()), "",
             f"Peak cross-correlation of the residuals with the command changes: {d.xcorr['peak_rho']:.2f} at a lag "
             f"of {d.xcorr['lag_s']:.3f} s.", "",
             *([_pose_line(d.pose).capitalize() + ".", ""] if d.pose else []),
             "| candidate | held-out error | gain | BIC change | parameters | whiteness Q |", "|---|---|---|---|---|---|"]
    for c in d.candidates:
        ps = ", ".join(f"{k} = {v:.4g} ± {_n(c.stderr[k], '.2g')}" + _at(c, k)
                       for k, v in c.params.items())
        gain = f"{c.gain:.3f}" + (f" (pose {c.pose_gain:.3f})" if c.fitted_on == "pose" else "")
        lines.append(f"| {c.effect} | {c.heldout_error:.2f} | {gain} | {c.bic_delta:.0f} | {ps} | "
                     f"{_n(c.whiteness_q, '.0f')} |")
    lines += ["", "![measured vs baseline vs extended](replay.png)", "", "![residuals and ranking](residuals.png)", ""]
    write_text(folder / "report.md", "\n".join(lines))
