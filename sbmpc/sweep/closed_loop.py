"""Closed-loop robustness in a sweep (``robustness: {mode: closed_loop, ...}``): each
scenario run by ``sbmpc run`` (whole-route and/or the horizon controller) on vehicles,
maps and executions drawn per sample (:mod:`sbmpc.truth`), one task per run.

A spec's ``robustness`` then reads::

    robustness:
      mode: closed_loop
      samples: 20                       # drawn truths per scenario, cost, seed, settings, variant
      seed: 0
      modes: [whole_route, horizon]     # how sbmpc run drives (default: whole_route)
      horizon_s: 10                     # the horizon of the horizon runs (default: the scenario's, else 10)
      wall_limit_s: 600                 # a run that takes longer on the wall clock fails ("timeout")
      own_plan: true                    # also plan for each truth's own vehicle on its own map
      run: {adapt_periods: 5}           # run settings of every run (the scenario's otherwise)
      vary: {mass: 0.10, mu_sa: 0.10, mu_op: 0.10}
      faults: {delay_s: 0.05, map: {noise_sd_m: 0.05, corr_m: 2.0}}

Sample k of a task draws the same truth for every mode (the seed hashes the spec's seed,
the task without its mode, and k), so whole-route and horizon runs meet the same truths.
Each run is a row (:data:`RUN_COLUMNS` beside the plan columns): how it ended (``end``:
reached, stopped (rather than tip over), no_path (the planner found no way on from
where it stood, and said why), failed, tipped, off_map, timeout, error) and
why, what the first plan predicted and what was executed, what a plan for the truth's
own vehicle on its own map predicts (``own_*``; ``can_cross`` false where no plan exists
for it), the executed cost over that (``cost_ratio``: what not knowing the truth cost)
and over the first plan's prediction (``predicted_ratio``: the prediction's error), stalls, re-plans, guarded and dropped periods, wall time. A run that does not
reach the goal writes its run JSON to ``DIR/runs/TASK_ID.json`` (``sbmpc run --replay``).
"""
from __future__ import annotations

import hashlib
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

RUN_COLUMNS = ("sample", "run_mode", "end", "truth", "executed_time_s", "executed_energy_J", "predicted_time_s",
               "predicted_energy_J", "own_time_s", "own_energy_J", "can_cross", "cost_ratio", "predicted_ratio", "stalls", "replans",
               "guarded", "dropped", "run_wall_s", "run_file", "truth_spec")
KEYS = ("mode", "samples", "seed", "modes", "horizon_s", "wall_limit_s", "own_plan", "run", "vary", "faults")
DRAWN_BY = ("seed", "vary", "faults")    # what a sample's truth depends on (with the task's scenario, cost, ...)
MODES = ("whole_route", "horizon")
ENDS = ("reached", "stopped", "no_path", "failed", "tipped", "off_map", "timeout", "error")
WALL_LIMIT_S = 600.0
HORIZON_S = 10.0


def closed(rob) -> bool:
    """Whether a spec's robustness is closed-loop."""
    return isinstance(rob, dict) and rob.get("mode") == "closed_loop"


def problems(rob: dict) -> list:
    """Every problem of a closed-loop robustness mapping, one line each."""
    from dynamics.params import did_you_mean
    from ..scenario import shown
    from .. import truth as TT
    out = [f"robustness.{k}: expected one of the keys {', '.join(KEYS)}, found an unknown key"
           f"{did_you_mean(k, KEYS)}" for k in rob if k not in KEYS]
    modes = rob.get("modes", ["whole_route"])
    if not (isinstance(modes, list) and modes and all(m in MODES for m in modes)):
        out.append(f"robustness.modes: expected a list of {' and/or '.join(MODES)}, found {shown(modes)}")
    for key, lo, hi in (("horizon_s", 0.5, 600.0), ("wall_limit_s", 1.0, 86400.0)):
        v = rob.get(key)
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not lo <= v <= hi):
            out.append(f"robustness.{key}: expected seconds in [{lo:g}, {hi:g}], found {shown(v)}")
    if not isinstance(rob.get("own_plan", True), bool):
        out.append(f"robustness.own_plan: expected true or false, found {shown(rob['own_plan'])}")
    if rob.get("run") is not None:
        from .. import scenario as SC
        probs = SC._Problems("")
        SC._run(rob["run"], probs)
        out += [f"robustness.{line.lstrip(': ')}" for line in probs.items]
    return out + TT.problems(rob.get("vary") or {}, rob.get("faults") or {}, "robustness.")


def digest(doc: dict) -> str:
    """16 hex digits of a task's inputs (its JSON, keys sorted): a task id, a draw key."""
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:16]


def expand(task: dict, rob: dict) -> list:
    """The run tasks of a task: one per sample and mode. ``draw_key`` (with the sample,
    the seed of its truth) hashes the task without what only the plans and runs read
    (the planner settings, the modes, their settings, the sample count): two specs, or
    two settings of one, that differ only there meet the same truths, sample for
    sample. The scenario enters by its file's content, not its path: the same
    scenario met from another folder (a clone, a worktree) meets the same truths (by
    its path, two tables of 2026-12-07 meant to be on the same truths were not)."""
    drawn = dict(task, scenario=_content(task["scenario"]), settings={},
                 robustness={k: rob.get(k) for k in DRAWN_BY})
    key = digest(drawn)
    return [dict(task, sample=k, run_mode=m, draw_key=key)
            for k in range(int(rob["samples"])) for m in rob.get("modes", ["whole_route"])]


def _content(path) -> str:
    """16 hex digits of a scenario file's bytes (its path where it cannot be read: the
    loader says why, later)."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]
    except OSError:
        return str(path)


def truth_seed(rob: dict, task: dict) -> int:
    """The seed of sample ``task['sample']``'s truth."""
    h = hashlib.sha256(f"{int(rob.get('seed', 0))}:{task['draw_key']}:{task['sample']}".encode()).hexdigest()
    return int(h[:8], 16)


def run(world, cost: str, task: dict) -> dict:
    """One closed-loop run of a task (module doc): the row's run columns."""
    from .. import receding
    from .. import truth as TT
    from ..planning import plan as PL
    rob = task["robustness"]
    truth = TT.draw(world, rob.get("vary"), rob.get("faults"), truth_seed(rob, task))
    mode = task["run_mode"]
    ps = world.scenario.planner
    hz = (rob.get("horizon_s") or ps.horizon_s or HORIZON_S) if mode == "horizon" else 0.0
    rs = world.scenario.run
    if rob.get("run"):
        rs = replace(rs, **rob["run"])
    w = replace(world, scenario=replace(world.scenario, planner=replace(ps, horizon_s=float(hz)), run=rs))
    row = {"sample": task["sample"], "run_mode": mode, "truth": truth.name,
           "truth_spec": json.dumps(truth.spec, sort_keys=True)}
    t0 = time.perf_counter()
    res = receding.run(w, cost, truth, wall_limit_s=float(rob.get("wall_limit_s", WALL_LIMIT_S)))
    row["run_wall_s"] = time.perf_counter() - t0
    d = res.to_json()
    pred, ex = d["predicted"], d["executed"]
    if mode == "horizon":          # the horizon's plans predict no whole route: the whole-route plan's
        first = PL.plan(world, cost)
        pred = {"travel_time_s": first.travel_time_s, "energy_J": first.energy_J} if first.found else pred
    row.update(end=res.end, status=res.end, reason=(res.reason or "")[:500] or None,
               executed_time_s=ex["travel_time_s"], executed_energy_J=ex["energy_J"],
               predicted_time_s=pred["travel_time_s"], predicted_energy_J=pred["energy_J"],
               stalls=res.stalls, replans=res.replans, guarded=res.guarded, dropped=res.dropped)
    if rob.get("own_plan", True):
        # the truth's own vehicle on its own map: whether it can cross, and what it would cost
        own = PL.plan(truth.world, cost)
        row.update(can_cross=bool(own.found), own_time_s=own.travel_time_s if own.found else None,
                   own_energy_J=own.energy_J if own.found else None)
    key = "time_s" if cost == "time" else "energy_J"
    done = row[f"executed_{key}"] if res.end == "reached" else None
    ref = row.get(f"own_{key}") or row[f"predicted_{key}"]
    row["cost_ratio"] = done / ref if done is not None and ref else None
    pred = row[f"predicted_{key}"]
    row["predicted_ratio"] = done / pred if done is not None and pred else None
    out = task.get("out")
    if res.end != "reached" and out:
        path = Path(out) / "runs" / f"{task['task_id']}.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(d, indent=1))
        tmp.replace(path)
        row["run_file"] = str(path)
    return row


# ---- the report ------------------------------------------------------------------------
def _groups(rows: list) -> dict:
    """Rows by (scenario, cost, mode, variant); a family's maps pooled as 'NAME maps'."""
    g: dict = {}
    for r in rows:
        name = r["scenario"] if r.get("family_seed") is None else f"{r['scenario']} maps"
        g.setdefault((name, r["cost"] or "-", r["run_mode"] or "-", r["variant"]), []).append(r)
    return dict(sorted(g.items(), key=lambda kv: tuple(str(x) for x in kv[0])))


def summary_table(rows: list) -> str:
    """Per scenario, cost, mode and variant: runs, how they ended, p_reach (of all, and of
    those whose truth can cross), the executed cost over the own vehicle's plan (median,
    90th percentile), stalls."""
    lines = [("scenario", "cost", "mode", "variant", "runs", "reached", "stopped/no path", "failed", "tipped/off",
              "timeout/err",
              "p_reach", "p_reach crossable", "over own plan median (p90)", "over prediction median (p90)",
              "stalls")]
    for (s, c, m, v), rs in _groups(rows).items():
        n = len(rs)
        count = {e: sum(r["end"] == e for r in rs) for e in ENDS}
        cross = [r for r in rs if r.get("can_cross") is not False]
        def mp(key, rs=rs):
            x = np.array([r[key] for r in rs if r.get(key) is not None], float)
            return f"{np.median(x):.3f} ({np.percentile(x, 90):.3f})" if x.size else "-"
        lines.append((s, c, m, v, str(n), str(count["reached"]), f"{count['stopped']}/{count['no_path']}",
                      str(count["failed"]),
                      f"{count['tipped']}/{count['off_map']}", f"{count['timeout']}/{count['error']}",
                      f"{count['reached'] / n:.2f}",
                      f"{sum(r['end'] == 'reached' for r in cross) / len(cross):.2f} of {len(cross)}" if cross else "-",
                      mp("cost_ratio"), mp("predicted_ratio"),
                      str(sum(int(r["stalls"] or 0) for r in rs))))
    w = [max(len(line[i]) for line in lines) for i in range(len(lines[0]))]
    return "\n".join("  ".join(x.ljust(w[i]) for i, x in enumerate(line)) for line in lines)


def plot_summary(rows: list, path: Path) -> None:
    """DIR/summary.png of a closed-loop sweep: p_reach per scenario, cost and mode (bars,
    the crossable runs' as a dot), and every reached run's executed cost over its own
    vehicle's plan (points, the median a bar)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    groups = _groups(rows)
    labels = [f"{s}\n{c}, {m.replace('_', '-')}" + (f", {v}" if v != "nominal" else "") for s, c, m, v in groups]
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(max(6.0, 0.9 * len(groups) + 2), 7), sharex=True)
    x = np.arange(len(groups))
    p = [sum(r["end"] == "reached" for r in rs) / len(rs) for rs in groups.values()]
    a1.bar(x, p, color="tab:blue", alpha=0.7, label="p_reach (all runs)")
    pc = [(lambda cr: sum(r["end"] == "reached" for r in cr) / len(cr) if cr else np.nan)(
        [r for r in rs if r.get("can_cross") is not False]) for rs in groups.values()]
    a1.plot(x, pc, "o", color="k", label="p_reach (truth can cross)")
    a1.axhline(0.95, color="tab:red", ls="--", lw=1, label="0.95")
    a1.set_ylim(0, 1.05)
    a1.set_ylabel("p_reach")
    a1.legend(fontsize=7, loc="lower left")
    for i, rs in enumerate(groups.values()):
        r = np.array([q["cost_ratio"] for q in rs if q.get("cost_ratio") is not None], float)
        if r.size:
            a2.plot(np.full(r.size, i) + np.linspace(-0.15, 0.15, r.size), r, ".", color="tab:gray")
            a2.plot([i - 0.3, i + 0.3], [np.median(r)] * 2, color="tab:blue", lw=2)
    a2.axhline(1.1, color="tab:red", ls="--", lw=1)
    a2.axhline(1.0, color="k", lw=0.5)
    a2.set_ylabel("executed / own vehicle's plan")
    a2.set_xticks(x, labels, fontsize=7, rotation=30, ha="right")
    ends = {e: sum(r["end"] == e for r in rows) for e in ENDS}
    a1.set_title(f"{len(rows)} closed-loop runs: " + ", ".join(f"{n} {e}" for e, n in ends.items() if n))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
