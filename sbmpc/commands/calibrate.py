"""``sbmpc calibrate``: the vehicle's and terrain's parameters fitted to measured runs."""
from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from .files import Outputs, path_arg, write_json, write_text


def add_parsers(sub):
    c = sub.add_parser("calibrate", help="fit the vehicle's and terrain's parameters to measured runs, write the "
                       "files to plan with, then diagnose on top",
                       description="Calibrate: fit every parameter the runs excite (mass, torque constant, "
                       "current limit, reference acceleration, rolling resistance, the turning friction mu_sa and mu_op) jointly on the model's replay "
                       "of the training part of each run (the first 70 %), keep at its prior every parameter the "
                       "runs cannot pin (standard error over 25 % of the value, or correlated beyond 0.95 with "
                       "another) and say so, score nominal against calibrated on the held-out 30 %, write a "
                       "vehicle and a terrain YAML (each value with its source) that plan, run --truth and "
                       "scenarios take as they are, then diagnose each run on top: every add-on effect fitted jointly "
                       "with the calibrated parameters, named where its held-out evidence is decisive "
                       "(docs/validation.md).")
    c.add_argument("runs", nargs="+", type=path_arg, metavar="RUN", help="run CSV files (docs/formats.md), all of "
                   "one vehicle on one terrain")
    c.add_argument("--vehicle", help="the base vehicle, a shipped name or YAML (default: the first run's "
                   "# vehicle:)")
    c.add_argument("--terrain", help="the base terrain, a shipped name or YAML (default: the first run's # terrain:)")
    c.add_argument("--out", type=path_arg, required=True, help="folder for the calibrated vehicle and terrain "
                   "YAML and calibration.json")
    c.add_argument("--only", help="comma-separated parameters to consider (default: all the runs excite: mass, "
                   "torque_constant, current_limit, ref_accel, mu_roll, mu_sa, mu_op)")
    c.add_argument("--effects", help="comma-separated add-on effects the diagnosis tries (default: every one of "
                   "sbmpc diagnose's)")
    c.add_argument("--no-diagnose", action="store_true", help="skip the diagnosis on the calibrated model")
    c.set_defaults(func=run_calibrate)


def _names(text, allowed, flag: str, what: str):
    """A comma-separated list of names among ``allowed`` (None where not given)."""
    if not text:
        return None
    names = [s.strip() for s in text.split(",") if s.strip()]
    bad = [s for s in names if s not in allowed]
    if bad:
        raise InputError(f"{flag}: expected {what} among {', '.join(allowed)}, found {bad[0]!r}")
    return names


def _base(kind: str, given, runs):
    from dynamics import ParameterError, load_terrain, load_vehicle
    name = given or runs[0].meta.get(kind)
    if not name:
        raise InputError(f"--{kind}: expected the base {kind} (a shipped name or a YAML file), found none given "
                         f"and no '# {kind}:' line in {runs[0].source}")
    try:
        return (load_vehicle if kind == "vehicle" else load_terrain)(name)
    except ParameterError as exc:
        raise InputError(f"--{kind}: {exc}") from None


def run_calibrate(args) -> int:
    from dynamics.runs import RunError, read_run
    from ..calibration import PARAMS, calibrate
    outs = Outputs(list(args.runs) + [args.vehicle, args.terrain])
    outs.folder(args.out, "--out")
    runs = []
    for p in args.runs:
        try:
            runs.append(read_run(p))
        except RunError as exc:
            raise InputError(str(exc)) from None
    vehicle, terrain = _base("vehicle", args.vehicle, runs), _base("terrain", args.terrain, runs)
    from dynamics.discrepancy import CANDIDATES
    only = _names(args.only, PARAMS, "--only", "parameters")
    effects = _names(args.effects, CANDIDATES, "--effects", "effects")
    from dynamics.discrepancy import check_run_length
    for r in runs:
        try:
            check_run_length(r)
        except RunError as exc:
            raise InputError(str(exc)) from None
    cal = calibrate(runs, vehicle, terrain, only=only)
    names = ", ".join(Path(r.source).name for r in runs)
    doc = cal.to_json()
    if not args.no_diagnose:
        doc["diagnosis"] = _diagnoses(cal, runs, effects)
    v, t = _with_sources(cal, names)
    v, t, doc["with_effect"] = _with_effect(v, t, doc.get("diagnosis", []), names)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    from dynamics.params import vehicle_to_yaml
    vpath, tpath = out / f"{v.name}.yaml", out / f"{t.name}.yaml"
    if vpath == tpath:                      # a vehicle and a terrain of the same name
        vpath, tpath = out / f"{v.name}_vehicle.yaml", out / f"{t.name}_terrain.yaml"
    outs.folder(out, "--out", (vpath.name, tpath.name, "calibration.json"))
    write_text(vpath, vehicle_to_yaml(v, f"calibrated by sbmpc calibrate on {names}"))
    write_text(tpath, vehicle_to_yaml(t, f"calibrated by sbmpc calibrate on {names}"))
    doc["files"] = {"vehicle": str(vpath), "terrain": str(tpath)}
    write_json(out / "calibration.json", doc)
    print(describe(cal, doc))
    print(f"wrote {vpath}, {tpath}, {out / 'calibration.json'}")
    return 0


def _with_sources(cal, names: str):
    """The calibrated vehicle and terrain renamed (``*_calibrated``), each fitted value's
    source saying where and how well it was fitted."""
    from ..calibration import PARAMS
    vs, ts = dict(cal.vehicle.sources), dict(cal.terrain.sources)
    for n, p in cal.params.items():
        if not p["fitted"]:
            continue
        src = f"fitted by sbmpc calibrate on {names} (+- {p['se']:.3g}; prior {p['prior']:.4g})"
        (vs if PARAMS[n][0] == "vehicle" else ts)[n] = src
        if n == "mass":
            vs["inertia"] = f"scaled with the fitted mass (prior {cal.vehicle.inertia * p['prior'] / p['value']:.4g})"
    base_v, base_t = cal.vehicle.name, cal.terrain.name
    v = cal.vehicle.replace(name=f"{base_v}_calibrated", sources=vs,
                            description=f"{cal.vehicle.description or base_v}, calibrated on {names}")
    t = cal.terrain.replace(name=f"{base_t}_calibrated", sources=ts)
    return v, t


# effects a vehicle or terrain file holds (a grade belongs to the ground under one run)
FILE_EFFECTS = ("command_delay", "actuator_lag", "wheel_radius", "viscous_friction", "no_load_current", "voltage_sag",
                "shear_relaxation", "turning_friction")


def _with_effect(v, t, diagnosis: list, names: str) -> tuple:
    """(vehicle, terrain, the effect written or None): where one run's diagnosis names an
    effect a file can hold, the files hold the joint fit: the base parameters fitted with
    it, and the effect."""
    if len(diagnosis) != 1 or diagnosis[0]["cause"] not in FILE_EFFECTS:
        return v, t, None
    from dataclasses import fields

    from dynamics.synth import apply
    from ..calibration import with_params
    c = diagnosis[0]["candidates"][0]
    src = f"fitted by sbmpc calibrate on {names}, jointly with {c['effect']}"
    vb, tb = with_params(list(c["base"]), list(c["base"].values()), v, t)
    v2, t2, _ = apply(vb, c["effect"], c["params"], tb)
    # every value the joint fit set (the inertia with the mass)
    changed_v = {f.name: src for f in fields(v) if f.name != "sources" and getattr(v2, f.name) != getattr(v, f.name)}
    changed_t = {f.name: src for f in fields(t) if f.name != "sources" and getattr(t2, f.name) != getattr(t, f.name)}
    return (v2.replace(sources=dict(v.sources, **changed_v)), t2.replace(sources=dict(t.sources, **changed_t)),
            {"effect": c["effect"], "params": c["params"], "base": c["base"],
             "note": "the files hold these base values, fitted jointly with the effect, not params' values"})


def _diagnoses(cal, runs, effects) -> list:
    """Calibrate, then diagnose: each add-on effect fitted jointly with the calibrated
    parameters (:func:`sbmpc.calibration.effects_on_top`); per run its cause and the
    three best candidates."""
    from ..calibration import effects_on_top
    out = []
    for d in effects_on_top(cal, runs, effects):
        out.append(dict(d, candidates=d["candidates"][:3]))
    return out


def describe(cal, doc) -> str:
    lines = [f"calibrated {cal.vehicle.name.replace('_calibrated', '')} on {cal.terrain.name.replace('_calibrated', '')}"
             f" ({cal.rounds} fit{'s' if cal.rounds > 1 else ''}):"]
    for n, p in cal.params.items():
        if p["fitted"]:
            lines.append(f"  {n:16s} {p['prior']:10.4g} -> {p['value']:10.4g} +- {p['se']:.2g}")
        else:
            lines.append(f"  {n:16s} {p['prior']:10.4g}    kept: {p['kept']}")
    for src, h in cal.heldout.items():
        lines.append(f"  held out, {Path(src).name}: {h['nominal']:.2f} -> {h['calibrated']:.2f} noise units "
                     f"({', '.join(h['channels'])})")
    for d in doc.get("diagnosis", []):
        c = d["candidates"][0] if d["candidates"] else None
        named = c is not None and d["cause"] == c["effect"]
        share = ("" if not named else f"pose error {100 * d['share']:.0f} % lower" if d["decided_on"] == "pose"
                 else f"{100 * d['share']:.0f} % of the excess" + (", on the training part"
                                                                    if d["decided_on"] == "training" else ""))
        extra = (f" ({', '.join(f'{k} {v:.4g}' for k, v in c['params'].items())}; held out {d['base_error']:.2f} -> "
                 f"{c['error']:.2f}, {share})" if named else f" (held out {d['base_error']:.2f})")
        lines.append(f"  calibrate, then diagnose, {Path(d['run']).name}: {d['cause']}{extra}")
    return "\n".join(lines)
