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
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
PAGES = [ROOT / "README.md", ROOT / "docs" / "status.md", ROOT / "docs" / "validation.md",
         ROOT / "docs" / "robustness.md"]
MARK = re.compile(r"(<!-- report:(?P<name>[a-z0-9-]+) -->\n)(?P<body>.*?)(<!-- /report:(?P=name) -->)", re.S)


def _load(name: str) -> dict:
    return json.loads((RESULTS / name).read_text())


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.0f} %"


def _ratio(s) -> str:
    return "-" if not s else f"{s['median']:.2f} ({s['p90']:.2f})"


def closed_loop_table() -> str:
    """Per scenario, cost and mode: runs, ends, p_reach, the cost ratios (closed_loop.json)."""
    d = _load("closed_loop.json")
    lines = [f"*`python bench/bench_closed_loop.py --samples {d['samples']} --workers {d['workers']}` "
             f"({d['date']}; {d.get('label') or 'no label'}): {d['samples']} truths per row, vehicle "
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
    return (f"{t['runs']} runs ({d['date']}; {d.get('label') or 'no label'}): {e.get('reached', 0)} reached, {e.get('stopped', 0)} stopped rather "
            f"than tip over, {e.get('no_path', 0)} found no way on and said why, {e.get('failed', 0)} failed "
            f"(stalls, the time or re-plan limit); tipped over {bad['tipped']}, off the map {bad['off_map']}, "
            f"timeouts {bad['timeout']}, tracebacks {bad['error']}. p_reach {t['p_reach_crossable']:.2f} over the "
            f"{t['crossable']} runs whose truth the planner finds a way for (target 0.95: met on "
            f"{t['groups_meeting_p_reach_0.95']} of the {t.get('groups_crossable', t['groups'])} rows with such runs); executed cost over the own vehicle's "
            f"plan median {t['over_own_plan']['median']:.2f}, p90 {t['over_own_plan']['p90']:.2f} (p90 within "
            f"10 %: {t['groups_meeting_cost_p90_1.10']} of {t.get('groups_crossable', t['groups'])} rows).")


def readme_closed_loop() -> str:
    """The README's line under its table (closed_loop.json)."""
    d = _load("closed_loop.json")
    t = d["totals"]
    e = t["ends"]
    where = "the shipped maps" + (" and unseen ones" if d["families"] else "")
    return (f"Closed loop on drawn vehicles ([details](docs/robustness.md#measured)): {t['runs']} runs on {where}, "
            f"the vehicle drawn at 10 %, the map 5 cm off, commands 50 ms late: "
            f"{_pct(t['p_reach_crossable'])} reach the goal where a way exists for the drawn vehicle, "
            f"{e.get('tipped', 0)} tip over, {e.get('off_map', 0)} leave the map; the others stop or fail and say why "
            f"({d['date']}).")


def closed_loop_adapt() -> str:
    """Adaptation on and off on the same truths (closed_loop_adapt_off/on.json)."""
    off, on = _load("closed_loop_adapt_off.json"), _load("closed_loop_adapt_on.json")
    lines = [f"*`python bench/bench_closed_loop.py --modes whole_route --adapt N` on "
             f"{', '.join(on['scenarios'])}, both costs, {on['samples']} truths each ({on['date']}; the same truths "
             f"in both: the draw does not depend on the run settings).*", "",
             "| run.adapt_periods | runs | reached (crossable) | stopped / no path / failed | re-plans, median | "
             "executed / own plan, median (p90) | executed / prediction, median (p90) |", "|---|---|---|---|---|---|---|"]
    for d in (off, on):
        t = d["totals"]
        e = t["ends"]
        lines.append(f"| {d.get('adapt_periods', 0)} | {t['runs']} | {e.get('reached', 0)} "
                     f"({t['p_reach_crossable']:.2f}) | {e.get('stopped', 0)} / {e.get('no_path', 0)} / "
                     f"{e.get('failed', 0)} | {t.get('replans_median', '-')} | {_ratio(t['over_own_plan'])} | "
                     f"{_ratio(t.get('over_prediction'))} |")
    return "\n".join(lines)


BLOCKS = {"closed-loop-table": closed_loop_table, "closed-loop-totals": closed_loop_totals,
          "closed-loop-before": lambda: closed_loop_totals("closed_loop_before.json"),
          "closed-loop-maps": lambda: closed_loop_totals("closed_loop_maps.json"),
          "closed-loop-adapt": closed_loop_adapt,
          "readme-closed-loop": readme_closed_loop}


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
