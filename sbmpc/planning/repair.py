"""A searched plan made to hold at the controller rate: its polish judged at 1 kHz
(:func:`polished`), its repair by re-planning from where the 1 kHz drive parted from
the search's prediction (:func:`checked`), and which of two checked plans is better
(:func:`better`). :func:`sbmpc.planning.plan.search_plan` runs them in that order, but for
a long plan (more than polish.EXACT_UP_TO controls), which is checked and repaired first
and then polished from where its last re-plan starts (:func:`polished_standing`)."""
from __future__ import annotations

import math
import time

import numpy as np

from dynamics import kernels as K

from .check import Check, boundaries, check_cost, controller_rate, fine_state, parting, predicted
from .heuristics import unreachable_reason
from .polish import polish
from .problem import batch_size, problem, search_threads
from ..problems import skidsteer as SS
from ..search.astar import Problem, Search, numba_threads
from .world import World, _start, wheel_speed_range

MAX_REPAIRS = 6      # re-plans from a parted controller-rate state before a plan is given up
POLISH_GOAL_MARGIN = 0.1   # m (at most half the goal radius): the polish aims this far inside the goal disc
POLISH_TIP_MARGIN_DEG = 3.0   # deg: the tip-over limit lowered by this for a second polish (polished)
APPROACH_CONTROLS = 3   # a plan that only passes the goal within the drift allowance is
APPROACH_SLACK = 0.05   # re-planned from this many controls before its end (or from where
                        # it parted) and the result kept when it enters the goal disc at
                        # 1 kHz for at most 5 % more cost



def better(new: Check, old: Check, cost: str) -> bool:
    """Whether a plan checked ``new`` at the controller rate beats one checked ``old``:
    reaching the goal beats not reaching it; entering the disc beats passing it within
    the drift allowance for up to APPROACH_SLACK more cost (as the last approach's
    re-plan is judged in :func:`checked`); else the one that misses by no more and
    costs less."""
    if not new.reached:
        return False
    if not old.reached:
        return True
    c_new, c_old = check_cost(new, cost), check_cost(old, cost)
    if new.miss_m == 0.0 and old.miss_m > 0.0:
        return c_new <= (1.0 + APPROACH_SLACK) * c_old
    return new.miss_m <= old.miss_m and c_new < c_old


def polished(world: World, cost: str, prob: Problem, X0: np.ndarray, controls, deadline: float,
              threads: int | None = None, every: bool | None = None):
    """(polish, drive, missed): the polish of searched ``controls`` (:mod:`sbmpc.planning.polish`)
    and the controller-rate drive (:func:`sbmpc.planning.check.controller_rate`'s result, for
    :func:`checked`) of the controls that stand: the polish's, or, where the polish is
    None, the searched ones' when they were driven to judge it (else None). The polish
    is None when it gained nothing, or when its controls, driven at the controller rate,
    do not reach the goal (or only pass it where the searched ones entered it) or cost
    more there than the searched ones: the polish is judged where every plan is. ``missed``: (polish, drive) when the drive
    misses the goal (or only passes it) at the controller rate, for :func:`sbmpc.planning.plan.search_plan` to
    repair (a long plan's 20 ms line drifts from the 1 kHz one). The polish aims at the goal
    disc less POLISH_GOAL_MARGIN (or, where no trial reaches that, none gains there or it
    is no cheaper at the controller rate, the disc; not where its controls miss at the
    controller rate other than by tipping over, or only pass the disc there where the
    searched ones entered it: aimed at the disc they miss no less, and they go to the
    repair as they are): a cheapest
    path only grazes its target, and a plan that grazes the disc at the planner's step
    may pass just outside it at 1 kHz. Where the polished controls tip the vehicle over
    at 1 kHz, they are polished again from the searched ones with the tip-over limit
    lowered by POLISH_TIP_MARGIN_DEG: the polish presses a path against the limit (the
    flanks of narrow_pass's pass), where the 1 kHz drive, a few centimetres off the
    20 ms line, tips (four of narrow_pass's eight seeds did). ``threads``: numba's
    threads for the polish's trials (None: planner.threads; search_plan passes 1 where
    the search's threads "auto" measured one thread faster: cores busy elsewhere).
    ``every``: polish.polish's (None: by the number of controls)."""
    lo, hi = wheel_speed_range(world)
    r = world.scenario.goal["radius"]
    missed = None
    searched = None
    for margin in (min(POLISH_GOAL_MARGIN, 0.5 * r), 0.0):     # no margin: where none reaches it or gains
        if margin == 0.0 and time.perf_counter() > deadline:
            break
        for tip_margin in (0.0, math.radians(POLISH_TIP_MARGIN_DEG)):
            params = prob.params.copy()
            params[SS.Q_TIP] -= tip_margin
            params[SS.Q_GR] = r - margin
            # the polish's trials: on planner.threads, or one where the search found one faster (threads auto)
            with numba_threads(threads or world.scenario.planner.threads or None):
                pol = polish(params, prob.data, X0, controls, lo, hi, deadline, every)
            if pol is None or pol.gain <= 0.0:
                break                                  # nothing gained at this margin
            drive = controller_rate(world, cost, pol.controls, X0)
            new = drive[0]
            if not new.reached:
                missed = (pol, drive)
                if new.end != -SS.TIP:
                    # parted from its line at 1 kHz (stalled, or passed outside the disc):
                    # a polish aimed at the disc itself parts no less; the repair takes it
                    return None, searched, missed
                if time.perf_counter() > deadline:
                    break
                continue                               # tipped at 1 kHz: again, further from the limit
            if searched is None:
                searched = controller_rate(world, cost, controls, X0)
            old = searched[0]
            if new.miss_m > 0.0 and old.reached and old.miss_m == 0.0:
                # only passes the disc where the searched entered it: aimed at the disc
                # itself it passes no closer; the repair takes it
                return None, searched, missed or (pol, drive)
            if old.reached and check_cost(old, cost) <= check_cost(new, cost):
                break                                  # no cheaper at 1 kHz (aimed inside the disc, a detour)
            return pol, drive, None
    return None, searched, missed


_OUT_OF_BUDGET = object()


def _replanned(world: World, cost: str, prefix, X0: np.ndarray, dt: float, left: float, ps):
    """The re-plan of :func:`checked` after the controls ``prefix`` driven at the controller
    rate from X0, searched at step ``dt`` within ``left`` seconds: (tail controls, the
    search's poses (x, y, yaw) at their boundaries, the state after ``prefix``, whether a
    search ran, whether the result is the same whatever the budget: not where a search
    that refines its plan, planner.refine, was cut by the clock); (None, None, state,
    whether a search ran, True) where there is no way on from there (stalled, on ground
    no path leaves, or the search exhausted every state it could reach); _OUT_OF_BUDGET
    where a budget ran out first."""
    Sj = fine_state(world, cost, prefix, X0)
    if Sj[K.S_STALLED] != 0.0 or unreachable_reason(world, (float(Sj[K.S_X]), float(Sj[K.S_Y]))) is not None:
        return None, None, Sj, False, True
    prob = problem(world, cost, Sj, dt)
    res = Search(prob).run(ps.max_expansions, left, batch=batch_size(ps), threads=search_threads(ps))
    if res.status != "found":
        return (None, None, Sj, True, True) if res.exhausted else _OUT_OF_BUDGET
    T = res.states[:, K.S_T]
    tail = [(float(prob.controls[c, 0]), float(prob.controls[c, 1]), round(float(T[i + 1] - T[i]), 9))
            for i, c in enumerate(res.control_rows)]
    # a search cut by its time budget (an anytime refinement's best so far) depends on the clock
    return tail, res.states[:, [K.S_X, K.S_Y, K.S_YAW]], Sj, True, res.planning_time_s < left


def checked(world: World, cost: str, controls, pred: np.ndarray, X0: np.ndarray, t0: float,
             budget: float, ps, drive=None, memo: dict | None = None) -> tuple:
    """Check searched controls at the controller rate. Where the check fails, re-plan
    from the controller-rate state and splice, up to MAX_REPAIRS times within the time
    budget: from the first control where the replay parted from the search's prediction
    ``pred`` (poses at the control boundaries: the search's model drifted from the vehicle's there), or, where it never
    parted but an edge failed at 1 kHz that passed at the search's step, from that
    edge's start with the search's step halved (that edge was not converged). Where the
    re-plan finds no way on from there (a dead end: every edge tips or stalls), the next
    one starts 2, 4, 8 ... controls further back. A replay
    that only passes within the drift allowance of the goal disc gets its last approach
    planned from where it passed closest, so that the plan enters the disc (a receding-
    horizon run executes exactly that); if that fails the allowance stands. Returns
    (controls as driven, Check, the controller-rate trajectory, re-plans made (one taken
    from ``memo`` counts as made), (j, state):
    the control where the last re-plan spliced in starts and the controller-rate state
    there, or None without one). ``drive``:
    the controls' drive at the controller rate when it is known already (the polish's).
    ``memo``: a dict shared by the checks of one search's plans from X0 (the searched
    controls and their polish): a re-plan after the same controls is made once (a polish
    that changed only controls past where the plan parts gets the searched plan's repairs).
    A repaired plan is replayed at the controller rate from where it parted."""
    rate = world.vehicle.controller_rate
    chk, fine, kept = drive if drive is not None else controller_rate(world, cost, controls, X0)
    repairs = 0
    dt = ps.dt
    back = 0          # controls to step back from where the check failed (a dead end there)
    at = None         # (j, state): where the last re-plan kept starts, the state there
    while repairs < MAX_REPAIRS and not (chk.reached and chk.miss_m == 0.0):
        left = budget - (time.perf_counter() - t0)
        if left <= 0:
            break
        j, parted = parting(pred, controls, fine, rate)
        if chk.reached:
            # the last approach: from where the replay parted, else a few controls back
            if not parted:
                j = max(0, len(kept) - APPROACH_CONTROLS)
        elif not parted and back == 0:
            dt = max(dt / 2.0, 1.0 / rate)
        j = max(0, j - back)
        key = (tuple(tuple(c) for c in controls[:j]), dt)
        step = memo.get(key) if memo is not None else None
        if step is None:
            step = _replanned(world, cost, controls[:j], X0, dt, left, ps)
            if step is _OUT_OF_BUDGET:
                break
            if memo is not None and step[4]:
                memo[key] = step
        repairs += step[3]
        if step[0] is None:
            if chk.reached or j == 0:
                break
            # no way on from there (the vehicle already on a flank it tips over from at
            # every control, or stalled): re-plan from further back, 2, 4, 8 ... controls
            back = max(2, 2 * back)
            continue
        back = 0
        tail, poses, Sj = step[:3]
        new = [tuple(c) for c in controls[:j]] + tail
        chk2, fine2, kept2 = controller_rate(world, cost, new, X0, known=(j, fine, Sj))
        if chk.reached and not (chk2.reached and chk2.miss_m < chk.miss_m
                                and check_cost(chk2, cost) <= (1.0 + APPROACH_SLACK) * check_cost(chk, cost)):
            break                              # the approach did not help: keep the allowance
        controls, pred = new, np.vstack([pred[:j], poses])
        chk, fine, kept = chk2, fine2, kept2
        at = (j, Sj)
    return kept, chk, fine, repairs, at


def polished_standing(world: World, cost: str, prob: Problem, X0: np.ndarray, checked_plan: tuple,
                      deadline: float, t0: float, budget: float, ps, threads: int | None = None,
                      memo: dict | None = None) -> tuple:
    """The polish of a long plan (more than polish.EXACT_UP_TO controls) after its check:
    what the repairs leave standing. ``checked_plan`` is :func:`checked`'s result for the
    searched controls; the polish (:func:`polished`, at the first polish.HEAD and last
    polish.TAIL controls) moves the controls from where the last re-plan spliced in
    starts (all of them where none was), driven from the controller-rate state there,
    whose 20 ms line is the search's own. Polished before
    the check, a long plan's polish was undone by the repairs: its 20 ms line parts from
    the 1 kHz drive within 30-60 m, and every re-plan from there replaces the rest (the
    polish of three 340 m field plans, 2.4-3.3 s each, was kept on none).
    Returns ``checked_plan`` with the polished controls where, driven at the controller
    rate from the start, they do better (:func:`better`: they reach the goal for less, or
    enter the disc the checked plan only passes for at most APPROACH_SLACK more; a polish
    that parts from its line there is repaired first, :func:`checked`, sharing ``memo``),
    and the polish (None where none was kept)."""
    kept, chk, fine, repairs, at = checked_plan
    if not chk.reached or time.perf_counter() > deadline:
        return checked_plan, None
    j, Sj = at if at is not None else (0, X0)
    head = [tuple(c) for c in kept[:j]]
    # the margin's twin starts from the vehicle's state there (fine_state replays without it)
    pol, drive, missed = polished(world, cost, prob, _start(world, Sj), kept[j:], deadline, threads, every=False)
    if pol is not None:
        new = head + list(pol.controls)
        c2, f2, k2 = controller_rate(world, cost, new, X0, known=(j, fine, Sj))
        if better(c2, chk, cost):
            return (k2, c2, f2, repairs, at), pol
        return checked_plan, None
    if missed is None or time.perf_counter() - t0 > budget:
        return checked_plan, None
    mpol = missed[0]
    new = head + list(mpol.controls)
    # the prefix as driven at 1 kHz (it does not part from itself), the polished rest as predicted from there
    n_f = boundaries(head, 1.0 / world.vehicle.controller_rate)
    pre = np.column_stack([fine["x"][n_f], fine["y"][n_f], fine["yaw"][n_f]])
    pred = np.vstack([pre[:-1], predicted(world, cost, mpol.controls, Sj)]) if j else predicted(world, cost, new, X0)
    out = checked(world, cost, new, pred, X0, t0, budget, ps, controller_rate(world, cost, new, X0, known=(j, fine, Sj)),
                  memo)
    if better(out[1], chk, cost):
        return (out[0], out[1], out[2], repairs + out[3], out[4] or at), mpol
    return checked_plan, None
