"""Generated blocks of the docs, written from bench/results/*.json (issue 63: numbers
that stay true).

    python bench/report.py           # rewrite every block in the pages
    python bench/report.py --check   # exit 1 where a page's block differs from its file

A page marks a block with ``<!-- report:NAME -->`` and ``<!-- /report:NAME -->``; the
lines between are this script's, from the results file NAME reads (with its date and
settings). tests/test_report.py fails when a page and its files disagree.
"""
from __future__ import annotations

import argparse
import functools
import json
import math
import re
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
PAGES = [ROOT / "README.md", ROOT / "docs" / "status.md", ROOT / "docs" / "validation.md", ROOT / "docs" / "planner.md",
         ROOT / "docs" / "robustness.md", ROOT / "docs" / "performance.md", ROOT / "scenarios" / "README.md"]
MARK = re.compile(r"(<!-- report:(?P<name>[a-z0-9-]+) -->\n)(?P<body>.*?)(<!-- /report:(?P=name) -->)", re.S)


@functools.lru_cache(maxsize=None)
def _load(name: str) -> dict:
    """A results file, read once per run of the script (several blocks read the same)."""
    return json.loads((RESULTS / name).read_text())


def _planning_times() -> tuple:
    """value.json's plans at the defaults (the value on): ({scenario: time plan's planning
    time [s]}, {scenario: energy plan's}, the scenario whose time plan is slowest)."""
    plans = [p for p in _load("value.json")["plans"] if p["value"]]
    tp = {p["scenario"]: p["planning_s"] for p in plans if p["cost"] == "time"}
    en = {p["scenario"]: p["planning_s"] for p in plans if p["cost"] == "energy"}
    return tp, en, max(tp, key=tp.get)


def _pct(x, fmt: str = ".0f") -> str:
    return "-" if x is None else f"{100 * x:{fmt}} %"


def _met(ok: bool) -> str:
    return "met" if ok else "not met"


def _change(xs) -> str:
    """Signed percentages: '+0.2 %', or '-3.4 to +4.1 %'."""
    lo, hi = f"{min(xs):+.1f}", f"{max(xs):+.1f}"
    return f"{lo} %" if lo == hi else f"{lo} to {hi} %"


def _ratio(s) -> str:
    return "-" if not s else f"{s['median']:.2f} ({s['p90']:.2f})"


def closed_loop_table() -> str:
    """Per scenario, cost and mode: runs, ends, p_reach, the cost ratios (closed_loop.json)."""
    d = _load("closed_loop.json")
    lines = [f"*`python bench/bench_closed_loop.py --samples {d['samples']} --workers {d['workers']}` "
             f"({_when(d)}; {d.get('label') or 'no label'}): {d['samples']} truths per row, vehicle "
             f"{', '.join(sorted(d['vary']))} at {100 * max(d['vary'].values()):.0f} % relative sd, map heights off by "
             f"{100 * d['faults']['map']['noise_sd_m']:.0f} cm at {d['faults']['map']['corr_m']:g} m correlation, "
             f"{1000 * d['faults']['delay_s']:.0f} ms delay"
             + (f"; hills_field maps: its generator at map seeds {', '.join(map(str, d['families']))}"
                if d["families"] else "") + ".*", "",
             "| scenario | cost | mode | runs | reached | how the others ended | p_reach (crossable) | executed / own plan, median (p90) | executed / prediction, median (p90) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for key, g in d["groups"].items():
        s, c, m = key.split("/")
        others = ", ".join(f"{n} {e.replace('_', ' ')}" for e, n in g["ends"].items() if e != "reached" and n)
        pc = "-" if g["p_reach_crossable"] is None else f"{g['p_reach_crossable']:.2f} of {g['crossable']}"
        lines.append(f"| {s} | {c} | {m.replace('_', '-')} | {g['runs']} | {g['ends'].get('reached', 0)} | "
                     f"{others or '-'} | {g['p_reach']:.2f} ({pc}) | {_ratio(g['over_own_plan'])} | "
                     f"{_ratio(g['over_prediction'])} |")
    return "\n".join(lines)


def closed_loop_totals(name: str = "closed_loop.json") -> str:
    """The totals against issue 62's targets (closed_loop.json, or another file of
    bench_closed_loop's)."""
    d = _load(name)
    t = d["totals"]
    e = t["ends"]
    bad = {k: e.get(k, 0) for k in ("tipped", "off_map", "timeout", "error")}
    return (f"{t['runs']} runs ({_when(d)}; {d.get('label') or 'no label'}): {e.get('reached', 0)} reached, {e.get('stopped', 0)} stopped rather "
            f"than tip over, {e.get('no_path', 0)} found no way on and said why, {e.get('failed', 0)} failed "
            f"(stalls, the time or re-plan limit); tipped over {bad['tipped']}, off the map {bad['off_map']}, "
            f"timeouts {bad['timeout']}, tracebacks {bad['error']}. p_reach {t['p_reach_crossable']:.2f} over the "
            f"{t['crossable']} runs whose truth the planner finds a way for (target 0.95: met on "
            f"{t['groups_meeting_p_reach_0.95']} of the {t.get('groups_crossable', t['groups'])} rows with such runs); executed cost over the own vehicle's "
            f"plan median {t['over_own_plan']['median']:.2f}, p90 {t['over_own_plan']['p90']:.2f} (p90 within "
            f"10 %: {t['groups_meeting_cost_p90_1.10']} of {t.get('groups_crossable', t['groups'])} rows).")


HILLS_SERIES = ("closed_loop_edge.json", "closed_loop_stall.json", "closed_loop_nomark.json", "closed_loop_turns.json")


def closed_loop_hills() -> str:
    """robustness.md: hills_field's horizon rows, measured again after each change to what
    a stall means (HILLS_SERIES, each file's label says what it ran)."""
    lines = ["| results | date, commit | what ran | reached | stopped | no way on | failed | stalls |",
             "|---|---|---|---|---|---|---|---|"]
    for name in HILLS_SERIES:
        d = _load(name)
        e = d["totals"]["ends"]
        stalls = sum(g["stalls"] for g in d["groups"].values())
        lines.append(f"| {name} | {d['date']}, {d['commit']} | {d.get('label') or '-'} | {e.get('reached', 0)} of "
                     f"{d['totals']['runs']} | {e.get('stopped', 0)} | {e.get('no_path', 0)} | {e.get('failed', 0)} | "
                     f"{stalls} |")
    return "\n".join(lines)


GUARD_SERIES = (        # (results file, scenario, mode, what the code had)
    ("closed_loop.json", "hills_field", "horizon", "the table (531da84)"),
    ("closed_loop_guarded.json", "hills_field", "horizon",
     "the lesser evil on descents; backing off after a held whole-route plan"),
    ("closed_loop_part_moving.json", "hills_field", "horizon", "and a held period driven in part, moving too (not kept)"),
    ("closed_loop_shortened.json", "hills_field", "horizon", "and a held period driven in part from rest"),
    ("closed_loop_maps_before.json", "hills_field maps", "horizon", "today's code before the three (42edd47)"),
    ("closed_loop_maps_lesser.json", "hills_field maps", "horizon", "the lesser evil on descents"),
    ("closed_loop_maps_guarded.json", "hills_field maps", "horizon", "and backing off after a held whole-route plan"),
    ("closed_loop_maps_part_moving.json", "hills_field maps", "horizon",
     "and a held period driven in part, moving too (not kept)"),
    ("closed_loop_maps_shortened.json", "hills_field maps", "horizon", "and a held period driven in part from rest"),
    ("closed_loop_wall.json", "narrow_pass", "horizon", "before the three (4646b54)"),
    ("closed_loop_guard_others.json", "narrow_pass", "horizon", "the three as landed: a check for harm"),
    ("closed_loop_wall.json", "steep_hill", "horizon", "before the three (4646b54)"),
    ("closed_loop_guard_others.json", "steep_hill", "horizon", "the three as landed: a check for harm"),
    ("closed_loop_guard_whole_before.json", "hills_field", "whole_route", "before the three (42edd47)"),
    ("closed_loop_guard_whole.json", "hills_field", "whole_route", "the three as landed: a check for harm"))


def closed_loop_guard() -> str:
    """robustness.md: the rows of hills_field, of its generator's maps (seeds 100-102) and
    of narrow_pass and steep_hill after each change to what the guard does with a held
    period (GUARD_SERIES; the same truths in every file of a scenario: the draw hashes the
    scenario's content)."""
    lines = ["| results | date, commit | rows | what the code had | runs | reached | stopped | no way on | failed | "
             "tipped over | stalls |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, rows, mode, what in GUARD_SERIES:
        d = _load(name)
        gs = [g for k, g in d["groups"].items() if k.split("/")[0] == rows and k.endswith("/" + mode)]
        n = sum(g["runs"] for g in gs)

        def ends(e, gs=gs):
            return sum(g["ends"].get(e, 0) for g in gs)
        lines.append(f"| {name} | {d['date']}, {d['commit']} | {rows}, {mode.replace('_', '-')} | {what} | {n} | "
                     f"{ends('reached')} | {ends('stopped')} | {ends('no_path')} | {ends('failed')} | {ends('tipped')} | "
                     f"{sum(g['stalls'] for g in gs)} |")
    return "\n".join(lines)


def closed_loop_adapt() -> str:
    """Adaptation off, on with the file's margin, and on with the margin firmed by the
    estimate, on the same truths (closed_loop_adapt_off/on/firm.json)."""
    rows = [("0", _load("closed_loop_adapt_off.json")), ("5, the file's margin", _load("closed_loop_adapt_on.json")),
            ("5, the margin firmed (`run.firm_margin`)", _load("closed_loop_adapt_firm.json"))]
    on = rows[1][1]
    lines = [f"*`python bench/bench_closed_loop.py --modes whole_route --adapt N [--firm-margin]` on "
             f"{', '.join(on['scenarios'])}, both costs, {on['samples']} truths each ({_when(*(d for _, d in rows))}; "
             "the same truths in all: the draw does not depend on the run settings; the file's margin measured "
             "at the code before run.firm_margin, the same path as the key off).*", "",
             "| run.adapt_periods | runs | reached (crossable) | stopped / no path / failed | re-plans, median | "
             "executed / own plan, median (p90) | executed / prediction, median (p90) |", "|---|---|---|---|---|---|---|"]
    for name, d in rows:
        t = d["totals"]
        e = t["ends"]
        lines.append(f"| {name} | {t['runs']} | {e.get('reached', 0)} "
                     f"({t['p_reach_crossable']:.2f}) | {e.get('stopped', 0)} / {e.get('no_path', 0)} / "
                     f"{e.get('failed', 0)} | {t.get('replans_median', '-')} | {_ratio(t['over_own_plan'])} | "
                     f"{_ratio(t.get('over_prediction'))} |")
    return "\n".join(lines)


GRADE = (("0 (the default)", "closed_loop_grade0.json"), ("1.4", "closed_loop_grade.json"))


def _ends(g: dict, tipped_column: bool = False) -> str:
    """A closed-loop group's ends other than reached: 'stopped / no way on / failed'
    (timeouts counted as failed), then the roll-overs: as a fourth column, or only where
    there are any, in bold."""
    e = g["ends"]
    tipped = (f" / {e.get('tipped', 0)}" if tipped_column else
              f" / **{e['tipped']} tipped**" if e.get("tipped") else "")
    return f"{e.get('stopped', 0)} / {e.get('no_path', 0)} / {e.get('failed', 0) + e.get('timeout', 0)}{tipped}"


def _ab(a: dict, b: dict, caption: str) -> str:
    """Two closed-loop results on the same truths, row by row (b's groups): each cell 'a → b'."""
    lines = [caption, "", "| scenario, cost, mode | reached of 10 | stopped / no way on / failed | stalls | "
             "executed / own plan, median (p90) |", "|---|---|---|---|---|"]

    for key, gb in b["groups"].items():
        ga = a["groups"][key]
        lines.append(f"| {key.replace('/', ', ')} | {ga['ends'].get('reached', 0)} → {gb['ends'].get('reached', 0)} | "
                     f"{_ends(ga)} → {_ends(gb)} | {ga['stalls']} → {gb['stalls']} | "
                     f"{_ratio(ga['over_own_plan'])} → {_ratio(gb['over_own_plan'])} |")
    keys = list(b["groups"])
    ta = {"ends": {e: sum(a["groups"][k]["ends"].get(e, 0) for k in keys) for e in
                   ("reached", "stopped", "no_path", "failed", "timeout", "tipped")}}
    tb = {"ends": {e: sum(b["groups"][k]["ends"].get(e, 0) for k in keys) for e in ta["ends"]}}
    lines.append(f"| **all {sum(b['groups'][k]['runs'] for k in keys)}** | {ta['ends']['reached']} → "
                 f"{tb['ends']['reached']} | {_ends(ta)} → {_ends(tb)} | "
                 f"{sum(a['groups'][k]['stalls'] for k in keys)} → {sum(b['groups'][k]['stalls'] for k in keys)} | "
                 f"{_ratio(a['totals']['over_own_plan']) if len(keys) == len(a['groups']) else '-'} → "
                 f"{_ratio(b['totals']['over_own_plan'])} |")
    return "\n".join(lines)


def closed_loop_grade() -> str:
    """robustness.md: the twin's grade allowance off and at the map error's slope (1.4 deg
    for 5 cm at 2 m), on the same truths, per scenario, cost and mode (GRADE's files)."""
    (na, a), (nb, b) = [(n, _load(f)) for n, f in GRADE]
    return _ab(a, b, f"*`python bench/bench_closed_loop.py --samples {b['samples']} --scenarios "
                     f"{' '.join(b['scenarios'])} --families --workers {b['workers']} --planner margin_grade_deg=G` "
                     f"({_when(a, b)}; the same truths in both: the draw does not depend on the planner settings). "
                     f"Each cell: margin_grade_deg {na.split()[0]} → {nb}; failed counts the runs out of their "
                     "wall-clock limit.*")


def closed_loop_backoff() -> str:
    """robustness.md: the horizon rows of runup_ramp and hills_field before and after the
    controller's back-off without a stall (closed_loop_grade0.json's rows, closed_loop_backoff.json)."""
    a, b = _load("closed_loop_grade0.json"), _load("closed_loop_backoff.json")
    return _ab(a, b, f"*`python bench/bench_closed_loop.py --samples {b['samples']} --scenarios "
                     f"{' '.join(b['scenarios'])} --families --modes horizon --workers {b['workers']}` "
                     f"({_when(a, b)}; the same truths as the rows before, from closed_loop_grade0.json). "
                     "Each cell: before → after.*")


def closed_loop_runon() -> str:
    """robustness.md: the rows of the guard's run-on rule, before (the whole table,
    closed_loop_grow.json, 1e1c9f6's) and after (closed_loop_runon.json), on the same truths."""
    a, b = _load("closed_loop_grow.json"), _load("closed_loop_runon.json")
    return _ab(a, b, f"*`python bench/bench_closed_loop.py --samples {b['samples']} --scenarios "
                     f"{' '.join(b['scenarios'])} --families --workers {b['workers']}` "
                     f"({_when(a, b)}; the same truths as the whole table's rows, run from the same folder). "
                     "Each cell: before → after.*")


def closed_loop_aside() -> str:
    """robustness.md: narrow_pass and steep_hill without the margin's allowance aside
    (closed_loop_aside0.json, narrow_pass only) and with it as landed (closed_loop_wall.json),
    on the whole table's truths (closed_loop.json: with the first allowance)."""
    a, m, b = _load("closed_loop_aside0.json"), _load("closed_loop.json"), _load("closed_loop_wall.json")
    lines = [f"*`python bench/bench_closed_loop.py --samples {b['samples']} --scenarios {' '.join(b['scenarios'])} "
             f"--families --workers {b['workers']} [--planner margin_aside_m=0]` ({_when(a, m, b)}; the same truths "
             "in all three: the draw takes the scenario's content). Each cell: no allowance → the allowance "
             "(closed_loop.json's rows) → the allowance kept as the clearance the vehicle has.*", "",
             "| scenario, cost, mode | reached of 10 | stopped / no way on / failed / tipped | stalls |",
             "|---|---|---|---|"]

    for key, gb in b["groups"].items():
        ga, gm = a["groups"].get(key), m["groups"][key]
        cells = [(ga["ends"].get("reached", 0) if ga else "-", gm["ends"].get("reached", 0), gb["ends"].get("reached", 0)),
                 (_ends(ga, True) if ga else "-", _ends(gm, True), _ends(gb, True)), (ga["stalls"] if ga else "-", gm["stalls"], gb["stalls"])]
        lines.append(f"| {key.replace('/', ', ')} | " + " | ".join(" → ".join(map(str, c)) for c in cells) + " |")
    return "\n".join(lines)


def slope_layer() -> str:
    """performance.md: the allowance aside's check with and without the steepest-slope
    layer (slope_layer.json, bench/bench_slope_layer.py)."""
    d = _load("slope_layer.json")
    lines = [f"*`taskset -c 0 python bench/bench_slope_layer.py` ({_when(d)}; the whole-route search alone, one "
             f"core, {d['rounds']} rounds each way, medians; without the value where marked: a longer search)*", "",
             "| scenario, cost | expansions | search with the layer [s] | without [s] | ratio |", "|---|---|---|---|---|"]
    for r in d["rows"]:
        lines.append(f"| `{r['scenario']}` {r['cost']}{'' if r['value'] else ' (no value)'} | {r['expansions']:,} | "
                     f"{r['median_with_s']:.3g} | {r['median_without_s']:.3g} | {r['ratio']:.2f}x |")
    rs = [r["ratio"] for r in d["rows"]]
    lines += ["", f"The search takes {min(rs):.2f}-{max(rs):.2f}x its time without the layer (median "
                  f"{statistics.median(rs):.2f}x)."]
    return "\n".join(lines)


def warthog() -> str:
    """validation.md: the Warthog's held-out errors, calibration and named cause per
    terrain (warthog.json, bench/real_warthog.py)."""
    d = _load("warthog.json")
    lines = [f"*`python bench/real_warthog.py` ({_when(d)}; held-out wheel-speed RMSE, left / right, rad/s, on "
             "the last 30 %)*", "",
             "| terrain | nominal | calibrated | + the named cause | named cause (gain; share of the excess) | "
             "calibrated k, I_max, ref. accel. | alpha: assumed → fitted |", "|---|---|---|---|---|---|---|"]
    for t in ("asphalt", "gravel", "sand"):
        r = d[t]
        e = r["heldout_rmse_rad_s"]
        pair = lambda k, e=e: f"{e[k]['wl']:.2f} / {e[k]['wr']:.2f}"
        best = r["candidates"][0]
        scale = "".join(f" ×{v:.2f}" for v in best["params"].values())
        share = "" if r.get("share") is None else f"; {100 * r['share']:.0f} %"
        cause = (f"`{r['cause']}`{scale} ({r['gain']:.2f}{share})" if r["cause"] == best["effect"] else
                 f"{r['cause']} (best `{best['effect']}`{scale}, gain {best['gain']:.2f}{share})")
        cal = r["calibrated"]
        lines.append(f"| {t} | {pair('nominal')} | {pair('calibrated')} | "
                     + (pair("extended") if r["cause"] == best["effect"] else "-") + f" | {cause} | "
                     f"{cal['torque_constant'][0]:.2f} N m/A, {cal['current_limit'][0]:.0f} A, "
                     f"{cal['ref_accel'][0]:.1f} m/s² | {r['assumed_alpha']:g} → {r['kinematics']['alpha']:.2f} |")
    pose = []
    for t in ("asphalt", "gravel", "sand"):
        p = d[t]["heldout_pose_error"]
        steps = [p[k]["rot_rmse_rad"] for k in ("nominal", "calibrated", "calibrated_alpha")]
        if d[t]["cause"] == d[t]["candidates"][0]["effect"] and p.get("extended"):
            steps.append(p["extended"]["rot_rmse_rad"])
        pose.append(f"{t} " + " → ".join(f"{x:.2f}" for x in steps))
    lines += ["", "Held-out relative pose error over 2 s windows (heading, rad), nominal → calibrated → with the "
              "fitted alpha → with the named cause: " + "; ".join(pose) + "."]
    return "\n".join(lines)


def diagnose_speed() -> str:
    """validation.md: how long a 10-minute run's diagnosis takes (diagnose.json)."""
    d = _load("diagnose.json")
    runs = {r["effect"]: r for r in d["runs"]}
    times = [r["diagnosis_time_s"] for r in d["runs"]]
    delay, tyre = runs["command_delay"], runs["wheel_radius"]
    side = min(tyre["hidden"], key=tyre["hidden"].get)
    return (f"`python bench/bench_diagnose.py` (results in `bench/results/diagnose.json`; {_when(d)}) diagnoses "
            f"{d['minutes']:g}-minute runs at 100 Hz in {_range(times, '.0f')} s on one thread (the bar: well under a "
            f"minute; one run each)"
            + (f", {_range([r['diagnosis_time_threads_s'] for r in d['runs']], '.1f')} s with the candidates fitted "
               f"side by side on {d['threads']} threads (the default; "
               f"{_range([r['diagnosis_time_s'] / r['diagnosis_time_threads_s'] for r in d['runs']], '.2f')}x as fast, "
               "the same diagnosis)" if "threads" in d else "")
            + ". The delay and the tyre were named "
            + ("correctly" if delay["cause"] == "command_delay" and tyre["cause"] == "wheel_radius" else "WRONG")
            + f" ({delay['hidden']['delay_s']:.3f} -> {delay['fitted']['delay_s']:.3f} s; "
            f"{tyre['hidden'][side]:.4f} -> {tyre['fitted'][side]:.4f}, the tyre fitted to the pose) and a clean run "
            f"was named `{runs['none']['cause']}`.")


def hand_over_beside() -> str:
    """The hand-over with and without the plans made beside, on a robot's clock
    (controller_beside_{off,on}.json and _hf for hills_field's longer cap)."""
    pairs = [(_load(f"controller_beside_off{x}.json"), _load(f"controller_beside_on{x}.json"), n)
             for x, n in (("", "narrow_pass"), ("_hf", "hills_field"))]
    docs = [d for a, b, _ in pairs for d in (a, b)]
    lines = [f"*`taskset -c 0 python bench/bench_controller.py --scenarios S --field --beside off|on [--cap C]` "
             f"(the controller at {docs[0]['period_s']:g} s driving the simulated truth in real time on one core; "
             f"{_when(*docs)})*", "",
             "| scenario, cost | `run.beside` | end | driven [s] | energy [J] | held at rest, waiting [s] | "
             "whole-route plans from where it stood | plans made beside (hand-overs onto one) |",
             "|---|---|---|---|---|---|---|---|"]
    for off, on, name in pairs:
        for d, b in ((off, "off"), (on, "on")):
            r = d["runs"][name]
            end = r["status"] if r["status"] == "reached" else f"{r['status'].split(',')[0]}, {r['to_goal_m']} m to go"
            wait = (r["statuses"].get("waiting", 0) + r["statuses"].get("planning", 0)) * d["period_s"]
            lines.append(f"| {name}, {r['cost']} | {b} | {end} | {r['driven_s']:.1f} | {r['energy_J']:.0f} | "
                         f"{wait:.1f} | {r['fallbacks']} | {r['beside_made']} ({r['rejoined']}) |")
    return "\n".join(lines)


def _when(*docs: dict) -> str:
    """Results files' dates and commits (the measured code's, or the commit that stored
    the file): '2026-12-06, f20e6bc, 9e03f87'."""
    dates = sorted({d.get("date", "undated") for d in docs})
    commits = list(dict.fromkeys(c for c in (d.get("commit") or d.get("stored_in") for d in docs) if c))
    return ", ".join(dates + commits)


def _range(xs, fmt: str = ".2f") -> str:
    lo, hi = min(xs), max(xs)
    return f"{lo:{fmt}}" if f"{lo:{fmt}}" == f"{hi:{fmt}}" else f"{lo:{fmt}}-{hi:{fmt}}"


def readme_caption() -> str:
    """The README figure's caption: hill_tradeoff's two plans (energy_plans.json)."""
    d = _load("energy_plans.json")
    t, e = (d["scenarios"]["hill_tradeoff"]["reported"][c] for c in ("time", "energy"))
    return (f"*`sbmpc compare scenarios/hill_tradeoff.yaml --out out` ({_when(d)}; one core):*\n"
            f"- *The time-optimal plan (orange) drives straight over the 1.6 m hill in {t['travel_time_s']:.1f} s.*\n"
            f"- *The energy-optimal plan (violet) skirts the hill's flank: {e['travel_time_s']:.1f} s, but "
            f"{e['energy_J']:.0f} J instead of\n  {t['energy_J']:.0f} J (planned in {e['planning_time_s']:.1f} s, the "
            f"time plan in {t['planning_time_s']:.2f} s).*\n"
            "- *Both are driven at the vehicle's 1 kHz controller rate, as every plan is before it is\n  reported.*\n"
            "- *Halton seed 0 (`--seed`) is shown. The spread over seeds is in [docs/status.md](docs/status.md).*")


def readme_table() -> str:
    """The README's table of what a user gets, every row from its results file."""
    rows = []
    u, ep = _load("unseen_value.json"), _load("energy_plans.json")
    s = u["summary"]
    sp = s["energy_plan_saved_pct"]
    ht = ep["scenarios"]["hill_tradeoff"]["reported"]
    cheaper = ("always costs less than" if s["energy_plan_no_dearer"] == s["both_found"] else
               f"costs no more than on {s['energy_plan_no_dearer']} of them")
    rows.append(("[energy saved against time added](docs/status.md#shipped-scenarios)",
                 f"on {s['both_found']} hilly maps no setting was tuned for, the energy plan {cheaper} the time plan: median "
                 f"{sp['median']:.1f} % less energy for {s['time_cost_pct_median']:.1f} % more time "
                 f"({sp['min']:.1f}-{sp['max']:.0f} %); on `hill_tradeoff` "
                 f"{100 * (1 - ht['energy']['energy_J'] / ht['time']['energy_J']):.0f} % less for "
                 f"{100 * (ht['energy']['travel_time_s'] / ht['time']['travel_time_s'] - 1):.0f} % more",
                 _when(u, ep)))
    v = _load("value.json")
    tp, en, slow = _planning_times()
    rows.append(("[planning time, one core](docs/status.md#status-what-is-measured-against-which-goal)",
                 f"time plans {_range([x for k, x in tp.items() if k != slow])} s (`{slow}` {tp[slow]:.1f} s); "
                 f"energy plans {min(en.values()):.2f}-{max(en.values()):.1f} s on the {len(en)} shipped maps with a path, median "
                 f"{s['planning_time_s_median']['energy_reported']:.1f} s on unseen ones", _when(v, u)))
    rows.append(("[plans that hold](docs/planner.md)",
                 "every reported plan is its drive at the vehicle's 1 kHz controller rate", "always"))
    c = _load("closed_loop.json")
    t = c["totals"]
    rows.append(("[a drawn vehicle, closed loop](docs/robustness.md#measured)",
                 f"{t['runs']} runs on the shipped maps, the vehicle's parameters drawn at random (10 % sd), the map 5 cm off, commands "
                 f"50 ms late: {_pct(t['p_reach_crossable'])} reach the goal where a way exists for the drawn "
                 f"vehicle, {t['ends'].get('tipped', 0)} tip over, {t['ends'].get('off_map', 0)} "
                 f"{'leaves' if t['ends'].get('off_map', 0) == 1 else 'leave'} the map; "
                 "the others stop or fail and say why", _when(c)))
    k = _load("controller.json")
    runs = k["runs"].values()
    rows.append(("[on a robot](docs/performance.md#the-controllers-step)",
                 f"`Controller.step` at {k['period_s']:g} s on one core: p95 at most "
                 f"{max(r['p95_ms'] for r in runs):.1f} ms, "
                 + ("never past the period" if sum(r["over_period"] for r in runs) == 0 else
                    f"{sum(r['over_period'] for r in runs)} steps past the period"), _when(k)))
    cal = _load("calibration.json")
    real = [r for r in cal["real"] if r["robot"] == "warthog"]
    h = lambda key: _range([r["heldout"][key] for r in real], ".0f")
    rows.append(("[model error, real Warthog runs](docs/validation.md#calibration)",
                 f"held-out wheel-speed error {h('nominal')} noise units (1: the sensor's noise) as shipped, {h('calibrated')} calibrated "
                 f"(`sbmpc calibrate`), {h('with_effect')} with the effect `diagnose` names "
                 f"({', '.join(r['terrain'] for r in real)})", _when(cal)))
    cl = _load("calibration_closed_loop.json")
    shipped = [x for key, x in cl["runs"].items() if key.endswith("/shipped")]
    calib = [x for key, x in cl["runs"].items() if key.endswith("/calibrated")]
    prior = cl["calibrated"]
    fails = sum(x["status"] != "reached" for x in shipped)
    fails_c = sum(x["status"] != "reached" for x in calib)
    rows.append(("[calibrate your robot](docs/validation.md#calibration)",
                 f"a P3-AT (the default vehicle) {100 * (cl['truth']['mass'] / prior['mass']['prior'] - 1):.0f} % heavier with its torque "
                 f"constant {100 * (1 - cl['truth']['torque_constant'] / prior['torque_constant']['prior']):.0f} % "
                 f"low: planned with the shipped model it uses "
                 f"{_range([100 * x['energy_error'] for x in shipped if x['status'] == 'reached'], '.0f')} % more "
                 f"energy than predicted" + (f" ({fails} of {len(shipped)} runs {'fails' if fails == 1 else 'fail'})" if fails else "")
                 + "; calibrated on a 90 s drive, within "
                 f"{max(100 * abs(x['energy_error']) for x in calib if x['status'] == 'reached'):.2f} %"
                 + (f" ({fails_c} fail)" if fails_c else ""), _when(cl)))
    lines = ["| | measured at the defaults | when, commit |", "|---|---|---|"]
    lines += [f"| {a} | {b} | {w} |" for a, b, w in rows]
    return "\n".join(lines)


SHOWS = {
    "flat": "sanity: level vinyl, 15 m",
    "hill_tradeoff": "crosses the hill (time) vs skirts it on its lower flank (energy)",
    "hills_field": "60 m x 60 m of hills, ridge and valley",
    "mixed_terrain": "a road around, a rough field across",
    "narrow_pass": "a ridge too steep to cross with one pass 1.5 m wide: both plans take the pass",
    "runup_ramp": "a 20.6° ramp crossed only with momentum (0.7 m/s stalls)",
    "steep_hill": "a 26° hill (13.9° is the limit): every plan goes around",
}


def shipped_scenarios() -> str:
    """status.md's table of the shipped scenarios' plans at the defaults (energy_plans.json)."""
    d = _load("energy_plans.json")
    lines = [f"*`taskset -c 0 python bench/bench_energy_plans.py` ({_when(d)}): the defaults (margin 0.1, guided "
             "by the value), seed 0, one core; every number is the plan driven at the 1 kHz controller rate; the "
             "energy plan's planning time includes the time search it is checked against.*", "",
             "| scenario | shows | time-optimal | energy-optimal |", "|---|---|---|---|"]
    for name, sc in d["scenarios"].items():
        cells = []
        for cost in ("time", "energy"):
            r = sc["reported"][cost]
            kept = " (the time plan: it uses less energy than the energy search's)" if (
                cost == "energy" and (r.get("found_by") or "").startswith("time search")) else ""
            cells.append(f"{r['travel_time_s']:.1f} s, {r['energy_J']:.0f} J ({r['planning_time_s']:.2f} s to plan){kept}"
                         if r["status"] == "found" else f"{r['status']}: {r.get('reason') or ''}")
        lines.append(f"| `{name}` | {SHOWS.get(name, '')} | {cells[0]} | {cells[1]} |")
    lines.append("| `unreachable` | goal on a mesa with 72° cliffs | exit 1 with the reason |  |")
    return "\n".join(lines)


def _params(d: dict, digits: int = 3) -> str:
    return ", ".join(f"{k} {v:.{digits}g}" for k, v in d.items())


def calibration_generated() -> str:
    """validation.md: calibrate, then diagnose, on generated runs (calibration.json)."""
    d = _load("calibration.json")
    rows = d["generated"]
    lines = [f"*`taskset -c 0 python bench/bench_calibrate.py --seeds {len(rows)} --real` ({_when(d)}): a P3-AT "
             "5-15 % off in mass, torque constant, mu_roll, mu_sa and mu_op per seed, 90 s of the synthetic "
             "excitation; held-out error in noise units (1 is the noise); the base error is the joint fit's "
             "against the generating vehicle.*", "",
             "| seed | hidden | named | held out: shipped → calibrated → with the effect | largest base error (joint fit) |",
             "|---|---|---|---|---|"]
    right = 0
    for r in rows:
        h = r["heldout"]
        worst = max(r["relative_error"].items(), key=lambda kv: abs(kv[1]))
        hid = r["hidden"] + (f" ({_params(r['hidden_params'])})" if r["hidden_params"] else "")
        named = r["cause"] + (f" ({_params(r['best']['params'])})" if r["best"] and r["cause"] == r["best"]["effect"]
                              else "")
        right += r["cause"] == r["hidden"]
        lines.append(f"| {r['seed']} | {hid} | {named} | {h['nominal']:.2f} → {h['calibrated']:.2f} → "
                     f"{h['with_effect']:.2f} | {worst[0]} {100 * worst[1]:+.1f} % |")
    clean = [r for r in rows if r["hidden"] == "none"]
    clean_err = max((abs(x) for r in clean for x in r["relative_error"].values()), default=0.0)
    within = sum(all(abs(z) <= 2.0 for z in r["z"].values()) for r in rows)
    floor = sum(r["heldout"]["with_effect"] <= 1.2 for r in rows)
    lines += ["", f"Causes named right: {right} of {len(rows)} (the clean runs `none`: "
              f"{sum(r['cause'] == 'none' for r in clean)} of {len(clean)}). Held-out error at the noise (1.2 or "
              f"less) with the named effect: {floor} of {len(rows)}. Base parameters of the clean runs within "
              f"{100 * clean_err:.1f} % of the truth; every fitted parameter within two standard errors on "
              f"{within} of {len(rows)} runs."]
    return "\n".join(lines)


def calibration_real() -> str:
    """validation.md: calibrate on the real Warthog runs (calibration.json)."""
    d = _load("calibration.json")
    lines = ["| terrain | held out | fitted | named (joint) |", "|---|---|---|---|"]
    for r in d["real"]:
        h = r["heldout"]
        fitted = ", ".join(f"{n} {p['prior']:.3g} → {p['value']:.3g}" for n, p in r["params"].items() if p["fitted"])
        named = r["cause"] + (f" ({_params(r['best']['params'])})" if r["best"] and r["cause"] == r["best"]["effect"]
                              else "")
        lines.append(f"| {r['terrain']} | {h['nominal']:.1f} → {h['calibrated']:.1f} → {h['with_effect']:.1f} | "
                     f"{fitted} | {named} |")
    secs = ", ".join(f"{r['seconds']:.0f}" for r in d["real"])
    lines += ["", f"*({_when(d)}; {secs} s a run on one core.)*"]
    return "\n".join(lines)


def independent_calibrated() -> str:
    """validation.md: calibrate, then diagnose, on the independent implementation's runs
    (independent_calibrated.json)."""
    d = _load("independent_calibrated.json")
    lines = ["| batch | run | hidden | named | held out: shipped → calibrated → with the effect | decided on, share "
             "(else the best candidate's gain) |", "|---|---|---|---|---|---|"]
    for r in d["runs"]:
        h, b = r["heldout"], r["best"] or {}
        hidden = r["hidden"] + (f" ({_params(r['truth'])})" if r["truth"] else "")
        named = r["cause"] + (f" ({_params(r['fitted'])})" if r["fitted"] else "")
        if r.get("absorbed"):
            named += (" (in the calibrated terrain: mu_sa ×" f"{r['base_ratio']['mu_sa']:.2f}, mu_op ×"
                      f"{r['base_ratio']['mu_op']:.2f})")
        mark = "" if r["right"] else " ✗"
        lines.append(f"| {r['base_seed']} | `{Path(r['run']).stem}` | {hidden} | {named}{mark} | "
                     f"{h['nominal']:.2f} → {h['refitted']:.2f} → {h['with_effect']:.2f} | "
                     f"{_decided(r, b)} |")
    clean = d["clean_floor"]
    secs = sorted(r["seconds"] for r in d["runs"])
    lines += ["", f"Causes named right: {d['right']} of {d['total']} (a clean run right only as `none`; a turning "
              "friction right where the calibrated terrain holds it, mu_sa and mu_op within 0.1 of its scale). The clean "
              f"runs' held-out error: {', '.join(f'{x:.2f}' for x in clean['nominal'])} noise units with the "
              f"shipped model, {', '.join(f'{x:.2f}' for x in clean['calibrated'])} calibrated.",
              "", f"*`python bench/bench_independent.py --calibrate --workers 2` ({_when(d)}; "
              f"{secs[len(secs) // 2]:.0f} s a run, median, {secs[0]:.0f}-{secs[-1]:.0f}).*"]
    return "\n".join(lines)


def _decided(r: dict, best: dict) -> str:
    """independent_calibrated's last column: what a named cause was decided on and the
    share it explains (the pose's gain where decided on the pose), else the best
    candidate and its held-out gain."""
    on = r.get("decided_on")
    if on:
        what = {"heldout": "held out", "heldout_only": "held out alone", "training": "training part",
                "pose": "pose"}.get(on, on)
        return f"{what}, {r['share']:.2f}"
    return f"none decisive (best {best.get('effect', '-')}: {best.get('gain', 0):.2f})"


def calibration_closed_loop() -> str:
    """validation.md: what calibration buys in planning (calibration_closed_loop.json)."""
    d = _load("calibration_closed_loop.json")
    cal, truth = d["calibrated"], d["truth"]
    kept = [f"{n} kept ({p['kept']})" for n, p in cal.items() if not p["fitted"] and n in ("current_limit",)]
    lines = [f"*`taskset -c 0 python bench/bench_calibrate.py --closed-loop` ({_when(d)}): calibrated mass "
             f"{cal['mass']['value']:.2f} ± {cal['mass']['se']:.2f} kg for {truth['mass']:.2f}, k "
             f"{cal['torque_constant']['value']:.4f} for {truth['torque_constant']:.4f}"
             + (f"; {'; '.join(kept)}" if kept else "") + ".*", "",
             "| scenario | shipped model: status, stalls, re-plans, executed against predicted energy | calibrated: the same |",
             "|---|---|---|"]
    scen = list(dict.fromkeys(k.split("/")[0] for k in d["runs"]))
    for s_ in scen:
        cells = []
        for m in ("shipped", "calibrated"):
            r = d["runs"][f"{s_}/{m}"]
            cells.append(f"{r['status']}, {r['stalls']} stall{'s' if r['stalls'] != 1 else ''}, {r['replans']} "
                         f"re-plans, {100 * r['energy_error']:+.2f} %")
        lines.append(f"| `{s_}` | {cells[0]} | {cells[1]} |")
    return "\n".join(lines)


def husky() -> str:
    """validation.md: eq. 28 on the Husky's BorealTC runs (husky.json)."""
    d = _load("husky.json")
    lines = ["| terrain | steady stretches (fit / held-out) | fitted μ_roll, μ_sa, μ_op | held-out torque RMSE [N m]: "
             "nearest shipped → fitted |", "|---|---|---|---|"]
    for name, r in d.items():
        if not isinstance(r, dict) or "fitted" not in r:
            continue
        f = r["fitted"]
        se = r["fitted"].get("stderr") or []
        bad = " (standard errors unbounded)" if any(x is None or not math.isfinite(x) for x in se) else ""
        h = r["heldout_rmse_Nm"]
        lines.append(f"| {name.lower().replace('_', ' ')} | {r['steady_train']} / {r['steady_heldout']} | "
                     f"{f['mu_roll']:.2g}, {f['mu_sa']:.2g}, {f['mu_op']:.2g}{bad} | {h['nominal']:.1f} "
                     f"({r['nominal'].replace('_', ' ')}) → {h['fitted']:.1f} |")
    return "\n".join(lines + ["", f"*`python bench/real_husky.py` ({_when(d)}).*"])


CURRENTS = ("i_l", "i_r")


def _runs_mean(terrain: dict, channels, which: str) -> float:
    """A Husky terrain's held-out error (``which``: 'nominal', 'calibrated') over its runs
    and ``channels`` (husky_calibrated*.json)."""
    xs = [u["per_channel"][c][which] for u in terrain["runs"].values() for c in channels if c in u["per_channel"]]
    return sum(xs) / len(xs)


def husky_calibrated() -> str:
    """validation.md: the replay calibrated on the Husky's BorealTC runs, then diagnosed on
    top (husky_calibrated.json)."""
    d = _load("husky_calibrated.json")
    lines = ["| terrain | runs, s | fitted (× the shipped value) | held out, wheel speeds: nominal → calibrated | "
             "held out, currents: nominal → calibrated | on top, on the longest run | its currents: calibrated → "
             "with the effect |", "|---|---|---|---|---|---|---|"]
    for name, r in d["terrains"].items():
        fitted = ", ".join(f"{n} ×{p['value'] / p['prior']:.2f}" for n, p in r["params"].items()
                           if p["fitted"] and p["prior"])
        runs = r["runs"]
        L = r["longest"]
        cur = [c for c in CURRENTS if c in L]
        base = sum(L[c]["base"] for c in cur) / len(cur)
        eff = [L[c].get("with_effect") for c in cur]
        longest = f"{base:.2f}" + (f" → {sum(eff) / len(eff):.2f}" if all(e is not None for e in eff) else "")
        on = r["cause"] + (f" ({_params(r['effect']['params'])}, {r['decided_on']})" if r.get("effect") else "")
        lines.append(f"| {name.lower().replace('_', ' ')} ({r['terrain'].replace('_', ' ')}) | {len(runs)}, "
                     f"{r['seconds_driven']:.0f} | {fitted or 'none'} | {_runs_mean(r, ('wl', 'wr'), 'nominal'):.2f} → "
                     f"{_runs_mean(r, ('wl', 'wr'), 'calibrated'):.2f} | {_runs_mean(r, CURRENTS, 'nominal'):.2f} → "
                     f"{_runs_mean(r, CURRENTS, 'calibrated'):.2f} | {on} | {longest} |")
    return "\n".join(lines + ["", "Held-out errors in noise units, the mean over the terrain's runs and their two "
                               "sides; the last column on the run diagnosed (its longest), the base fitted again on "
                               "it, then with the effect.", "",
                               f"*`python bench/real_husky.py --calibrate --workers 2` ({_when(d)}; "
                               f"{d['seconds_per_terrain']:.0f} s of driving a terrain).*"])


def husky_no_load() -> str:
    """validation.md: the Husky's replay without and with the motors' no-load current
    (husky_calibrated_no_i0.json against husky_calibrated.json)."""
    old, new = _load("husky_calibrated_no_i0.json"), _load("husky_calibrated.json")
    lines = ["| terrain | currents held out, nominal: without → with i0 | calibrated: without → with i0 | "
             "mu_roll fitted (× the shipped): without → with i0 | torque constant fitted: without → with i0 |",
             "|---|---|---|---|---|"]

    def mean(r, which):
        return _runs_mean(r, CURRENTS, which)

    def factor(r, name):
        p = r["params"].get(name)
        return "-" if not p or not p["fitted"] else f"×{p['value'] / p['prior']:.2f}"
    for name, a in old["terrains"].items():
        b = new["terrains"].get(name)
        if b is None:
            continue
        lines.append(f"| {name.lower().replace('_', ' ')} | {mean(a, 'nominal'):.2f} → {mean(b, 'nominal'):.2f} | "
                     f"{mean(a, 'calibrated'):.2f} → {mean(b, 'calibrated'):.2f} | {factor(a, 'mu_roll')} → "
                     f"{factor(b, 'mu_roll')} | {factor(a, 'torque_constant')} → {factor(b, 'torque_constant')} |")
    return "\n".join(lines + ["", f"*Without: {_when(old)}; with the `husky` file's `no_load_current: 1.35` A: "
                                   f"{_when(new)}; both `python bench/real_husky.py --calibrate --workers 2`, held-out "
                                   "errors in noise units, the mean over a terrain's runs and both sides.*"])


def status_defaults() -> str:
    """status.md: the rows measured at today's defaults, each from its results file."""
    rows = []
    v = _load("value.json")
    tp, energy, slow = _planning_times()
    en = sorted((x, n) for n, x in energy.items())
    met_e = sum(x <= 2.0 for x, _ in en)
    met_t = sum(x <= 0.5 for x in tp.values())
    rows.append(("planning time on one core at the defaults (margin 0.1, the value; the polish, the time plan an "
                 "energy plan is checked against and the 1 kHz check included)",
                 "energy plans " + ", ".join(f"{x:.2f} (`{n}`)" for x, n in en) + f" s; time plans "
                 f"{_range([x for k, x in tp.items() if k != slow])} s, `{slow}` {tp[slow]:.1f} s ({_when(v)})",
                 f"issue 59: energy 2 s met on {met_e} of {len(en)}, time 0.5 s on {met_t} of {len(tp)}",
                 "`taskset -c 0 python bench/bench_value.py`"))
    e = _load("energy_plans.json")
    spread = sorted((sc["seed_spread_pct"], n) for n, sc in e["scenarios"].items())
    secs = [x for sc in e["scenarios"].values() for _, x in sc["planning_s_by_seed"]]
    rows.append(("energy plans over Halton seeds 0-7 (the defaults)",
                 "spread " + ", ".join(f"{x:.1f} % (`{n}`)" for x, n in spread)
                 + f"; energy plans {min(secs):.2f}-{max(secs):.0f} s a seed ({_when(e)}, one core)",
                 f"issue 59, 5 % on every scenario: met on {sum(x <= 5.0 for x, _ in spread)} of {len(spread)}",
                 "`taskset -c 0 python bench/bench_energy_plans.py --keep-reference`"))
    u = _load("unseen_value.json")
    s = u["summary"]
    sp = s["energy_plan_saved_pct"]
    pt = s["planning_time_s_median"]
    rows.append((f"energy plan against time plan, {s['maps']} random hilly maps no setting was tuned for (the "
                 "defaults, one core)",
                 f"both found on {s['both_found']} ({s['neither_found']} with no way, {s['one_found']} with one plan "
                 f"only); the energy plan no dearer on {s['energy_plan_no_dearer']} of {s['both_found']} (median "
                 f"saving {sp['median']:.1f} %, {sp['min']:.1f}-{sp['max']:.0f} %; time +{s['time_cost_pct_median']:.1f} "
                 f"% median); planning time median {pt['time']:.2f} s (time), {pt['energy_reported']:.1f} s (the energy "
                 f"plan, its time plan included) ({_when(u)})",
                 "issue 59: found and cheaper on every map both exist: "
                 + ("met" if s["energy_plan_no_dearer"] == s["both_found"] else "not met"),
                 "`taskset -c 0 python bench/bench_unseen.py --first 100 --maps 20 --threads 1 --out "
                 "bench/results/unseen_value.json`"))
    h = _load("horizon.json")
    hs = h["summary"]
    rng = hs["cost_ratio_range"]
    rows.append(("receding-horizon runs (`sbmpc run --horizon 10`: the controller against the simulated truth; "
                 "one core, 7 scenarios and 70/170 m fields, both costs)",
                 f"{hs['horizon_reached']} of {hs['cases']} reach the goal; horizon plans within 0.1 s: "
                 f"{100 * hs['replan_within_0.1s']:.0f} % of {hs['horizon_plans']} (p95 "
                 f"{1000 * hs['replan_p95_s']:.0f} ms), first plans at most {1000 * hs['first_max_s']:.0f} ms; executed "
                 f"cost median {hs['cost_ratio_median']:.2f}x the whole-route run's ({rng[0]:.2f}-{rng[1]:.2f}), within "
                 f"5 % on {hs['within_5pct']}; {hs['cases_with_fallback']} needed a whole-route fallback "
                 f"({_when(h)})",
                 f"issue 59: {hs['horizon_reached']} of {hs['cases']} reach; within 5 % on 16: "
                 + ("met" if hs["within_5pct"] >= 16 else "not met"),
                 "`taskset -c 0 python bench/bench_horizon.py --threads 1`"))
    k = _load("controller.json")
    runs = k["runs"]
    rows.append((f"the controller a robot calls (`sbmpc.Controller.step` at {k['period_s']:g} s, one core, the "
                 "simulated truth driven in real time, planning in worker threads; 7 scenarios and the 340 m field, "
                 f"{k['cap_s']:.0f} s each at most)",
                 f"`step` median {_range([r['median_ms'] for r in runs.values()])} ms, p95 "
                 f"{_range([r['p95_ms'] for r in runs.values()], '.1f')} ms, max "
                 f"{max(r['max_ms'] for r in runs.values()):.1f} ms; {sum(r['over_period'] for r in runs.values())} of "
                 f"{sum(r['steps'] for r in runs.values())} steps over the period; "
                 f"{sum(r['fallbacks'] for r in runs.values())} whole-route hand-overs, the wheels held at rest while "
                 f"each is made ({_when(k)})",
                 "issue 60: p95 ≤ 50 ms, never past the period: "
                 + ("met" if all(r["p95_ms"] <= 50 and r["over_period"] == 0 for r in runs.values()) else "not met")
                 + "; never waiting on a whole-route plan: "
                 + ("met" if sum(r["fallbacks"] for r in runs.values()) == 0 else
                    "not met by default; with `run.beside` far fewer waits, but runs not reliably better "
                    "([planner.md](planner.md#measured-off-by-default))"),
                 "`taskset -c 0 python bench/bench_controller.py`"))
    return _table(rows)


def _table(rows) -> str:
    """status.md's tables: what, measured, goal, command."""
    lines = ["| what | measured | goal | command |", "|---|---|---|---|"]
    return "\n".join(lines + [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows])


def _edges() -> list:
    """Converged edges and the cost of one (edges.json): two rows."""
    d = _load("edges.json")
    c, s, m = d["convergence"]["all"], d["convergence"]["all_seeds"], d["on_maps"]["all"]
    seeds = len(s["seeds"])
    ok = (min(c["stall_verdict_agrees"], s["stall_verdict_agrees"], m["stall_agrees"]) >= 0.995
          and min(x["energy_within_2pct"] for x in (c, s, m)) >= 0.99
          and min(x["pose_within_5cm_2deg"] for x in (c, s, m)) >= 0.99)
    k = d["cost"]
    r = k["ratio_current_to_baseline"]["median"]
    cmd = f"`python bench/bench_edges.py --baseline {k['baseline_rev']}`"
    return [(f"edges at the planner's {1000 * d['dt']:.0f} ms step against the 1 kHz controller rate ({c['edges']} "
             f"random edges, {s['edges']} over {seeds} seeds; {m['edges']} on the shipped hilly maps)",
             f"stall verdicts {_pct(c['stall_verdict_agrees'], '.2f')}, over {seeds} seeds "
             f"{_pct(s['stall_verdict_agrees'], '.2f')} (maps {_pct(m['stall_agrees'], '.1f')}), energies within 2 % "
             f"{_pct(c['energy_within_2pct'], '.1f')} (maps {_pct(m['energy_within_2pct'], '.1f')}), poses within 5 cm "
             f"and 2° {_pct(c['pose_within_5cm_2deg'])} (maps {_pct(m['pose_within_5cm_2deg'])}) ({_when(d)})",
             f"99.5 %, 99 %, 99 %: {_met(ok)}", cmd),
            (f"cost of an edge against the old explicit edge ({k['baseline_rev']})",
             f"{r:.2f}x as shipped ({d['cost_on_search_nodes']['ratio_current_to_baseline']['median']:.2f}x on search "
             f"nodes; the edge {k['current']['us_per_edge_median']:.1f} µs against "
             f"{k['baseline']['us_per_edge_median']:.1f} µs) ({_when(d)})", f"1.5x: {_met(r <= 1.5)}", cmd)]


def _unweighted() -> tuple:
    """The energy plans' median over seeds against a long unweighted search (energy_plans.json)."""
    e = _load("energy_plans.json")
    ref = {n: s for n, s in e["scenarios"].items() if (s.get("unweighted_10x") or {}).get("status") == "found"}
    gap = sorted((100 * (s["seed_median_J"] / s["unweighted_10x"]["energy_J"] - 1), n) for n, s in ref.items())
    same = {}
    for x, n in gap:
        same.setdefault(f"{x:+.1f} %", []).append(f"`{n}`")
    over = [f"`{n}` {x:+.2f} %" for x, n in gap if x > 2.0]
    kept = all(s["unweighted_10x"].get("kept_from_results_file") for s in ref.values())
    return ("energy plans against a long unweighted search (w = 1, 10x the budget, guided by the grid alone)",
            "the median over seeds " + ", ".join(f"{k} ({', '.join(v)})" for k, v in same.items()) + f" ({_when(e)}"
            + ("; the reference searches kept from an earlier run: `--keep-reference`" if kept else "") + ")",
            f"issue 59, 2 %: met on {len(gap) - len(over)} of {len(gap)}" + (f" (not on {', '.join(over)})" if over else ""),
            "`taskset -c 0 python bench/bench_energy_plans.py --keep-reference`")


def _route_value() -> tuple:
    """Whole-route energy plans on long generated fields, with the margin (route_value.json)."""
    d = _load("route_value.json")
    rows, goal = d["rows"], {170: 3.0, 340: 6.0, 500: 10.0}
    by = {}
    for r in rows:
        if r["status"] == "found":
            by.setdefault(r["route_m"], []).append(r["planning_time_s"])
    ok = {m: sum(x <= goal[m] for x in xs) for m, xs in by.items()}
    seeds = sorted({r["seed"] for r in rows})
    return (f"whole-route energy plans on generated hills fields (margin {rows[0]['margin']:g}, one core, map seeds "
            f"{seeds[0]}-{seeds[-1]})",
            f"{sum(map(len, by.values()))} of {len(rows)} found: "
            + ", ".join(f"{m} m routes {_range(xs, '.1f')} s" for m, xs in by.items())
            + f" ({_when(d)}, the other core busy)",
            "issue 59: " + ", ".join(f"{goal[m]:g}" for m in by) + f" s: {_met(all(ok[m] == len(by[m]) for m in by))} ("
            + ", ".join(f"{m} m on {ok[m]} of {len(by[m])}" for m in by) + ")",
            "`taskset -c 0 python bench/bench_route.py --routes 170 340 500 --seeds 7 8 9 --margins 0.1 --costs energy "
            "--out bench/results/route_value.json`")


def _replans() -> tuple:
    """Re-plans of whole-route runs on drawn truths (value_replans.json)."""
    d = _load("value_replans.json")
    runs = d["replans"]
    scen = list(dict.fromkeys(r["scenario"] for r in runs))
    slowest = {i: max(r["replan_s"]) for i, r in enumerate(runs) if r["replan_s"]}
    slow = [i for i, x in slowest.items() if x > 1.0]
    slow_in = " and ".join(dict.fromkeys(f"`{runs[i]['scenario']}`" for i in slow))
    return (f"re-plans of `sbmpc run` (whole-route) from a vehicle drifted off its plan: truths with mass and grip drawn "
            f"at 10 % sd, {len(runs) // len(scen)} each on {', '.join(f'`{s}`' for s in scen)}, "
            + ", ".join(dict.fromkeys(r["cost"] for r in runs)),
            f"re-plans unpolished: {sum(r['status'] == 'reached' for r in runs)} of {len(runs)} runs reach the goal, "
            f"re-plans median {d['replan_median_s']:.2f} s, 95th percentile {d['replan_p95_s']:.1f} s "
            f"({_range(slowest.values())} s on the slowest of each run) ({_when(d)})",
            f"issue 59: 1 s at the 95th percentile: {_met(d['replan_p95_s'] <= 1.0)}"
            + (f" (the re-plans of {slow_in} take {_range([slowest[i] for i in slow], '.1f')} s at their slowest)"
               if slow else ""),
            "`taskset -c 0 python bench/bench_value.py --replans 4 --scenarios steep_hill narrow_pass hills_field --costs "
            "energy --out bench/results/value_replans.json`")


def _unseen() -> tuple:
    """Energy plan against time plan on unseen maps, before the margin and the value (unseen.json)."""
    u = _load("unseen.json")
    s = u["summary"]
    sp = s["energy_saved_pct"]
    return (f"energy plan against time plan, {s['maps']} random hilly maps no setting was tuned for",
            f"both found on {s['both_found']} (the other {s['maps'] - s['both_found']} say why); the energy search's own "
            f"plan no dearer on {s['energy_search_no_dearer']} of {s['both_found']} (median saving {sp['median']:.1f} %, "
            f"{sp['min']:.1f}-{sp['max']:.1f} %) ({_when(u)})",
            f"never dearer: {_met(s['energy_search_no_dearer'] == s['both_found'])}", "`python bench/bench_unseen.py`")


def _value_builds() -> tuple:
    """The value's build times on the large maps, grouped by lattice size (value.json)."""
    v = _load("value.json")
    size = {}
    for b in v["builds"]:
        if "field" in b["scenario"]:
            size.setdefault(b["states"], []).append(b)

    def maps(bs):
        names = list(dict.fromkeys(b["scenario"] for b in bs))
        routes = [n[6:-1] for n in names if n.startswith("field_")]
        shown = [f"`{n}`" for n in names if not n.startswith("field_")]
        if routes:
            shown.append(f"the {' and '.join(routes)} m route field{'s' if len(routes) > 1 else ''}")
        return " and ".join(shown)
    parts = [f"{_range([b['build_s'] for b in bs])} s for {maps(bs)} "
             f"({f'{n / 1e6:.2f} M' if n >= 1e6 else f'{n / 1e3:.0f} k'} lattice states, "
             f"{_range([b['cell_m'] for b in bs], '.2g')} m cells)" for n, bs in sorted(size.items())]
    small = size[min(size)]
    return ("the value over position and heading: its build on one core (`taskset -c 0`)",
            "; ".join(parts) + f"; the motion tables {_range([b['tables_s'] for b in v['builds']])} s once per vehicle "
            f"and terrains; {_range([b['us_per_state'] for b in v['builds']], '.1f')} µs a state ({_when(v)})",
            f"0.3 s for a 60 m map: {_met(max(b['build_s'] for b in small) <= 0.3)}; linear in the lattice",
            f"`{v['command'].strip()}`")


def _planner() -> list:
    """Planning time on one core, and two cores against one, before the margin and the value (planner.json)."""
    p = _load("planner.json")
    one = {(n, c): r["serial"]["planning_time_s"] for n, sc in p["scenarios"].items() for c, r in sc.items()
           if r["serial"]["status"] == "found"}
    tp = {n: x for (n, c), x in one.items() if c == "time"}
    slow = max(tp, key=tp.get)
    en = [x for (n, c), x in one.items() if c == "energy"]
    over = sum(x > 1.0 for x in one.values())
    both = {k: x / p["scenarios"][k[0]][k[1]]["batch16"]["planning_time_s"] for k, x in one.items() if x > 2.0}
    least = min(both, key=both.get)
    return [("planning time on one core (before the margin and the value)",
             f"time plans {_range([x for n, x in tp.items() if n != slow])} s, `{slow}` {tp[slow]:.1f} s; energy plans "
             f"{_range(en)} s ({sum(x > 1.0 for x in en)} over 1 s) ({_when(p)})",
             f"1 s: {_met(not over)} ({over} of {len(one)} plans over)", "`python bench/bench_planner.py`"),
            (f"planning on {p['cores']} cores against one",
             f"{_range(both.values())}x (median {statistics.median(both.values()):.2f}x) on the {len(both)} plans over "
             f"2 s, the least `{least[0]}` {least[1]} {both[least]:.2f}x ({_when(p)}) ([why](performance.md#planner))",
             f"1.7x: met on {sum(x >= 1.7 for x in both.values())} of {len(both)}", "`python bench/bench_planner.py`")]


def _corridor() -> tuple:
    """Coarse to fine against the search alone, over seeds (corridor.json: its two configurations)."""
    d = _load("corridor.json")
    off, on = d["configs"].values()
    ratio = lambda k, f: off[k][f] / on[k][f]
    name = lambda ks: ", ".join(f"`{k.split('/')[0]}`" for k in ks)
    en = [k for k in off if k.endswith("/energy")]
    dearer = {k: 100 * (on[k]["median"] / off[k]["median"] - 1) for k in en}
    gain = [k for k in en if ratio(k, "median_expansions") >= 2.0]
    worse = [k for k in en if k not in gain and dearer[k] > 1.0]
    rest = [k for k in en if k not in gain + worse]
    spread = ", ".join(f"{off[k]['spread_pct']:.1f} → {on[k]['spread_pct']:.1f} % ({name([k])})" for k in gain)
    return ("coarse to fine, opt-in (`planner.corridor_energy: 1.5`: the search looks along a coarse route first)",
            f"energy plans over seeds 0-{len(off[en[0]]['by_seed']) - 1}: {name(gain)} "
            f"{_range([ratio(k, 'median_expansions') for k in gain], '.1f')}x fewer expansions, "
            f"{_range([ratio(k, 'median_planning_s') for k in gain], '.1f')}x faster, median "
            f"{_change([dearer[k] for k in gain])}, spread {spread}; "
            + "".join(f"{name([k])} median {dearer[k]:+.1f} %; " for k in worse)
            + f"no such gain on {name(rest)} (at most {max(ratio(k, 'median_expansions') for k in rest):.1f}x fewer "
            f"expansions) or the time plans ({_range([ratio(k, 'median_planning_s') for k in off if k.endswith('/time')], '.1f')}x "
            f"as fast) ({_when(d)}) ([why](performance.md#coarse-to-fine))",
            "not the default: a plan must not get dearer",
            '`python bench/bench_settings.py --config "corridor_energy=0,corridor_time=0" --config '
            '"corridor_energy=1.5,corridor_time=1.5" --costs energy time --out bench/results/corridor.json`')


def _gpu() -> tuple:
    """The GPU backend's edges per second and plans (gpu.json)."""
    g = _load("gpu.json")
    e = max(g["edges"], key=lambda x: x["edges"])
    rate = max(v for k, v in e.items() if k.startswith("cuda") and k.endswith("edges_per_s"))
    plans = [r["planning_time_s"] for sc in g["plans"].values() for k, r in sc.items()
             if "cuda" in k and r["status"] == "found"]
    batches = " and ".join(str(c["batch"]) for c in g["configs"].values() if c["device"] == "cuda")
    return (f"on a GPU ({g['device'].removeprefix('NVIDIA ')}, not re-measured since the batches changed)",
            f"{rate / 1e6:.1f} M edges/s ({e['edges']} edges a call), {e['ratio_best_cuda_to_cpu']:.0f}x {g['cpu_cores']} CPU "
            f"cores; plans {_range(plans, '.1f')} s ({len(plans)} at batch {batches}, {len(g['skipped'])} skipped at "
            f"the deadline) ({_when(g)})",
            f"0.1 s: {_met(max(plans) <= 0.1)} (a GPU call costs about "
            f"{min(x['cuda_call_ms'] for x in g['edges']):.0f} ms)", "`python bench/bench_gpu.py`")


def _independent() -> tuple:
    """Diagnosis of runs from an independent implementation of the paper's model (independent.json)."""
    d = _load("independent.json")
    runs = d["runs"]
    world = [r for r in runs if "toward_deg" in (r["truth"] or {})]
    fits = " and ".join(f"{r['fitted']['grade_deg']:.2f}° towards {r['fitted']['toward_deg']:.1f}°" for r in world)
    gains = [r["gain"] for r in runs if r["hidden"] != "none" and r["decided_on"] != "training"]
    return ("diagnosis of runs from an independent implementation of the paper's model",
            f"{d['right']} of {d['total']} causes right (`none` included"
            + "".join(f"; a run without an effect, {r['baseline_heldout_error']:.1f} noise units left, is `unexplained`, "
                      f"counted {'right' if r['right'] else 'wrong'}" for r in runs if r["cause"] == "unexplained")
            + "".join(f"; a {r['truth']['grade_deg']:g}° grade towards {r['truth']['toward_deg']:g}° fixed in the world: "
                      f"{fits}" for r in world[:1])
            + f"), held-out gains {_range(gains)} where the held-out part can show the effect ({_when(d)})",
            "", "`python bench/bench_independent.py`")


TRUTHS = {"heavy": "heavier", "slippery": "with less grip"}


def _horizon_truths() -> tuple:
    """Receding-horizon and whole-route runs on a mismatched truth (horizon_truths.json)."""
    h = _load("horizon_truths.json")
    s, rows = h["summary"], h["rows"]
    case = lambda r: f"`{r['scenario']}` {r['cost']} {TRUTHS.get(r['truth'], r['truth'])}"
    lost = [r for r in rows if r["horizon"]["status"] != "reached"]
    stopped = [r for r in rows if r["whole_route"]["status"] != "reached"]
    tip = all("tip-over margin" in (r["whole_route"]["reason"] or "") for r in stopped)
    ratios = [r for r in rows if r["cost_ratio"] is not None]
    worst = max(ratios, key=lambda r: r["cost_ratio"])["scenario"]
    w = [r for r in ratios if r["scenario"] == worst]
    lo, hi = s["cost_ratio_range"]
    within = "all" if s["replan_within_0.1s"] == 1 else f"{_pct(s['replan_within_0.1s'])} of the"
    return (f"receding-horizon runs with a mismatched truth (10 % heavier or 10 % less grip; "
            f"{len({r['scenario'] for r in rows})} scenarios, both costs, both cores)",
            f"horizon runs reach the goal in {s['horizon_reached']} of {s['cases']}"
            + "".join(f"; {case(r)}: {r['horizon']['reason']}" for r in lost)
            + (" (since then the guard holds back a period whose prediction leaves the map)"
               if any("left the map" in (r["horizon"]["reason"] or "") for r in lost) else "")
            + f"; whole-route runs {s['whole_route_reached']} of {s['cases']}"
            + (f", the others ({', '.join(map(case, stopped))}) "
               + ("stop rather than come within the tip margin, and say why" if tip else "fail, and say why")
               if stopped else "")
            + f"; {within} {s['horizon_plans']} horizon plans within 0.1 s (p95 {1000 * s['replan_p95_s']:.0f} ms); "
            f"cost median {s['cost_ratio_median']:.2f}x, within 5 % on {s['within_5pct']} of {len(ratios)} "
            f"({lo:.2f}-{hi:.2f}; `{worst}` {_range([r['cost_ratio'] for r in w])}x with "
            f"{_range([r['horizon']['horizon']['fallbacks'] for r in w], '.0f')} fallbacks); "
            f"{s['cases_with_fallback']} with fallbacks ({_when(h)})",
            "issue 44 item 2: every run reaches, within 5 %: "
            + _met(s["horizon_reached"] == s["cases"] and s["within_5pct"] == s["cases"]),
            "`python bench/bench_horizon.py --fields --truths heavy slippery --out bench/results/horizon_truths.json`")


def _horizon_seeds() -> tuple:
    """Receding-horizon runs over seeds beside the whole-route plans' spread (horizon_seeds.json)."""
    d = _load("horizon_seeds.json")
    s = d["summary"].values()
    return (f"receding-horizon runs over Halton seeds 0-{d['seeds'] - 1} (energy, nominal truth, one core)",
            f"executed energy spreads {_range([x['spread_pct'] for x in s], '.1f')} % (whole-route plans with the "
            f"margin {_range([x['whole_route_plans_spread_pct'] for x in s], '.1f')} %); {sum(x['reached'] for x in s)} "
            f"of {sum(x['runs'] for x in s)} reach the goal ({_when(d)}) ([why](planner.md#receding-horizon-plans))",
            "issue 44 item 4: reported beside the plans' spread (5 % allowed for the plans)",
            f"`taskset -c 0 python bench/bench_horizon.py --threads 1 --fields --costs energy --seeds {d['seeds']}`")


def _horizon_340() -> tuple:
    """Receding-horizon runs on the 340 m field (horizon_340.json)."""
    d = _load("horizon_340.json")
    s, rows = d["summary"], d["rows"]
    hz = [r["horizon"]["horizon"] for r in rows]
    whole = " and ".join(f"{r['whole_route']['first_plan_s']:.1f}" for r in rows)
    falls = ", ".join(f"{r['cost']} {', '.join(f'{x:.1f} s' for x in z['fallback_s']) or 'none'}" for r, z in zip(rows, hz))
    within = "all" if s["replan_within_0.1s"] == 1 else f"{_pct(s['replan_within_0.1s'])} of the"
    return (f"receding-horizon runs on the {rows[0]['scenario'][6:-1]} m field (one core, both costs)",
            f"{s['horizon_reached']} of {s['cases']} reach the goal; first plans "
            f"{_range([1000 * z['first_s'] for z in hz], '.0f')} ms (the value built by the whole-route run before, whose "
            f"first plans took {whole} s), {within} {s['horizon_plans']} horizon plans after the first within 0.1 s (p95 "
            f"{1000 * s['replan_p95_s']:.0f} ms); whole-route fallbacks: {falls}; executed cost "
            + " and ".join(f"{r['cost_ratio']:.2f}x ({r['cost']})" for r in rows)
            + f" the whole-route run's ({_when(d)}) ([why](planner.md#receding-horizon-plans))",
            f"issue 59, first plan 0.3 s: {_met(s['first_max_s'] <= 0.3)} where the value is built; no fallback, within "
            f"5 %: {_met(s['cases_with_fallback'] == 0 and s['within_5pct'] == s['cases'])}",
            "`taskset -c 0 python bench/bench_horizon.py --threads 1 --scenarios --fields 340 --out "
            "bench/results/horizon_340.json`")


def _route_length() -> tuple:
    """Whole-route planning time against route length, margin 0 (route.json), against the polish at
    every control (route_every.json) and the time plan always checked (route_ab.json)."""
    r, ev, ab = _load("route.json"), _load("route_every.json"), _load("route_ab.json")
    med = r["slopes"]["energy, margin 0"]["median_s"]
    limit = {"170": 4.0, "340": 10.0}
    energy = {(x["route_m"], x["seed"]): x for x in r["rows"] if x["cost"] == "energy"}
    slow = [x for x in energy.values() if x["planning_time_s"] > limit.get(str(x["route_m"]), math.inf)]
    every = [x for x in ev["rows"] if x["margin"] == 0]
    gap = {(x["route_m"], x["seed"]): 100 * (energy[x["route_m"], x["seed"]]["energy_J"] / x["energy_J"] - 1)
           for x in every if not x["found_by"]}
    checked = {}
    for key, x in ab["summary"].items():
        checked.setdefault(key.split(" m")[0], []).append(x["ratio_median"])
    return (f"whole-route plans against route length (fields of {', '.join(med)} m, "
            f"{len({x['seed'] for x in r['rows']})} maps each, one core, margin {r['rows'][0]['margin']:g})",
            f"energy plans median {', '.join(f'{x:.1f}' for x in med.values())} s; with the polish at every control, "
            "as before: " + ", ".join(f"{x['route_m']} m {x['planning_time_s']:.0f} s" if not x["found_by"] else
                                      f"{x['route_m']} m no energy plan in {x['planning_time_s']:.0f} s" for x in every)
            + "".join(f"; the shipped plan's energy against it {g:+.2f} % ({m} m map {sd})" for (m, sd), g in gap.items())
            + f"; the polish of plans over {r['exact_up_to']} controls at their head and tail after the check, re-plans "
            "made once per plan, the time plan driven at 1 kHz only where it could be the energy plan ("
            + ", ".join(f"{m} m {_range(x)}x" for m, x in checked.items())
            + f" the planning time, `--ab {ab['pairs']}`) ({_when(r, ev, ab)}) ([why](performance.md#route-length))",
            "340 m within 10 s, 170 m within 4 s, energy within 1 %: "
            + _met(all(med[m] <= x for m, x in limit.items()) and all(abs(g) <= 1.0 for g in gap.values()))
            + " at the median" + (" (not on " + ", ".join(f"{x['route_m']} m map {x['seed']}: {x['planning_time_s']:.1f} s"
                                                        for x in slow) + ")" if slow else ""),
            "`taskset -c 0 python bench/bench_route.py`, `--polish every`, `--ab 3`")


def _sbmpo() -> tuple:
    """The lab's C++ SBMPO benchmark run by this planner (sbmpo_unicycle.json)."""
    d = _load("sbmpo_unicycle.json")
    c = d["reference_cpp"]
    t, tc = d["suite"]["total_time_s"], c["suite"]["total_time_s"]
    m, mc = d["main"]["solve_time_s"], c["main"]["solve_time_s"]
    return ("the lab's C++ SBMPO benchmark (its main map and 100-map suite), run exactly",
            f"suite in {1000 * t:.0f} ms per pass against {1000 * tc:.0f} ms ({d['suite']['solved']} maps solved, the "
            f"C++ {c['suite']['solved']}); main map {1000 * m:.2f} ms against {1000 * mc:.2f} ms ({_when(d)})",
            f"faster: {_met(t < tc and m < mc)}", "`python bench/sbmpo_unicycle.py --json bench/results/sbmpo_unicycle.json`")


def status_other() -> str:
    """status.md: the other measurements (older, or not at the defaults), each row from its results file."""
    return _table([*_edges(), _unweighted(), _route_value(), _replans(), _unseen(), _value_builds(), *_planner(),
                   _corridor(), _gpu(), _independent(), _horizon_truths(), _horizon_seeds(), _horizon_340(),
                   _route_length(), _sbmpo()])


BLOCKS = {"closed-loop-table": closed_loop_table, "closed-loop-aside": closed_loop_aside, "closed-loop-totals": closed_loop_totals,
          "closed-loop-before": lambda: closed_loop_totals("closed_loop_before.json"),
          "closed-loop-maps": lambda: closed_loop_totals("closed_loop_maps.json"),
          "closed-loop-adapt": closed_loop_adapt,
          "closed-loop-hills": closed_loop_hills, "closed-loop-guard": closed_loop_guard, "closed-loop-grade": closed_loop_grade,
          "closed-loop-backoff": closed_loop_backoff, "closed-loop-runon": closed_loop_runon, "hand-over-beside": hand_over_beside,
          "diagnose-speed": diagnose_speed, "warthog": warthog, "slope-layer": slope_layer,
          "husky-no-load": husky_no_load,
          "readme-caption": readme_caption, "readme-table": readme_table,
          "shipped-scenarios": shipped_scenarios, "calibration-generated": calibration_generated,
          "calibration-real": calibration_real, "independent-calibrated": independent_calibrated,
          "calibration-closed-loop": calibration_closed_loop,
          "husky": husky, "husky-calibrated": husky_calibrated, "status-defaults": status_defaults, "status-other": status_other}


def updated(text: str) -> str:
    """``text`` with every block rewritten from its results file."""
    def one(m):
        name = m.group("name")
        if name not in BLOCKS:
            raise KeyError(f"report:{name}: no such block (known: {', '.join(BLOCKS)})")
        return m.group(1) + BLOCKS[name]() + "\n" + m.group(4)
    return MARK.sub(one, text)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 where a page differs from what its files give")
    a = ap.parse_args()
    stale = []
    for page in PAGES:
        text = page.read_text()
        new = updated(text)
        if new != text:
            stale.append(page)
            if not a.check:
                page.write_text(new)
    for p in stale:
        print(f"{'stale' if a.check else 'rewrote'}: {p.relative_to(ROOT)}")
    return 1 if (a.check and stale) else 0


if __name__ == "__main__":
    sys.exit(main())
