"""Sweeps: many scenarios, costs, seeds, planner settings and vehicle variants in one go,
on Ray (``pip install 'sbmpc[sweep]'``), with the robustness of every plan.

A sweep spec (YAML)::

    scenarios: [scenarios/hill_tradeoff.yaml, scenarios/]    # files or folders of them
    families:                                                # generated maps, one per seed
      - {scenario: scenarios/hills_field.yaml, seeds: [1, 2, 3]}
    costs: [time, energy]                                    # default: the scenario's cost
    seeds: [0, 1]                                            # planner.seed (Halton); default [scenario's]
    planner: {branching: [10, 16]}                           # settings to vary: every combination
    variants:                                                # the vehicle/terrain the plan is made for
      - {name: nominal}
      - {name: heavy, vehicle: {mass: "+10%"}}
      - {name: slippery, terrain: {mu_sa: "-20%", mu_op: "-20%"}}
      - {name: husky, vehicle: husky}                        # a shipped name or a file
    robustness:                                              # replay each plan on drawn vehicles
      samples: 20
      seed: 0
      vary: {mass: 0.10, mu_sa: 0.20, radius_scale_right: 0.02}   # relative standard deviations

Every combination is one task (:func:`tasks`). A task plans with one thread (the sweep
runs tasks side by side instead), checks the plan at the controller rate as every plan
is checked, and with ``robustness`` replays it on ``samples`` vehicles drawn from normal
distributions around the variant (``vary``: relative standard deviations of vehicle or
terrain parameters): the share that stall or miss the goal, and the spread of the
energy. A task that fails or raises is a row with its reason; it never stops the sweep.

Rows (:data:`COLUMNS`) go to ``DIR/results.parquet``: each finished batch of tasks is
written as a part file at once (``DIR/parts/``) and the parts are merged at the end, so
an interrupted sweep keeps what it finished and ``--resume`` skips those tasks (by task
id, a hash of the task's inputs).
"""
from __future__ import annotations

import copy
import itertools
import json
import time
import traceback
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..planning.margin import drawn_worlds as _drawn_worlds     # the robustness draw
from . import closed_loop as CL

COLUMNS = ("task_id", "scenario", "family_seed", "cost", "seed", "settings", "variant", "status", "reason",
           "failure", "travel_time_s", "energy_J", "length_m", "planning_time_s", "expansions", "reached_at_rate",
           "robust_samples", "p_stall", "p_miss", "energy_mean_J", "energy_std_J", "task_time_s") + CL.RUN_COLUMNS
KNOWN = {"scenarios", "families", "costs", "seeds", "planner", "variants", "robustness"}


# ---- the spec --------------------------------------------------------------------
def load_spec(path: Path) -> dict:
    """A sweep spec, validated (every problem at once), paths resolved against its folder."""
    from dynamics.params import read_yaml_text
    from dynamics.params import did_you_mean
    from ..scenario import shown
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: expected a sweep spec YAML file, found no such file")
    try:
        spec = read_yaml_text(path)
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: {exc}") from None
    if not isinstance(spec, dict):
        raise InputError(f"{path}: expected a mapping (scenarios, costs, seeds, planner, variants, robustness), "
                         f"found {type(spec).__name__}")
    probs = []
    for k in spec:
        if k not in KNOWN:
            probs.append(f"{k}: expected one of the keys {', '.join(sorted(KNOWN))}, found an unknown key"
                         f"{did_you_mean(k, KNOWN)}")
    base = path.parent
    files = []
    listed = spec.get("scenarios") or []
    if isinstance(listed, str):                       # one file or folder, not in a list
        listed = [listed]
    if not isinstance(listed, list):
        probs.append(f"scenarios: expected a list of scenario files or folders, found {shown(listed)}")
        listed = []
    for s in listed:
        p = base / str(s)
        if not isinstance(s, str) or not s:
            probs.append(f"scenarios: expected scenario files or folders (paths), found {shown(s)}")
        elif p.is_dir():                              # the scenario files in it (not the spec, vehicles ...)
            files += [f for f in sorted(p.glob("*.yaml")) if _looks_like_scenario(f) and f.resolve() != path.resolve()]
        elif p.is_file():
            files.append(p)
        else:
            probs.append(f"scenarios: expected scenario files or folders, found no {shown(str(s))}")
    files = list({f.resolve(): f for f in files}.values())      # a file listed twice (or in a folder too) runs once
    families = []
    fams = spec.get("families") or []
    if not isinstance(fams, list):
        probs.append(f"families: expected a list of {{scenario: FILE, seeds: [integers]}}, found {shown(fams)}")
        fams = []
    for i, f in enumerate(fams):
        if not (isinstance(f, dict) and set(f) == {"scenario", "seeds"} and isinstance(f.get("scenario"), str)
                and isinstance(f.get("seeds"), list) and f["seeds"]
                and all(isinstance(x, int) and not isinstance(x, bool) and 0 <= x < 2 ** 63 for x in f["seeds"])):
            probs.append(f"families[{i}]: expected {{scenario: FILE, seeds: [integers in [0, 2^63), at least one]}}, "
                         f"found {shown(f)}")
            continue
        if not (base / f["scenario"]).is_file():
            probs.append(f"families[{i}].scenario: expected a scenario file, found no {shown(f['scenario'])}")
            continue
        families.append((base / f["scenario"], list(dict.fromkeys(f["seeds"]))))
    costs = spec.get("costs")
    if costs is not None and not (isinstance(costs, list) and costs and all(isinstance(c, str) for c in costs)
                                  and set(costs) <= {"time", "energy"}):
        probs.append(f"costs: expected a list of time and/or energy, found {shown(costs)}")
    seeds = spec.get("seeds")
    if seeds is not None and not (isinstance(seeds, list) and seeds and all(
            isinstance(x, int) and not isinstance(x, bool) and 0 <= x < 2 ** 31 for x in seeds)):
        probs.append(f"seeds: expected a list of integers in [0, 2^31), found {shown(seeds)}")
    grid = spec.get("planner", {}) or {}
    if not (isinstance(grid, dict) and all(isinstance(v, list) and v for v in grid.values())):
        probs.append(f"planner: expected {{setting: [values]}}, found {shown(grid)}")
        grid = {}
    probs += _setting_problems(grid)
    variants = spec.get("variants") or [{"name": "nominal"}]
    if not (isinstance(variants, list) and all(isinstance(v, dict) and isinstance(v.get("name"), str)
                                               for v in variants)):
        probs.append(f"variants: expected a list of {{name:, vehicle:, terrain:}}, found {shown(variants)}")
        variants = [{"name": "nominal"}]
    else:
        for i, v in enumerate(variants):
            probs += _variant_problems(f"variants[{i}]", v, base)
            if [w["name"] for w in variants].index(v["name"]) < i:
                probs.append(f"variants[{i}].name: expected a name of its own (rows are told apart by it), "
                             f"found {shown(v['name'])} again")
    rob = spec.get("robustness")
    if CL.closed(rob) and isinstance(rob.get("samples"), int) and not isinstance(rob["samples"], bool) and \
            0 < rob["samples"] <= 10_000:
        probs += CL.problems(rob)
    elif rob is not None and not (isinstance(rob, dict) and isinstance(rob.get("samples"), int)
                                and not isinstance(rob["samples"], bool) and 0 < rob["samples"] <= 10_000
                                and isinstance(rob.get("vary", {}) or {}, dict)):
        probs.append(f"robustness: expected {{samples: N, seed: S, vary: {{parameter: relative std}}}} (open loop) "
                     f"or {{mode: closed_loop, samples: N, ...}}, found {shown(rob)}")
    elif rob is not None:
        probs += _robustness_problems(rob)
    if not files and not families and not probs:
        probs.append("scenarios: expected at least one scenario (scenarios: or families:), found none")
    # a variant's vehicle file is the spec's, like its scenarios: resolved here, once
    variants = [dict(v, vehicle=str((base / v["vehicle"]).resolve()))
                if isinstance(v.get("vehicle"), str) and (base / v["vehicle"]).is_file() else v for v in variants]
    from .. import scenario as SC
    family_files = {p for p, _ in families}
    for f in dict.fromkeys(files + [p for p, _ in families]):     # each scenario file checked once, up front
        try:
            scn = SC.load(f)
        except InputError as exc:
            probs.append(str(exc).replace("\n", " "))
            continue
        if f in family_files and not (isinstance(scn.map_spec, dict) and "generate" in scn.map_spec):
            probs.append(f"families: {f}: expected a scenario with a generated map (map: generate:), one map per "
                         "seed; found a map read from a file")
    if probs:
        raise InputError(f"{path}: " + (probs[0] if len(probs) == 1 else f"{len(probs)} problems:\n  " + "\n  ".join(probs)))
    return {"scenarios": files, "families": families, "costs": costs, "seeds": seeds, "planner": grid,
            "variants": variants, "robustness": rob, "base": base}


def _change_ok(c) -> bool:
    """A variant's change as :func:`_scaled` applies it: a number (or a string of one),
    or a string '+N%' / '-N%' above -100 %."""
    import math
    if isinstance(c, bool) or not isinstance(c, (int, float, str)):
        return False
    text = str(c).strip()
    pct = text.endswith("%")
    try:
        x = float(text[:-1] if pct else text)
    except ValueError:
        return False
    return math.isfinite(x) and (not pct or x > -100.0)


def _variant_problems(where: str, v: dict, base: Path) -> list:
    """What is wrong with one variant, before any task runs (a task would turn it into
    an error row with Python's words)."""
    from dynamics import ParameterError, load_vehicle
    from dynamics.params import did_you_mean
    from ..scenario import shown
    out = []
    for k in v:
        if k not in ("name", "vehicle", "terrain"):
            out.append(f"{where}.{k}: expected one of the keys name, terrain, vehicle, found an unknown key"
                       f"{did_you_mean(k, ('name', 'vehicle', 'terrain'))}")
    from ..truth import numeric_fields
    veh, ter = numeric_fields()
    for key, names in (("vehicle", veh), ("terrain", ter)):
        spec = v.get(key)
        if spec is None:
            continue
        if key == "vehicle" and isinstance(spec, str):
            try:
                load_vehicle(spec, base)
            except ParameterError as exc:
                out.append(f"{where}.vehicle: {exc}")
            continue
        if not isinstance(spec, dict):
            kinds = "a vehicle name or file, or " if key == "vehicle" else ""
            out.append(f"{where}.{key}: expected {kinds}{{parameter: change}}, found {shown(spec)}")
            continue
        for name, c in spec.items():
            if name not in names:
                out.append(f"{where}.{key}.{name}: expected a numeric {key} parameter ({', '.join(names)}), "
                           f"found an unknown one{did_you_mean(name, names)}")
            elif not _change_ok(c):
                out.append(f"{where}.{key}.{name}: expected a change such as '+10%' or '-5%' (above -100%), or "
                           f"a number, found {shown(c)}")
    return out


def _robustness_problems(rob: dict) -> list:
    from dynamics.params import did_you_mean
    from ..scenario import shown
    from .. import truth as TT
    keys = ("mode", "samples", "seed", "vary")
    out = []
    for k in rob:
        if k not in keys:
            out.append(f"robustness.{k}: expected one of the keys {', '.join(keys)}, found an unknown key"
                       f"{did_you_mean(k, keys)} (faults and the keys of runs need mode: closed_loop)")
    if rob.get("mode", "open_loop") not in ("open_loop", "closed_loop"):
        out.append(f"robustness.mode: expected open_loop or closed_loop, found {shown(rob['mode'])}")
    seed = rob.get("seed", 0)
    if not (isinstance(seed, int) and not isinstance(seed, bool) and 0 <= seed < 2 ** 31):
        out.append(f"robustness.seed: expected an integer in [0, 2^31), found {shown(seed)}")
    return out + TT.problems(rob.get("vary") or {}, {}, "robustness.")


def _setting_problems(grid: dict) -> list:
    """Each value of the planner grid checked as a scenario's planner section checks it."""
    from .. import scenario as SC
    out = []
    for k, values in grid.items():
        for val in values:
            probs = SC._Problems("")
            SC._planner({k: val}, probs)
            out += [line for line in probs.items if line not in out]
    return out


def _looks_like_scenario(path: Path) -> bool:
    """Whether a YAML file in a listed folder is a scenario (a mapping with a start or a
    goal): a folder's vehicle, terrain or sweep spec files are left out."""
    from dynamics.params import read_yaml_text
    try:
        doc = read_yaml_text(path)
    except (OSError, ValueError):
        return True                                  # (a broken scenario is reported by the loader)
    return isinstance(doc, dict) and ("start" in doc or "goal" in doc)


def tasks(spec: dict) -> list:
    """Every combination of the spec, one dict per task, with its ``task_id``."""
    sources = [(p, None) for p in spec["scenarios"]] + [(p, s) for p, seeds in spec["families"] for s in seeds]
    labels = _labels([p for p, _ in sources], spec.get("base"))
    keys = sorted(spec["planner"])
    grid = [dict(zip(keys, vals)) for vals in itertools.product(*(spec["planner"][k] for k in keys))] or [{}]
    out = []
    for (path, fam), settings, variant in itertools.product(sources, grid, spec["variants"]):
        for cost in spec["costs"] or [None]:
            for seed in spec["seeds"] or [None]:
                base = {"scenario": str(Path(path).resolve()), "family_seed": fam, "cost": cost, "seed": seed,
                        "settings": settings, "variant": variant, "robustness": spec["robustness"]}
                # a closed-loop sweep: one task per run (sample and mode)
                for t in (CL.expand(base, spec["robustness"]) if CL.closed(spec["robustness"]) else [base]):
                    # the id hashes the scenario's resolved path: the same task however the spec was named
                    t["task_id"] = CL.digest(t)
                    t.update(scenario=str(path), label=labels[Path(path)])
                    out.append(t)
    return out


def _labels(paths: list, base) -> dict:
    """The ``scenario`` column of each file: its stem, or where two files share a stem,
    its path relative to the spec's folder (without .yaml), so rows are told apart."""
    stems = [Path(p).stem for p in dict.fromkeys(map(Path, paths))]
    out = {}
    for p in map(Path, paths):
        if stems.count(p.stem) == 1:
            out[p] = p.stem
        else:
            try:
                out[p] = str(p.with_suffix("").relative_to(base)) if base is not None else str(p.with_suffix(""))
            except ValueError:
                out[p] = str(p.with_suffix(""))
    return out


# ---- one task -------------------------------------------------------------------------
def _scaled(value: float, change) -> float:
    """A value changed by '+10%', '-20%' or set to a number."""
    if isinstance(change, str) and change.strip().endswith("%"):
        return value * (1.0 + float(change.strip()[:-1]) / 100.0)
    return float(change)


def _variant_world(world, variant: dict):
    """The world with the variant's vehicle (a name, a file, or changes) and terrain changes
    (an InputError naming the variant where a changed value leaves its parameter's range)."""
    from dynamics import ParameterError, load_vehicle
    try:
        v = world.vehicle
        spec = variant.get("vehicle")
        if isinstance(spec, str):
            v = load_vehicle(spec, world.scenario.base)
        elif isinstance(spec, dict):
            v = v.replace(**{k: _scaled(getattr(v, k), c) for k, c in spec.items()})
        terrains = world.terrains
        tspec = variant.get("terrain")
        if isinstance(tspec, dict):
            terrains = tuple(t.replace(**{k: _scaled(getattr(t, k), c) for k, c in tspec.items()}) for t in terrains)
    except ParameterError as exc:
        raise InputError(f"variant {variant['name']!r}: {str(exc).replace('<replace>: ', '')}") from None
    return replace(world, vehicle=v, terrains=terrains)


def run_task(task: dict) -> dict:
    """Plan one task (module doc); a row of COLUMNS. Never raises."""
    from ..planning import check as CK
    from ..planning import plan as PL
    from .. import scenario as SC
    from ..planning import world as WO
    from ..problems import skidsteer as SS
    t0 = time.perf_counter()
    row = {k: None for k in COLUMNS}
    row.update(task_id=task["task_id"], scenario=task.get("label") or Path(task["scenario"]).stem,
               family_seed=task["family_seed"], cost=task["cost"],
               seed=task["seed"], settings=json.dumps(task["settings"], sort_keys=True),
               variant=task["variant"]["name"], status="error")
    if task.get("sample") is not None:
        row.update(sample=task["sample"], run_mode=task["run_mode"], end="error")
    try:
        scn = SC.load(task["scenario"])
        if task["family_seed"] is not None:
            ms = copy.deepcopy(scn.map_spec)
            if "generate" not in ms:
                raise InputError(f"{task['scenario']}: a family needs a generated map (map: generate:)")
            ms["generate"]["seed"] = int(task["family_seed"])
            scn = replace(scn, map_spec=ms)
        over = dict(task["settings"], threads=1)
        if task["seed"] is not None:
            over["seed"] = task["seed"]
        from ..api import load_scenario
        scn = load_scenario(scn, **over)
        cost = task["cost"] or scn.cost
        row["cost"] = cost
        world = _variant_world(WO.resolve(scn), task["variant"])
        if task.get("sample") is not None:         # a closed-loop run (sbmpc.sweep.closed_loop)
            row.update(CL.run(world, cost, task))
            row["task_time_s"] = time.perf_counter() - t0
            return row
        plan = PL.plan(world, cost)
        row.update(status=plan.status, reason=plan.reason, failure=plan.failure, travel_time_s=plan.travel_time_s, energy_J=plan.energy_J,
                   length_m=plan.length_m, planning_time_s=plan.planning_time_s, expansions=plan.nodes_expanded,
                   reached_at_rate=bool(plan.check.reached) if plan.check is not None else None)
        rob = task["robustness"]
        if rob and plan.found:
            try:
                drawn = _drawn_worlds(world, rob, task["task_id"])
            except InputError as exc:            # the plan stands; its robustness could not be measured
                row.update(robust_samples=0, reason=f"robustness: {exc}"[:500])
                drawn = []
            checks = [CK.check(w, cost, plan.controls) for w in drawn]
        if rob and plan.found and checks:
            stall = [c.end == -SS.STALL for c in checks]
            miss = [not c.reached for c in checks]
            e = np.array([c.energy_J for c in checks if c.reached], float)
            row.update(robust_samples=len(checks), p_stall=float(np.mean(stall)), p_miss=float(np.mean(miss)),
                       energy_mean_J=float(e.mean()) if e.size else None,
                       energy_std_J=float(e.std()) if e.size > 1 else None)
    except InputError as exc:
        row.update(status="error", reason=str(exc).splitlines()[0][:500])
    except Exception as exc:          # a crash is a row, not the end of the sweep
        tb = traceback.format_exc().strip().splitlines()
        row.update(status="error", reason=f"{type(exc).__name__}: {exc} ({tb[-3].strip() if len(tb) > 2 else ''})"[:500])
    row["task_time_s"] = time.perf_counter() - t0
    return row


def run_batch(batch: list) -> list:
    """Rows of a batch of tasks, one after another in this process (a Ray task)."""
    return [run_task(t) for t in batch]


# ---- the results ----------------------------------------------------------------------
def _table(rows: list):
    import pyarrow as pa
    cols = {k: [r.get(k) for r in rows] for k in COLUMNS}
    return pa.table(cols)


def write_part(out: Path, rows: list, k: int) -> Path:
    """Write finished rows as a part file at once (atomically)."""
    import pyarrow.parquet as pq
    parts = out / "parts"
    parts.mkdir(parents=True, exist_ok=True)
    path = parts / f"part-{int(time.time() * 1e3)}-{k:05d}.parquet"
    tmp = path.with_suffix(".tmp")
    pq.write_table(_table(rows), tmp)
    tmp.replace(path)
    return path


def read_rows(out: Path) -> list:
    """Every task's row written so far, one per task id (the merged results, then the
    parts: a part's row is the newer)."""
    import pyarrow.parquet as pq
    rows = pq.read_table(out / "results.parquet").to_pylist() if (out / "results.parquet").is_file() else []
    for p in sorted((out / "parts").glob("*.parquet")) if (out / "parts").is_dir() else []:
        rows += pq.read_table(p).to_pylist()
    return list({r["task_id"]: r for r in rows}.values())


def merge(out: Path, ids=None) -> list:
    """Merge the results so far and the parts into DIR/results.parquet: one row per task
    id, the last kept, only the ids given (the sweep's tasks) when ``ids`` is not None."""
    import pyarrow.parquet as pq
    rows = [r for r in read_rows(out) if ids is None or r["task_id"] in ids]      # (one per id already)
    tmp = out / ".results.tmp.parquet"
    pq.write_table(_table(rows), tmp)
    tmp.replace(out / "results.parquet")
    return rows


# ---- running ----------------------------------------------------------------------------
def execute(task_list: list, out: Path, workers: int = 0, address: str | None = None, batch_size: int = 0,
            resume: bool = False, progress=None, use_ray: bool = True) -> dict:
    """Run the tasks (skipping finished ones with ``resume``), writing parts as batches
    finish; returns {"rows", "ran", "skipped", "wall_s", "engine", "workers"}."""
    import os
    out.mkdir(parents=True, exist_ok=True)
    done = {r["task_id"] for r in read_rows(out)} if resume else set()
    if not resume:                                 # a new sweep: nothing of an earlier one is kept
        for p in ((out / "parts").glob("*.parquet") if (out / "parts").is_dir() else []):
            p.unlink()
        (out / "results.parquet").unlink(missing_ok=True)
    todo = [dict(t, out=str(out)) for t in task_list if t["task_id"] not in done]   # (runs write files there)
    workers = workers or os.cpu_count() or 1
    # batches: Ray costs about 0.5 ms a task, a plan 0.1-10 s, so one task per batch
    # balances best; only sweeps of thousands of tasks get larger batches
    size = batch_size or max(1, len(todo) // (64 * workers))
    batches = [todo[i:i + size] for i in range(0, len(todo), size)]
    t0 = time.perf_counter()
    finished = 0
    engine = "serial"
    if use_ray and batches:
        ray = _ray()
        if ray is not None:
            engine = "ray"
            if not ray.is_initialized():
                import logging
                quiet = dict(ignore_reinit_error=True, log_to_driver=False, logging_level=logging.ERROR)
                if address:
                    ray.init(address=address, **quiet)
                else:
                    ray.init(num_cpus=workers, include_dashboard=False, **quiet)
            remote = ray.remote(num_cpus=1)(run_batch)
            pending = {remote.remote(b): k for k, b in enumerate(batches)}
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1)
                for ref in ready:
                    k = pending.pop(ref)
                    rows = ray.get(ref)
                    write_part(out, rows, k)
                    finished += len(rows)
                    if progress:
                        progress(finished, len(todo), time.perf_counter() - t0)
    if engine == "serial":
        for k, b in enumerate(batches):
            rows = run_batch(b)
            write_part(out, rows, k)
            finished += len(rows)
            if progress:
                progress(finished, len(todo), time.perf_counter() - t0)
    wall = time.perf_counter() - t0
    rows = merge(out, {t["task_id"] for t in task_list})
    return {"rows": rows, "ran": len(todo), "skipped": len(task_list) - len(todo), "wall_s": wall,
            "engine": engine, "workers": workers if engine == "ray" else 1}


def _ray():
    try:
        import ray
        return ray
    except ImportError:
        return None


def summary_table(rows: list) -> str:
    """Per scenario and cost: tasks, found, median travel time and energy (with range),
    stall/miss probability when measured (a closed-loop sweep's rows: per run,
    :func:`sbmpc.sweep.closed_loop.summary_table`)."""
    if rows and all(r.get("sample") is not None for r in rows):
        return CL.summary_table(rows)
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["scenario"], r["cost"] or "-", r["variant"]), []).append(r)
    lines = [("scenario", "cost", "variant", "tasks", "found", "time [s] median (range)", "energy [J] median (range)",
              "p stall", "p miss")]
    for (s, c, v), rs in sorted(groups.items(), key=lambda kv: tuple(str(x) for x in kv[0])):
        f = [r for r in rs if r["status"] == "found"]

        def med(key, f=f):
            x = np.array([r[key] for r in f if r[key] is not None], float)
            return f"{np.median(x):.1f} ({x.min():.1f}-{x.max():.1f})" if x.size else "-"

        def mean(key, f=f):
            x = np.array([r[key] for r in f if r.get(key) is not None], float)
            return f"{x.mean():.2f}" if x.size else "-"
        lines.append((s, c, v, str(len(rs)), str(len(f)), med("travel_time_s"), med("energy_J"), mean("p_stall"),
                      mean("p_miss")))
    w = [max(len(line[i]) for line in lines) for i in range(len(lines[0]))]
    return "\n".join("  ".join(x.ljust(w[i]) for i, x in enumerate(line)) for line in lines)


def plot_summary(rows: list, path: Path) -> None:
    """DIR/summary.png: travel time against energy of every found plan, one colour per
    scenario, filled for time and hollow for energy plans; failures counted in the title
    (a closed-loop sweep's: :func:`sbmpc.sweep.closed_loop.plot_summary`)."""
    if rows and all(r.get("sample") is not None for r in rows):
        return CL.plot_summary(rows, path)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7.5, 5))
    scen = sorted({r["scenario"] for r in rows})
    cmap = plt.get_cmap("tab10")
    for i, s in enumerate(scen):
        for cost, face in (("time", True), ("energy", False)):
            f = [r for r in rows if r["scenario"] == s and r["cost"] == cost and r["status"] == "found"]
            if f:
                ax.scatter([r["travel_time_s"] for r in f], [r["energy_J"] for r in f], s=30,
                           facecolors=cmap(i % 10) if face else "none", edgecolors=cmap(i % 10),
                           label=f"{s} ({cost})")
    failed = sum(r["status"] != "found" for r in rows)
    ax.set_xlabel("travel time [s] (1 kHz replay)")
    ax.set_ylabel("energy [J] (1 kHz replay)")
    ax.set_title(f"{len(rows)} tasks, {len(rows) - failed} plans found, {failed} without a plan")
    ax.grid(alpha=0.3)
    if rows:
        ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
