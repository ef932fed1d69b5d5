"""Polish a found plan: a local search over its control sequence.

The search picks every control from the few wheel-speed pairs it samples at a node
(``planner.branching``, from a seeded Halton sequence) and merges nearby states on its
grid, so its plan is the best *over those samples*: two seeds give two sample sets and,
for the energy cost, plans whose speed profiles differ by several per cent. The polish
moves the plan towards the continuous optimum nearby: a compass (pattern) search over
the sequence, each trial driven through the same closed-loop model at the planner's
step from the state where it changes, to the goal.

At each control i, in order, it tries these moves (each a trial sequence, simulated in
parallel over numba's threads):

* both wheel speeds scaled by 1 + s and by 1 - s (faster or slower);
* the turn changed: s x the top speed added to one wheel and taken from the other;
* controls i and i + 1 swapped (a turn earlier or later), and both replaced by their
  mean (a turn spread over two periods);
* s x the top speed of turn moved from control i + 1 to control i or back (the heading
  after both kept: a turn that migrates a little earlier or later, where a swap would
  move the path's end out of the goal), and s x the top speed added to both wheels of
  control i and taken from both of control i + 1, or back (speed moved between them,
  the distance kept); none of these keeps heading and distance where a wheel speed is
  clipped to the range;

and keeps the best trial when it reaches the goal disc for less than the plan's cost
(time or energy); the last control is held longer or cut where the vehicle enters the
disc. Sweeps over the sequence repeat until one improves nothing (at most
``MAX_SWEEPS``), for s = 0.1, 0.03 and 0.01 of the top speed in turn. A trial whose cost
already reaches the best on the way is cut there (time and energy never decrease along a
drive). Every wheel speed stays within the range the search samples. The result depends
only on the plan and the model, never on the clock (the time budget only stops it early).

A plan of more than EXACT_UP_TO controls (a route of a few hundred metres) gets its moves
at its first HEAD and last TAIL controls only. Each trial is driven to the goal, so a
sweep over every control costs the square of the plan's length; over these it grows
linearly (the head's trials) plus a constant (the tail's). Little is lost: a control
changed mid-route moves the whole rest of the open-loop path, and after a hundred
metres that misses the goal disc, so nearly every mid-route trial fails. Measured on a
170 m field's energy plan (143 controls, one core, ``bench/bench_route.py``'s field): every
control 1.21 % cheaper in 23.4 s, head and tail (2, 40) 1.04 % in 2.3-3.0 s (3 and 30: 0.80 %
in 1.7 s); driven at 1 kHz the head-and-tail plan was the cheaper (6 073 J against
6 077 J). Such a polish makes at most HEAD_TAIL_SWEEPS sweeps per move size: on the
same plan, 0.94 % in 1.2 s with two, 1.04 % in 2.5 s with four. A planned long plan is
polished after its check at the controller rate, from where its last re-plan starts
(:func:`sbmpc.planning.repair.polished_standing`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from dynamics import kernels as K

from ..problems import skidsteer as SS

STEPS = (0.1, 0.03, 0.01)   # move sizes, x the top of the sampled wheel-speed range
MAX_SWEEPS = 4              # sweeps over the sequence per move size
HEAD_TAIL_SWEEPS = 2        # the same where only the head and tail are moved (module doc)
MIN_GAIN = 1e-6             # relative: smaller improvements are not taken
HEAD, TAIL = 2, 40                 # controls: where a long plan's moves are tried (module doc)
EXACT_UP_TO = 100           # controls: plans up to this long get moves at every control


@dataclass(frozen=True)
class Polished:
    """The result of :func:`polish`: controls [(wl, wr, duration_s)], their cost at the
    planner's step, the given controls' cost there (None: they did not reach the goal
    there), trials simulated, seconds spent."""

    controls: list
    cost: float
    cost_before: float | None
    trials: int
    seconds: float

    @property
    def gain(self) -> float:
        """Relative cost saved at the planner's step (0: nothing found)."""
        if self.cost_before is None:
            return 1.0
        return 1.0 - self.cost / self.cost_before if self.cost_before > 0 else 0.0

    def to_json(self) -> dict:
        return {"cost_before": self.cost_before, "cost_after": self.cost, "trials": self.trials,
                "seconds": round(self.seconds, 3)}


def _moves(ctrl: np.ndarray, i: int, s: float, top: float, lo: float, hi: float) -> np.ndarray:
    """The trial wheel speeds (m, 4) of controls i and i + 1 (module doc)."""
    n = len(ctrl)
    wl, wr = ctrl[i, 0], ctrl[i, 1]
    nl, nr = (ctrl[i + 1, 0], ctrl[i + 1, 1]) if i + 1 < n else (0.0, 0.0)
    d = s * top
    out = []
    for a, b in ((wl * (1 + s), wr * (1 + s)), (wl * (1 - s), wr * (1 - s)), (wl + d, wr - d), (wl - d, wr + d)):
        a, b = min(max(a, lo), hi), min(max(b, lo), hi)
        if (a, b) != (wl, wr):
            out.append((a, b, nl, nr))
    if i + 2 < n:                                    # two full periods (not the cut last one)
        # a turn or a speed moved between the two (heading and distance after both kept
        # but where a wheel speed is clipped to the range)
        for a, b, c, e in ((wl + d, wr - d, nl - d, nr + d), (wl - d, wr + d, nl + d, nr - d),
                           (wl + d, wr + d, nl - d, nr - d), (wl - d, wr - d, nl + d, nr + d)):
            a, b = min(max(a, lo), hi), min(max(b, lo), hi)
            c, e = min(max(c, lo), hi), min(max(e, lo), hi)
            if (a, b, c, e) != (wl, wr, nl, nr):
                out.append((a, b, c, e))
    if i + 2 < n and (wl, wr) != (nl, nr):
        out.append((nl, nr, wl, wr))
        ml, mr = 0.5 * (wl + nl), 0.5 * (wr + nr)
        out.append((ml, mr, ml, mr))
    return np.array(out, float).reshape(-1, 4)


def polish(params: np.ndarray, data: np.ndarray, start: np.ndarray, controls, lo: float, hi: float,
           deadline: float | None = None, every: bool | None = None) -> Polished | None:
    """Polish ``controls`` [(wl, wr, duration_s)] driven from the planner state ``start``
    on the problem (params, data) of :mod:`sbmpc.problems.skidsteer` (module doc); wheel
    speeds kept in [lo, hi] [rad/s]. ``deadline``: a ``time.perf_counter()`` value at
    which to stop early. ``every``: moves at every control (None: where the plan has at
    most EXACT_UP_TO controls; else at the first HEAD and last TAIL, module doc). When
    the controls do not reach the goal disc of ``params`` (the last held up to one period
    longer), the first control, from the last one back, with a trial that does gets its
    cheapest such trial before the sweeps; None when none does."""
    t0 = time.perf_counter()
    ctrl = np.array([tuple(c) for c in controls], float).reshape(-1, 3)
    if every is None:
        every = len(ctrl) <= EXACT_UP_TO
    extra = int(params[SS.Q_NSTEP])        # the last control may be held one period longer
    out = np.empty_like(start)
    c0, used, last = SS.sequence_cost(params, data, start, ctrl, 0, extra, np.inf, out)
    reached = 0.0 <= c0 < np.inf
    if reached:
        ctrl = ctrl[:used].copy()
        ctrl[-1, 2] = round(last, 9)
    best = c0 if reached else np.inf
    trials = 0
    top = max(abs(lo), abs(hi))
    energy = params[SS.Q_COST] != SS.COST_TIME
    col = K.S_E if energy else K.S_T
    states = np.empty((len(ctrl), start.size))     # states[i]: before control i (kept current)
    SS.sequence_states(params, data, start, ctrl, states)

    def attempt(i: int, s: float) -> bool:
        """Try the moves of size s at control i; keep the best trial that reaches the
        goal for less than the best so far. Whether one was kept."""
        nonlocal ctrl, states, best, trials
        moves = _moves(ctrl, i, s, top, lo, hi)
        m = len(moves)
        if not m:
            return False
        prefix = states[i, col] - start[col]
        costs = np.empty(m)
        used = np.empty(m, np.int64)
        lasts = np.empty(m)
        SS.sequence_costs(params, data, states[i], ctrl, i, moves, extra, best - prefix, costs, used, lasts)
        trials += m
        ok = np.flatnonzero((costs >= 0.0) & np.isfinite(costs))
        if not ok.size:
            return False
        j = ok[np.argmin(costs[ok])]
        if not prefix + costs[j] < best * (1.0 - MIN_GAIN):
            return False
        best = prefix + costs[j]
        ctrl[i, :2] = moves[j, :2]
        if i + 1 < len(ctrl):
            ctrl[i + 1, :2] = moves[j, 2:]
        ctrl = ctrl[:i + used[j]].copy()
        ctrl[-1, 2] = round(lasts[j], 9)
        states = states[:len(ctrl)]      # the prefix up to i is unchanged
        SS.sequence_states(params, data, states[i], ctrl[i:], states[i:])
        return True

    def late() -> bool:
        return deadline is not None and time.perf_counter() > deadline

    if best == np.inf:
        # the controls miss the goal: a sequence that reaches it first, from the last
        # control backwards (a trial there drives a short tail, and with no bound every
        # trial drives to the end), so that the sweeps have a cost to cut trials at
        for i in range(len(ctrl) - 1, -1, -1):
            if late() or attempt(i, STEPS[0]):
                break
    stop = False
    for s in STEPS:
        for _ in range(MAX_SWEEPS if every else HEAD_TAIL_SWEEPS):
            improved = False
            i = 0
            while i < len(ctrl):
                if late():
                    stop = True
                    break
                if every or i < HEAD or i >= len(ctrl) - TAIL:
                    improved |= attempt(i, s)
                i += 1
            if stop or not improved:
                break
        if stop:
            break
    if best == np.inf:
        return None
    return Polished([(float(a), float(b), float(d)) for a, b, d in ctrl], float(best),
                    float(c0) if reached else None, trials, time.perf_counter() - t0)


__all__ = ["Polished", "STEPS", "MAX_SWEEPS", "HEAD_TAIL_SWEEPS", "HEAD", "TAIL", "EXACT_UP_TO", "polish"]
