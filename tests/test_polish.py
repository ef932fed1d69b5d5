"""The polish of a found plan (sbmpc.planning.polish): a local search over its controls that
never makes a plan dearer, keeps the wheel speeds in the sampled range, reproduces its
own cost when replayed, and, judged at the controller rate, makes energy plans cheaper."""
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dynamics import kernels as K
from sbmpc.planning import check as CK, plan as PL, problem as PB, repair as RP
from sbmpc.problems import skidsteer as SS
from sbmpc.planning import polish as PO
from sbmpc import scenario as SC
from sbmpc.planning import world as WO

SCEN = Path(__file__).resolve().parents[1] / "scenarios"


def _world(seed=0, **planner):
    scn = SC.load(SCEN / "flat.yaml")
    return WO.resolve(replace(scn, planner=replace(scn.planner, seed=seed, **planner)))


@pytest.fixture(scope="module")
def flat():
    w = _world()
    return w, PB.problem(w, "energy")


def _replayed_cost(world, cost, controls):
    """Cost of controls replayed by check.replay at the planner's step (goal entry ends it)."""
    traj, end, S, used = CK.replay(world, cost, controls)
    assert end == SS.IN_GOAL and used == len(controls)
    return float(S[K.S_E] if cost == "energy" else S[K.S_T])


# a straight-ish start: controls that reach the goal of flat.yaml (16, 9) from (2, 2) facing east
BASE = [(2.0, 8.0, 1.0)] + [(8.0, 8.0, 1.0)] * 20


def test_polish_lowers_the_cost_and_its_result_replays_to_it(flat):
    world, prob = flat
    lo, hi = WO.wheel_speed_range(world)
    before = PO.polish(prob.params, prob.data, prob.start, BASE, lo, hi, deadline=0.0)   # no time: no moves
    assert before is not None and before.trials == 0 and before.cost == before.cost_before
    pol = PO.polish(prob.params, prob.data, prob.start, BASE, lo, hi)
    assert pol.cost_before == pytest.approx(_replayed_cost(world, "energy", before.controls), abs=1e-9)
    # the polished controls, replayed independently, cost what the polish says, and less
    assert _replayed_cost(world, "energy", pol.controls) == pytest.approx(pol.cost, abs=1e-9)
    assert pol.cost < 0.97 * pol.cost_before
    c = np.array(pol.controls)
    assert np.all((c[:, :2] >= lo - 1e-12) & (c[:, :2] <= hi + 1e-12))
    assert np.all(c[:-1, 2] == world.scenario.planner.period_s) and 0 < c[-1, 2] <= 2 * world.scenario.planner.period_s


def test_polish_of_controls_that_miss_the_goal_is_none(flat):
    world, prob = flat
    lo, hi = WO.wheel_speed_range(world)
    assert PO.polish(prob.params, prob.data, prob.start, BASE[:5], lo, hi) is None


@pytest.mark.slow      # 12 random detours, 9 s: CI runs it, the quick loop keeps the fixed cases
@settings(max_examples=12, deadline=None)
@given(st.lists(st.tuples(st.floats(-0.3, 0.3), st.floats(-0.3, 0.3)), min_size=3, max_size=3),
       st.sampled_from(["time", "energy"]))
def test_polish_never_makes_a_plan_dearer(flat, noise, cost):
    """Random detours of the base sequence: the polish ends no dearer than it started, in
    range, and its cost is the independent replay's."""
    world, _ = flat
    prob = PB.problem(world, cost)
    lo, hi = WO.wheel_speed_range(world)
    ctrl = [(wl * (1 + a), wr * (1 + b), d) for (wl, wr, d), (a, b) in zip(BASE, noise + [(0, 0)] * len(BASE))]
    ctrl = [(min(max(wl, lo), hi), min(max(wr, lo), hi), d) for wl, wr, d in ctrl]
    pol = PO.polish(prob.params, prob.data, prob.start, ctrl, lo, hi, deadline=None)
    if pol is None:        # no trial near this detour reaches the goal
        return
    if pol.cost_before is not None:
        assert pol.cost <= pol.cost_before
    assert _replayed_cost(world, cost, pol.controls) == pytest.approx(pol.cost, abs=1e-9)


def test_a_long_plans_polish_moves_its_head_and_tail_only(flat, monkeypatch):
    """Over EXACT_UP_TO controls the moves go to the first HEAD and last TAIL controls
    (a move at i changes i and i + 1): the middle stays as given, the result is no dearer
    and replays to its cost; polished at every control, the same plan's middle moves."""
    world, prob = flat
    lo, hi = WO.wheel_speed_range(world)
    monkeypatch.setattr(PO, "EXACT_UP_TO", 10)
    monkeypatch.setattr(PO, "HEAD", 2)
    monkeypatch.setattr(PO, "TAIL", 5)
    base = np.array(BASE)
    pol = PO.polish(prob.params, prob.data, prob.start, BASE, lo, hi)
    c = np.array(pol.controls)
    mid = slice(PO.HEAD + 1, len(c) - PO.TAIL)
    assert len(c) - PO.TAIL - PO.HEAD - 1 >= 8
    assert np.array_equal(c[mid, :2], base[mid, :2])
    assert pol.cost < pol.cost_before
    assert _replayed_cost(world, "energy", pol.controls) == pytest.approx(pol.cost, abs=1e-9)
    full = np.array(PO.polish(prob.params, prob.data, prob.start, BASE, lo, hi, every=True).controls)
    fmid = slice(PO.HEAD + 1, len(full) - PO.TAIL)
    assert fmid.stop - fmid.start >= 8
    assert not np.array_equal(full[fmid, :2], base[fmid, :2])


@pytest.mark.slow      # hills_field searched twice (10 s); test_plan's repair test keeps the repairs in the quick loop
def test_a_long_plans_polish_moves_what_its_repairs_leave_standing(monkeypatch):
    """A plan of more than EXACT_UP_TO controls is checked at 1 kHz and repaired first,
    and then polished from where its last re-plan starts, from the 1 kHz state there
    (repair.polished_standing): polished first, its polish was replaced by the repairs
    (on 170 and 340 m fields, kept on one plan of six; now on six). hills_field's energy
    search with a weight of 3 parts from its 1 kHz drive (test_plan's repair test);
    with EXACT_UP_TO at 10 its plan counts as long. The polish starts at the 1 kHz state
    after the repaired plan's controls before the last re-plan, which stay as they are;
    the plan replays to its cost and is cheaper than the repaired plan unpolished."""
    scn = SC.load(SCEN / "hills_field.yaml")
    # (guided by the grid alone, value off, as test_plan's repair test: the search whose
    # plan parts from its 1 kHz drive)
    planner = dict(energy_weight=3.0, margin=0.0, margin_tip_deg=0.0, value=False)
    world = WO.resolve(replace(scn, planner=replace(scn.planner, **planner)))
    bare = WO.resolve(replace(scn, planner=replace(scn.planner, polish_energy=False, **planner)))
    monkeypatch.setattr(PO, "EXACT_UP_TO", 10)
    plain = PL.search_plan(bare, "energy")
    assert plain.found and plain.repairs >= 1 and len(plain.controls) > 10
    X0 = PL._start(world, None)
    calls, real = [], RP.polish

    def spy(params, data, start, controls, *a, **k):
        calls.append((start.copy(), [tuple(c) for c in controls], k.get("every", a[3] if len(a) > 3 else None)))
        return real(params, data, start, controls, *a, **k)

    monkeypatch.setattr(RP, "polish", spy)
    p = PL.search_plan(world, "energy")
    assert p.found and calls
    start, given, every = calls[0]
    j = len(plain.controls) - len(given)
    assert 0 < j and given == [tuple(c) for c in plain.controls[j:]] and every is False
    there = CK.fine_state(world, "energy", plain.controls[:j], X0)
    np.testing.assert_allclose(start[:K.NS], there[:K.NS], atol=1e-9)
    # the margin's twin starts from the vehicle's state there, not from where the route began
    np.testing.assert_allclose(start[SS.X_TW:SS.X_TW + K.NS], there[:K.NS], atol=1e-9)
    assert [tuple(c) for c in p.controls[:j]] == [tuple(c) for c in plain.controls[:j]]
    chk = CK.controller_rate(world, "energy", p.controls, X0)[0]
    assert chk.reached and chk.energy_J == pytest.approx(p.energy_J, rel=1e-9)
    assert p.polish is not None and p.energy_J < plain.energy_J      # 5 799 J against 5 867 J


def test_polished_energy_plans_are_cheaper_at_the_controller_rate():
    """flat.yaml's energy plans for Halton seeds 0-3, driven at 1 kHz: the polish makes
    each cheaper than the search's own plan, the median by at least 1 % (1.8 % measured
    since the grid read at each pose's own cell corners made the searched plans
    cheaper; 2-3 % before). (It does not
    bring every seed to one optimum: a local search ends in the basin it starts in, so
    the spread over seeds stays a few per cent: docs/planner.md.)"""
    on, off = [], []
    for seed in range(4):
        p = PL.search_plan(_world(seed), "energy")
        q = PL.search_plan(_world(seed, polish_energy=False), "energy")
        assert p.found and q.found and p.check.reached and p.check.miss_m == 0.0
        assert p.polish is not None and q.polish is None
        assert p.energy_J < q.energy_J
        on.append(p.energy_J)
        off.append(q.energy_J)
    assert np.median(on) < 0.99 * np.median(off)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-4.0, 8.7), st.floats(-4.0, 8.7)), min_size=3, max_size=6),
       st.integers(0, 5), st.sampled_from(PO.STEPS))
def test_moves_stay_in_range_and_a_moved_turn_keeps_the_heading(ws, i, s):
    """Every trial keeps both controls' wheel speeds within [lo, hi]; the moves that shift
    a turn between controls i and i + 1 keep their summed wheel-speed difference (the
    heading change after both, on level ground), and those that shift speed their summed
    wheel speeds (the distance), where no clipping intervened."""
    lo, hi = -4.0, 8.7
    ctrl = np.array([(a, b, 1.0) for a, b in ws])
    i = min(i, len(ctrl) - 1)
    moves = PO._moves(ctrl, i, s, hi, lo, hi)
    assert np.all((moves >= lo) & (moves <= hi))
    if i + 2 >= len(ctrl):
        return
    d = s * hi
    turn = (ctrl[i, 1] - ctrl[i, 0]) + (ctrl[i + 1, 1] - ctrl[i + 1, 0])
    wl, wr, nl, nr = ctrl[i, 0], ctrl[i, 1], ctrl[i + 1, 0], ctrl[i + 1, 1]
    shifted = [m for m in moves if np.allclose(m, (wl + d, wr - d, nl - d, nr + d))
               or np.allclose(m, (wl - d, wr + d, nl + d, nr - d))]
    unclipped = all(lo <= x <= hi for x in (wl + d, wr - d, nl - d, nr + d, wl - d, wr + d, nl + d, nr - d))
    if unclipped:
        assert len(shifted) == 2
    for m in shifted:
        assert (m[1] - m[0]) + (m[3] - m[2]) == pytest.approx(turn, abs=1e-9)
    # the moves that shift speed between the two keep their summed wheel speeds (distance)
    speed = [m for m in moves if np.allclose(m, (wl + d, wr + d, nl - d, nr - d))
             or np.allclose(m, (wl - d, wr - d, nl + d, nr + d))]
    if unclipped:
        assert len(speed) == 2
    for m in speed:
        assert m.sum() == pytest.approx(wl + wr + nl + nr, abs=1e-9)


def test_a_polish_that_misses_the_goal_at_1khz_is_repaired_and_kept_when_cheaper(monkeypatch):
    """A long plan's 20 ms line drifts from the 1 kHz one, so a polish can miss the goal
    at the controller rate (hills_field seed 0: 0.7 m). Such a polish is repaired like a
    searched plan (re-planned from where its 1 kHz drive failed, here its last control)
    and is the plan when it then reaches the goal for less than the search's own. Here
    the 'polish' is flat's polished plan without its last two controls: it stops about
    a metre short; repaired, it reaches the disc (checked by an independent 1 kHz
    replay) for less than the unpolished plan. A 'polish' that spins on the spot on the
    way and misses too is repaired as well, but dearer: the searched plan stands."""
    w = _world(0, hold=False)         # the searched plan of this case (before held controls)
    p = PL.search_plan(w, "energy")
    q = PL.search_plan(_world(0, polish_energy=False, hold=False), "energy")
    X0 = PL._start(w, None)
    short = [tuple(c) for c in p.controls[:-2]]
    assert not CK.controller_rate(w, "energy", short, X0)[0].reached
    fake = PO.Polished(short, 0.0, None, 0, 0.0)
    monkeypatch.setattr(PL, "polished", lambda *a, **k: (None, None, (fake, None)))
    r = PL.search_plan(w, "energy")
    assert r.found and r.polish is fake and r.repairs >= 1
    n = len(short) - RP.APPROACH_CONTROLS
    assert r.controls[:n] == short[:n]
    chk = CK.controller_rate(w, "energy", r.controls, X0)[0]
    assert chk.reached and chk.miss_m == 0.0
    assert CK.check_cost(chk, "energy") == pytest.approx(r.energy_J, rel=1e-9)
    assert r.energy_J < q.energy_J
    spin = [tuple(c) for c in q.controls[:3]] + [(-8.0, 8.0, 1.0), (8.0, -8.0, 1.0)] + [tuple(c) for c in q.controls[3:-2]]
    assert not CK.controller_rate(w, "energy", spin, X0)[0].reached
    fake2 = PO.Polished(spin, 0.0, None, 0, 0.0)
    monkeypatch.setattr(PL, "polished", lambda *a, **k: (None, None, (fake2, None)))
    r2 = PL.search_plan(w, "energy")
    assert r2.found and r2.polish is None and r2.controls == q.controls and r2.energy_J == q.energy_J


def test_a_polish_that_parts_from_its_line_at_1khz_is_polished_once(monkeypatch):
    """A polish aimed 10 cm inside the goal disc whose controls miss at 1 kHz (not a
    tip-over) goes to the repair as it is: a polish aimed at the disc itself parts no
    less (a 340 m field's energy plan spent 2.6 s on that second polish, never kept)."""
    w = _world(0, hold=False)
    p = PL.search_plan(w, "energy")
    X0 = PL._start(w, None)
    short = [tuple(c) for c in p.controls[:-2]]
    drive = CK.controller_rate(w, "energy", short, X0)
    assert not drive[0].reached and drive[0].end != -SS.TIP
    fake = PO.Polished(short, 1.0, 2.0, 0, 0.0)
    calls = []
    monkeypatch.setattr(RP, "polish", lambda params, *a, **k: calls.append(params[SS.Q_GR]) or fake)
    pol, searched, missed = RP.polished(w, "energy", PB.problem(w, "energy"), X0, p.controls, float("inf"))
    assert pol is None and missed[0] is fake and not missed[1][0].reached
    r = w.scenario.goal["radius"]
    assert calls == [pytest.approx(r - min(RP.POLISH_GOAL_MARGIN, 0.5 * r))]


def test_a_polish_that_only_passes_the_disc_at_1khz_is_polished_once(monkeypatch):
    """A polish aimed 10 cm inside the goal disc whose 1 kHz drive passes outside the disc
    (within the open-loop drift allowance) where the searched controls enter it goes to
    the repair as it is, with no second polish aimed at the disc itself: that one passes
    no closer (a 170 m field's energy plan: the first passed 0.38 m outside, the second
    0.41 m, 2.3 s of 6.2). Here the 1 kHz check is told that the 'polish' passes 0.3 m
    outside."""
    w = _world(0, hold=False)
    p = PL.search_plan(w, "energy")
    X0 = PL._start(w, None)
    fake = PO.Polished([tuple(c) for c in p.controls], 1.0, 2.0, 0, 0.0)
    calls = []
    monkeypatch.setattr(RP, "polish", lambda params, *a, **k: calls.append(params[SS.Q_GR]) or fake)
    real = RP.controller_rate

    def rate(world, cost, controls, X0, **k):
        chk, fine, kept = real(world, cost, controls, X0, **k)
        if controls is fake.controls:
            assert chk.reached and chk.miss_m == 0.0 and chk.drift_m > 0.05
            chk = replace(chk, miss_m=0.05)
        return chk, fine, kept

    monkeypatch.setattr(RP, "controller_rate", rate)
    pol, searched, missed = RP.polished(w, "energy", PB.problem(w, "energy"), X0, p.controls, float("inf"))
    assert pol is None and missed[0] is fake and missed[1][0].miss_m == 0.05
    assert searched[0].reached and searched[0].miss_m == 0.0
    r = w.scenario.goal["radius"]
    assert calls == [pytest.approx(r - min(RP.POLISH_GOAL_MARGIN, 0.5 * r))]


def test_the_polish_runs_on_the_planners_threads(monkeypatch):
    """``planner.threads: 1`` plans on one core, the polish's trials included (they ran
    on every core before, so that a 'one core' planning time used two); numba's thread
    count is restored after."""
    import numba
    seen = []
    real = RP.polish

    def spy(*a, **k):
        seen.append(numba.get_num_threads())
        return real(*a, **k)

    monkeypatch.setattr(RP, "polish", spy)
    out = []

    def plans():
        # in a fresh thread (numba's count is per thread, every thread numba has at first):
        # after some other tests in the same process the main thread's count was 1
        # (2026-12-06, not traced)
        before = numba.get_num_threads()
        for threads in (1, 0):
            p = PL.search_plan(_world(threads=threads), "energy")
            out.append((p.found and p.polish is not None, numba.get_num_threads() == before))
    import threading
    t = threading.Thread(target=plans)
    t.start()
    t.join()
    assert out == [(True, True), (True, True)]
    assert seen[0] == 1 and seen[-1] == numba.config.NUMBA_NUM_THREADS


def test_a_polish_that_tips_over_at_1khz_is_polished_again_within_a_margin(monkeypatch, tmp_path):
    """The polish presses a path against the tip-over limit where that pays (the flanks
    of narrow_pass's pass); the 1 kHz drive, a few centimetres off the 20 ms line, then
    tips (four of narrow_pass's eight seeds did). Such a polish is redone from the
    searched controls with the limit lowered by POLISH_TIP_MARGIN_DEG, and that one is
    kept when it holds at 1 kHz. Here flat.yaml's floor with a steep ridge beside the
    start: the 'first polish' drives straight east along its flank and tips at 1 kHz; the
    second, the real polish of the time plan's controls for energy, must run with the
    limit lowered, reach the goal at 1 kHz and cost less energy there than the time plan."""
    text = (SCEN / "flat.yaml").read_text().replace(
        "features: []", "features: [{type: ridge, x0: 6, y0: 0.9, x1: 14, y1: 0.9, height: 2.0, width: 3.0}]")
    (tmp_path / "walled.yaml").write_text(text)
    w = WO.resolve(SC.load(tmp_path / "walled.yaml"))
    q = PL.plan(w, "time")
    assert q.found
    X0 = PL._start(w, None)
    top = WO.wheel_speed_range(w)[1]
    over = [(top, top, 1.0)] * 18
    chk = CK.controller_rate(w, "energy", over, X0)[0]
    assert not chk.reached and chk.reason.startswith("the vehicle tipped over")
    limits = []
    real = RP.polish

    def spy(params, *a, **k):
        limits.append(float(np.degrees(params[SS.Q_TIP])))
        if len(limits) == 1:
            return PO.Polished(over, 1.0, 2.0, 0, 0.0)
        return real(params, *a, **k)

    monkeypatch.setattr(RP, "polish", spy)
    prob = PB.problem(w, "energy", X0)
    pol, drive, missed = RP.polished(w, "energy", prob, X0, [tuple(c) for c in q.controls], np.inf)
    tip = w.scenario.planner.tip_over_deg
    assert limits[0] == pytest.approx(tip) and limits[1] == pytest.approx(tip - RP.POLISH_TIP_MARGIN_DEG)
    assert pol is not None and pol.controls != over and missed is None
    new = CK.controller_rate(w, "energy", pol.controls, X0)[0]
    assert new.reached and drive[0].energy_J == new.energy_J
    assert new.energy_J < q.energy_J
    # the second polish tips over too: nothing is polished, and the second is handed
    # back to be repaired (plan._checked); past the deadline, no second polish
    lat = [(top, top, 1.0)] * 17
    monkeypatch.setattr(RP, "polish", lambda params, *a, **k: PO.Polished(
        over if params[SS.Q_TIP] == pytest.approx(np.radians(tip)) else lat, 1.0, 2.0, 0, 0.0))
    pol, drive, missed = RP.polished(w, "energy", prob, X0, [tuple(c) for c in q.controls], np.inf)
    assert pol is None and drive is None and missed[0].controls == lat
    assert missed[1][0].reason.startswith("the vehicle tipped over")
    limits.clear()
    monkeypatch.setattr(RP, "polish", spy)
    pol, drive, missed = RP.polished(w, "energy", prob, X0, [tuple(c) for c in q.controls], 0.0)
    assert len(limits) == 1 and pol is None and missed[0].controls == over
