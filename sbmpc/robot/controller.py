"""The controller a robot's own loop calls (:class:`Controller`): ``step(t, measurement)
-> command`` at 10-20 Hz, the planning done beside it.

The policy, period by period (a *period* is the planner's ``period_s``, 1 s by default;
the robot calls :meth:`Controller.step` every ``period_s`` of the controller, 0.1 s by
default, and gets the same wheel speeds until the period ends):

1. **drive**: the first period of the current horizon plan
   (:class:`sbmpc.planning.horizon.HorizonPlanner`), after the **guard** has predicted it
   from the estimated state (the planning vehicle and the margin's twin at 1 kHz) and let
   it through: never a period that comes within half the tip-over margin or leaves the
   map;
2. meanwhile, in a worker thread, the **next plan** from the state the model predicts at
   the period's end, warm-started from the current plan;
3. at the period's end, the **estimate** (:class:`sbmpc.robot.estimator.Estimator`) is
   compared with that prediction: within the run's tolerance the plan made ahead is
   taken; off it, or **stalled** (the measurement says so, or the estimator's model
   infers it), a plan from the estimate is made while the wheels are held at rest;
4. a horizon plan that finds no way on from a saturated drive is first given a
   **settled** vehicle (one period at rest); where it still finds none, or the terminal
   cost has not fallen for ``STUCK_HORIZONS`` horizons, the controller **hands over** to a
   whole-route plan (:func:`sbmpc.planning.plan.plan`, in a second worker thread) from
   the vehicle at rest and follows it, re-planning the whole route where the vehicle
   leaves it; with ``beside`` (``run.beside``), the hand-over waits for no new plan:
   whole-route plans made in a third worker at the lowest CPU priority, kept fresh (each
   from where the horizon plan predicts the vehicle a period later than the last took to
   make), are offered (:mod:`sbmpc.planning.rejoin`), and the hand-over makes the newest
   that passes within reach the horizon plans' guide: their terminal cost runs onto its
   path and along it (status 'tracking'), every period planned and guarded as before.
   Only where no offer is ready, or the tracker too finds no way on, does it plan the
   whole route from where the vehicle stands (and its tracker takes over again off
   that plan). (Following an offer's controls from where the vehicle joined it, within
   the run's tolerances, stalled the nominal vehicle on ``hills_field`` in 3 of 3 energy
   runs: its plans ride the drive's limit, and a join 0.25 m/s slow loses the run-up);
5. where the guard holds a period back, from rest its first half or quarter where the
   guard lets that through (:func:`sbmpc.execution.shortened`), else a plan from where the
   vehicle stands (horizon, then whole-route); where that too is held back or finds no
   way, back along the way it came, each
   period guarded (:meth:`Controller._back_off`, twice a run at most), and horizon plans
   from there; where it cannot back off, the controller stops for good and says why
   (the guard lets a vehicle that cannot brake out of its band drive a period no
   steeper than braking: :func:`sbmpc.execution.holder`);
6. after a **stall**, the plans are made for the margin's pessimistic twin of the
   planning vehicle (it proved weaker there), and a second stall near an earlier one
   makes the slope ahead a wall in their map (:meth:`Controller._as_weaker`), unless it
   stalled in a turn (the sides' currents pulling against each other at the limit: the
   ground ahead did not hold it); such a turning stall grows the twin instead
   (:func:`sbmpc.execution.grown`: x1.2, then x1.3), whose plans turn more gently. A
   stall reported again within the stall test's time,
   where the vehicle stood, is the same stall (:meth:`Controller._same_stall`).

:meth:`Controller.step` never waits on a plan (``lockstep=False``, a robot): where the
plan it needs is not ready, the command holds the wheels at rest (``status``
'waiting'/'planning') and the next call looks again. ``lockstep=True`` (``sbmpc run``'s
simulated truth) waits instead: the simulated clock stands still while the planner
works, and every plan's wall-clock time is kept (``horizon.seconds``).
"""
from __future__ import annotations

import math
import os
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, replace

import numpy as np

from dynamics import kernels as K

from ..errors import InputError
from ..planning import plan as PL
from ..planning import rejoin as RJ
from ..planning import world as WO
from ..planning.horizon import HorizonPlanner, periods
from ..problems import skidsteer as SS
from .. import estimate as ES
from .. import execution as EX
from .estimator import Estimator
from .messages import STATUSES, Command, Measurement, to_twist

PERIOD_RANGE = (0.05, 1.0)     # s: the control periods the controller takes
BESIDE_OFFERS = 3              # the plans made beside kept for a hand-over (the newest)
SAME_STALL_M = 0.25            # m: a stall reported this close to the last, within STALL_TIME of it, is that one again


@dataclass
class _Drive:
    """Policy request: command ``control`` (wl, wr, duration_s) for a period."""
    control: tuple
    status: str


@dataclass
class _Await:
    """Policy request: the result of ``future`` (a plan)."""
    future: Future
    status: str


class Controller:
    """Receding-horizon SBMPC as a robot calls it (module doc).

    ``world``: the planning world (:func:`sbmpc.load_world`); ``cost``: 'time' or
    'energy' (default the scenario's); ``period_s``: the control period [s] (0.05-1,
    how often the robot calls :meth:`step`); ``horizon_s``: the look-ahead [s] (default
    the scenario's ``planner.horizon_s``, else 10); ``lockstep``: wait for plans (a
    simulated clock) instead of holding at rest; ``settings``: the run's tolerances
    (:class:`sbmpc.scenario.RunSettings`, default the scenario's ``run``); ``beside``:
    make a whole-route plan beside the horizon from the start and hand over to it
    (module doc, 4; default the settings' ``beside``).

    What it did is kept for the record: ``plans`` (:class:`sbmpc.execution.Replan` per
    plan), ``horizon`` (:class:`sbmpc.execution.HorizonStats`), ``guarded``, ``stalls``,
    ``periods``, ``driven`` [(wl, wr, duration_s)] and ``latencies`` (wall-clock seconds
    of every :meth:`step`); with ``keep_paths``, ``paths``: per plan found, (robot time
    [s], {x, y, z, yaw: arrays}) of the poses its model predicts (what a robot publishes
    as its plan)."""

    def __init__(self, world: WO.World, cost: str | None = None, period_s: float = 0.1,
                 horizon_s: float | None = None, lockstep: bool = False, settings=None, keep_paths: bool = False,
                 beside: bool | None = None):
        lo, hi = PERIOD_RANGE
        if not (isinstance(period_s, (int, float)) and lo <= period_s <= hi):
            raise InputError(f"period_s: expected a control period in [{lo:g}, {hi:g}] s, found {period_s!r:.30}")
        self.cost = WO.checked_cost(world, cost)
        ps = world.scenario.planner
        if horizon_s is None:
            horizon_s = ps.horizon_s if ps.horizon_s > 0.0 else 10.0
        if not (isinstance(horizon_s, (int, float)) and horizon_s > 0.0):
            raise InputError(f"horizon_s: expected a look-ahead > 0 s, found {horizon_s!r:.30}")
        if ps.horizon_s != horizon_s:
            world = replace(world, scenario=replace(world.scenario, planner=replace(ps, horizon_s=float(horizon_s))))
        self.world = world
        self.period_s = float(period_s)
        self.lockstep = bool(lockstep)
        self.settings = settings or world.scenario.run
        t0 = time.perf_counter()
        ps = world.scenario.planner
        self.planner = HorizonPlanner.of(world, self.cost)
        self.setup_s = time.perf_counter() - t0     # the value and turn cost: the first plan's time
        self.estimator = Estimator(world, self.cost)
        self.model = EX.Executor(world, self.cost)
        self.guards = EX.guards(world, self.cost)
        self.plan_world = world       # what the plans are made for (the margin's twin after a stall)
        self.planned_as = None        # the vehicle whose twin plans, once a stall showed it weaker
        self.weaker_from = None       # when [s]
        self.evidence = ES.Evidence()  # what the periods driven say of the vehicle (estimate: a stall's sign, the fit)
        self.nominal = EX.Executor(world, self.cost)   # the planning vehicle's one-period predictions
        self.inferred: list = []      # per stall: what the periods before it said (estimate.Evidence.infer, fit)
        self.adapted: list = []       # the fits the plans took up without a stall (run.adapt_periods)
        self._base = world            # the vehicle planned for (or whose twin): the file's, or as measured
        self._as_twin = False         # the margin's twin of _base plans (a stall showed the vehicle weaker)
        self._base_key = (1.0,) * len(ES.FIT)   # _base's factors on the file's vehicle (estimate.key)
        self._samples: list = []      # (t, row of K.CHANNELS) measured at each step of the period driven
        self._fitting = None          # the adaptation's fit being made in the route worker (run.adapt_periods)
        self._since_fit = 0           # periods driven since the last adaptation's fit
        self._marks = ()              # slopes a second stall near the first marked impassable
        self._retraced = 0            # retraces tried (execution.RETRACE_PERIODS)
        self._way: list = []          # the periods driven along the way it came (not those driven back)
        self._horizon_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="sbmpc-horizon")
        self._route_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="sbmpc-route")
        self._beside_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="sbmpc-beside", initializer=_low)
        self.beside = self.settings.beside if beside is None else bool(beside)
        self._beside = None           # (future of _beside, cancel, robot time, wall time): being made
        self._offers: list = []       # [(plan, tracker, start)]: plans made beside for plan_world, newest last
        self._beside_took = 0.0       # wall time [s] the last plan made beside took
        # the record
        self.plans: list = []
        self.horizon = EX.HorizonStats(ps.horizon_s)
        self.guarded = 0
        self.stalls = 0
        self.stall_at: list = []
        self._stall_t = None          # robot time of the last stall counted [s]
        self._stall_call = -1         # the step call that counted it
        self._stall_currents = (0.0, 0.0)   # each side's current [A] at it
        self._calls = 0               # step calls that reached the policy
        self.periods = 0
        self.driven: list = []
        self.latencies: list = []
        self.keep_paths = bool(keep_paths)
        self.paths: list = []
        # the loop's state
        self.status = "planning"
        self.reason = None
        self.done = False
        self.closed = False
        self._policy = None
        self._request = None          # the policy's pending _Drive or _Await
        self._segment_end = -math.inf
        self._segment_start = None
        self._command = (0.0, 0.0)    # the wheel speeds commanded now
        self._last_t = None
        self._last = None             # the last Command
        self._plan_t = None           # when the plan driven was made (robot time)
        self._X = None                # the estimate at the last step
        self._tilt = 0.0              # how far the map's tilt is off where the vehicle stands [rad]

    @classmethod
    def from_scenario(cls, scenario, cost: str | None = None, period_s: float = 0.1, horizon_s: float | None = None,
                      lockstep: bool = False) -> "Controller":
        """A controller for a scenario: a YAML path or a :class:`sbmpc.scenario.Scenario`
        (with planner overrides, a dict or a heights array:
        ``Controller(sbmpc.load_world(..., **planner))``)."""
        from .. import scenario as SC
        scn = scenario if isinstance(scenario, SC.Scenario) else SC.load(scenario)
        return cls(WO.resolve(scn), cost, period_s, horizon_s, lockstep)

    # ---- the robot's call ---------------------------------------------------------
    def step(self, t: float, measurement: Measurement, applied: tuple | None = None) -> Command:
        """The command for the control period from robot time ``t`` [s], given what the
        robot measures now. ``applied``: the wheel speeds (wl, wr) [rad/s] the drive was
        given since the last call, where not this controller's own (a shadow run: the
        driver's). A repeated ``t`` gets the last command again; a ``t`` before
        the last one, a measurement without a pose or with a value that is not a finite
        number, or a pose off the map, an InputError (the robot keeps its last command
        or stops: nothing wrong is commanded)."""
        t0 = time.perf_counter()
        if not (isinstance(t, (int, float)) and math.isfinite(t)):
            raise InputError(f"step: t: expected a finite time [s], found {t!r:.30}")
        m = measurement.checked()
        if self._last_t is not None:
            if t < self._last_t:
                raise InputError(f"step: t: expected times that never go back, found {t:.3f} s after "
                                 f"{self._last_t:.3f} s; the measurement is ignored")
            if t == self._last_t:
                return self._last
        done = applied if applied is not None else self._command
        issued = [] if self._last_t is None else [(float(done[0]), float(done[1]), t - self._last_t)]
        X = self.estimator.update(t, m, issued)
        stalled = self.estimator.stalled_now
        self._samples.append((float(t), self._sample(m)))
        # the map's tilt error where the vehicle stands, from the IMU (the guard's)
        self._tilt = 0.0 if m.pitch is None else EX.tilt_error(self.world, X, m.pitch, m.roll)
        self._X = X
        self._calls += 1
        self._last_t = float(t)
        cmd = self._advance(t, X, stalled)
        self.latencies.append(time.perf_counter() - t0)
        return cmd

    def _sample(self, m: Measurement) -> np.ndarray:
        """What a measurement says of the drive as a row of K.CHANNELS (NaN where it says
        nothing): the wheel speeds, the currents (or the efforts over the torque
        constants) and the forward speed (odometry's, else the wheels' mean)."""
        v = self.world.vehicle
        row = np.full(K.NR, np.nan)
        currents = m.currents(v)
        if currents is not None:
            row[K.R_IL], row[K.R_IR] = currents
        if m.wl is not None:
            row[K.R_WL], row[K.R_WR] = m.wl, m.wr
        if m.v is not None:
            row[K.R_V] = m.v
        elif m.wl is not None:
            row[K.R_V] = 0.5 * v.wheel_radius * (m.wl + m.wr)
        return row

    def _witness(self, X0: np.ndarray, control, t0: float, t1: float) -> None:
        """A period driven from the estimate X0 (robot times t0 to t1) kept as evidence of
        the vehicle (:meth:`sbmpc.estimate.Evidence.add_samples`): the measurements of the
        steps in it against the planning vehicle's prediction from X0 at the same
        controller steps."""
        rows = [(t, r) for t, r in self._samples if t0 <= t < t1]
        self._samples = [(t, r) for t, r in self._samples if t >= t1]
        if len(rows) < 2 or all(np.isnan(r[K.R_WL]) and np.isnan(r[K.R_IL]) for _, r in rows):
            return
        rate = self.world.vehicle.controller_rate
        idx = np.array([int(round((t - t0) * rate)) for t, _ in rows], np.int64)
        driven = (control[0], control[1], round(t1 - t0, 9))
        rec, _, _ = self.nominal.step(X0, driven)
        self.evidence.add_samples(np.array([r for _, r in rows]), rec[np.minimum(idx, len(rec) - 1)], X0, driven, idx)

    def ended_at(self, t: float) -> None:
        """The run ended at robot time ``t`` [s] (the goal reached, or the robot stopped
        from outside) in the middle of a period: that period is counted and recorded as
        driven up to ``t``."""
        if isinstance(self._request, _Drive) and self._segment_start is not None and t > self._segment_start:
            wl, wr, _ = self._request.control
            self.periods += 1
            self.driven.append((wl, wr, round(t - self._segment_start, 9)))
        self._request = None
        self.done = True

    def close(self):
        """Stop the worker threads (a plan being made is finished first). A later
        :meth:`step` holds the wheels at rest ('stopped')."""
        self.closed = True
        if self._beside is not None:
            self._beside[1].set()           # the plan made beside is called off
        self._horizon_pool.shutdown(wait=True, cancel_futures=True)
        self._route_pool.shutdown(wait=True, cancel_futures=True)
        self._beside_pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ---- the loop -----------------------------------------------------------------
    def _advance(self, t: float, X: np.ndarray, stalled: bool) -> Command:
        if self.closed and not self.done:
            return self._end("stopped", "the controller was closed")
        if self.done:
            return self._issue(0.0, 0.0, self.status)
        g = self.world.scenario.goal
        if math.hypot(X[K.S_X] - g["x"], X[K.S_Y] - g["y"]) <= g["radius"]:
            return self._end("reached", None)
        if self._policy is None:
            self._policy = self._run(X)
            return self._resume(t, None)
        req = self._request
        if isinstance(req, _Drive):
            if t < self._segment_end - 0.5 * self.period_s and not stalled:
                return self._issue(*self._command, req.status)
            return self._resume(t, (X, stalled))
        return self._resume(t, None)         # awaiting a plan

    def _resume(self, t: float, value) -> Command:
        """Runs the policy from its pending request: sends ``value`` (a period's end) or
        the awaited plan, until it asks to drive (the command) or awaits a plan that is
        not ready (the wheels at rest meanwhile)."""
        send = value
        while True:
            req = self._request
            try:
                if isinstance(req, _Await):
                    if not (self.lockstep or req.future.done()):
                        return self._issue(0.0, 0.0, req.status)
                    send = req.future.result()
                req = self._policy.send(send) if self._request is not None else next(self._policy)
            except StopIteration as stop:
                status, reason = stop.value
                return self._end(status, reason)
            except Exception as exc:      # a plan or a prediction that failed: stop, say why, never a wrong command
                return self._end("stopped", f"the controller stopped: {type(exc).__name__}: "
                                            f"{' '.join(str(exc).split())[:200]}")
            self._request, send = req, None
            if isinstance(req, _Drive):
                wl, wr, d = req.control            # (d whole control periods: _on_ticks)
                self._segment_start, self._segment_end = t, t + d
                return self._issue(wl, wr, req.status)

    def _issue(self, wl: float, wr: float, status: str) -> Command:
        self._command = (float(wl), float(wr))
        self.status = status
        v, w = to_twist(wl, wr, self.world.vehicle)
        age = math.inf if self._plan_t is None else self._last_t - self._plan_t
        self._last = Command(float(wl), float(wr), v, w, status, age, self.done, self.reason)
        return self._last

    def _end(self, status: str, reason: str | None) -> Command:
        self.done, self.reason = True, reason
        self._request = None
        return self._issue(0.0, 0.0, status)

    # ---- plans, in the workers ---------------------------------------------------
    def _await_horizon(self, X, previous=None, budget_s=None, status="waiting"):
        fut = self._horizon_pool.submit(self.planner.plan, X.copy(), previous, budget_s)
        return (yield _Await(fut, status))

    def _made(self, h, why: str, X0: np.ndarray, extra_s: float = 0.0):
        """A horizon plan recorded (``extra_s``: set-up time counted in the first)."""
        st = self.horizon
        st.seconds.append(h.seconds + extra_s)
        st.expansions.append(h.expansions)
        st.kept_previous += h.found_by == "previous"
        p = PL.Plan(self.world.scenario.name, self.cost, "found" if h.found else "no_path", h.reason,
                    list(h.controls), {}, planning_time_s=h.seconds + extra_s, nodes_expanded=h.expansions,
                    found_by=h.found_by)
        self._record(p, X0, why, h.found_by == "previous", h.start)
        return h

    def _record(self, p, X0: np.ndarray, why: str, warm: bool, start: np.ndarray) -> None:
        """A plan (a :class:`sbmpc.planning.plan.Plan`) kept in the record, made from X0 for
        ``why``, its path predicted from ``start`` where ``keep_paths``."""
        self.plans.append(EX.Replan(float(X0[K.S_T]), float(X0[K.S_X]), float(X0[K.S_Y]), why, p, warm,
                                    self.world.scenario.goal["radius"]))
        self._plan_t = self._last_t
        if self.keep_paths and p.found:
            self._keep_path(start, p.controls)

    def _keep_path(self, X0: np.ndarray, controls) -> None:
        """The poses the planning model predicts along ``controls`` from X0 (``paths``)."""
        rows, X = [], X0
        for c in controls:
            rec, end, X = self.model.step(X, c)
            rows.append(rec if not rows else rec[1:])
            if end < 0 or end == SS.IN_GOAL:
                break
        rec = np.vstack(rows)[::20]
        self.paths.append((self._last_t, {"x": rec[:, K.R_X], "y": rec[:, K.R_Y], "z": rec[:, K.R_Z],
                                          "yaw": rec[:, K.R_YAW]}))

    def _whole_route(self, X: np.ndarray, why: str):
        """A whole-route plan from X (the vehicle at rest), made in the second worker:
        the planner's own budget, an energy plan checked against the time plan (as
        ``sbmpc plan``'s; from narrow_pass's start the energy search alone found nothing
        in 60 s where the time search found a plan in 17 s)."""
        worlds = [self.plan_world] + ([self.world] if self.plan_world is not self.world else [])
        for w in worlds:
            # planning as the margin's twin (after a stall), where the twin has no way on the
            # planning vehicle's own plan is tried before the run stops: the twin is the
            # pessimistic bound, and the vehicle that stalled may still get out
            fut = self._route_pool.submit(PL.plan, w, self.cost, start=X.copy())
            p = yield _Await(fut, "waiting")
            self.horizon.fallbacks += 1
            self.horizon.fallback_s.append(p.planning_time_s)
            self._record(p, X, why if w is self.plan_world else f"{why}, as {self.world.vehicle.name} (its twin has "
                         "no way on)", False, X)
            if p.found:
                break
        return p

    def _start_beside(self, X: np.ndarray, ahead: tuple = ()) -> None:
        """A whole-route plan made beside the horizon (:func:`_beside`) for the world
        planned, in the third worker, from the state the model predicts at the end of the
        periods ``ahead`` [(wl, wr, duration_s)] driven from X (none: from X); one still
        being made is called off."""
        if not self.beside:
            return
        if self._beside is not None:
            self._beside[1].set()
        cancel = threading.Event()
        fut = self._beside_pool.submit(_beside, self.plan_world, self.cost, X.copy(), cancel, tuple(ahead))
        self._beside = (fut, cancel, float(self._last_t), time.perf_counter())

    def _poll_beside(self, t: float) -> None:
        """The plan being made beside taken up where it is ready at robot time ``t`` [s]:
        kept among the offers (the newest ``BESIDE_OFFERS``) where it found one. A robot's
        clock is the wall clock; a lockstep run's (``sbmpc run``) runs faster, so there
        the plan counts as ready only once as much robot time as wall time has passed from
        its asking to its end, and the run waits for it no longer than a robot would have
        (the run clock: the vehicle meets the plans made beside when a robot would)."""
        if self._beside is None:
            return
        fut, _, t0, wall0 = self._beside
        if self.lockstep and not fut.done():
            left = (t - t0) - (time.perf_counter() - wall0)
            if left > 0.0:
                wait([fut], timeout=left)
        if not fut.done():
            return
        p, tr, X0, ended = fut.result()
        if self.lockstep and t - t0 < ended - wall0:
            return
        self._beside = None
        self._beside_took = ended - wall0
        self.horizon.beside_s.append(round(t - t0, 3))
        if tr is not None:
            self._offers = (self._offers + [(p, tr, X0)])[-BESIDE_OFFERS:]

    def _refresh_beside(self, X: np.ndarray, h) -> None:
        """Keeps the plans made beside fresh while horizon plans drive: once the last is
        taken up, the next is made from where the horizon plan ``h`` (from X) predicts the
        vehicle a period later than the last one took to make on the wall clock (a robot's
        clock; short of the plan's end): so the vehicle is near it when it is ready."""
        self._poll_beside(self._last_t)
        if not self.beside or self._beside is not None or not h.found or h.goal:
            return
        steps = periods(h.controls, self.world.scenario.planner.period_s)
        lag = self._beside_took
        k = min(len(steps) - 1, int(math.ceil(lag / self.world.scenario.planner.period_s)) + 1)
        if k >= 1:
            self._start_beside(X, steps[:k])

    def _rejoin(self, X: np.ndarray, why: str, tracked=None):
        """At a hand-over: (plan, tracker) of a whole-route plan made beside
        (:mod:`sbmpc.planning.rejoin`) that is ready now, never waited for: the newest
        offer that X joins (:meth:`_join`), else the newest offer other than ``tracked``
        (the plan the horizon plans track now) whose path passes within reach of the
        tracker's horizon plans, which lead onto it; None where there is none."""
        self._poll_beside(self._last_t)
        offers = self._offers
        got = next((o for o in reversed(offers) if self._join(o[0], X) is not None), None)
        if got is None:
            # a tracker leads onto a path its horizon plans can reach (half the look-ahead
            # at the top speed): one made where the vehicle no longer is would lead it back
            ps = self.world.scenario.planner
            reach = 0.5 * ps.horizon_s * WO.wheel_speed_range(self.world)[1] * self.world.vehicle.wheel_radius
            got = next((o for o in reversed(offers) if o[0] is not tracked
                        and RJ.path_distances(o[0], X).min() <= reach), None)
            if got is None:
                return None
        p, tr, X0 = got
        offers.remove(got)
        self.horizon.rejoined += 1
        self._record(p, X0, f"{why}: the whole-route plan made beside from t = {X0[K.S_T]:.1f} s", False, X0)
        return p, tr

    def _join(self, p, X: np.ndarray):
        """The rest of the whole-route plan ``p`` from where the estimate X joins it, in
        periods (:func:`sbmpc.planning.rejoin.join`, within the run's re-plan
        tolerances), or None."""
        rs = self.settings
        return RJ.join(p, X, self.world.scenario.planner.period_s, self.period_s, rs.tol_xy,
                       math.radians(rs.tol_yaw_deg), rs.tol_v)

    def _on_ticks(self, control) -> tuple:
        """``control`` (wl, wr, duration_s) with its duration a whole number of control
        periods (at least one): how long the robot's loop commands it."""
        wl, wr, d = control
        return wl, wr, max(1, int(round(d / self.period_s))) * self.period_s

    def _drive(self, control, status):
        """Drives one period (``control`` on ticks, :meth:`_on_ticks`); returns (estimate,
        stalled) at its end, the period counted."""
        wl, wr, _ = control
        t_start, X0 = self._last_t, self._X
        X, stalled = yield _Drive(control, status)
        self.periods += 1
        self.driven.append((wl, wr, round(self._last_t - t_start, 9)))
        if status not in ("backing", "held"):
            self._way.append(self.driven[-1])
        if not stalled:
            self._witness(X0, control, t_start, self._last_t)
        return X, stalled

    def _as_weaker(self, X: np.ndarray, control):
        """After a stall where the plans drove the vehicle (the margin on), what the
        periods before it say (:class:`sbmpc.estimate.Evidence`, as whole-route runs do):
        the vehicle fitted to them (:func:`sbmpc.estimate.fit`, made in the worker) where
        there are enough, and the sign of the stall. From here on the plans are made for the
        margin's pessimistic twin of the vehicle as fitted (without a fit, of the vehicle
        planned for, unless the periods said it is stronger than that: the stall then came
        from where the plans drove it, not from a weaker drive); stalled again within
        ``MARK_NEAR`` of an earlier stall, the slope ahead is a wall in their map too
        (:func:`sbmpc.execution.marked`). Returns whether the planner was rebuilt (its value
        and motion tables, in the worker)."""
        if self.world.scenario.planner.margin <= 0.0:
            return False
        inf = self.evidence.infer(X)
        fitted = yield _Await(self._horizon_pool.submit(_fit, self.evidence, self.world, self.cost), "planning")
        inf["fit"] = fitted
        self.inferred.append(inf)
        marks = self._marks
        if EX.marks_wall(self.stall_at, X, self._stall_currents, self.world.vehicle):
            marks = marks + (EX.ahead(self.world, X, control),)
        # (the file's margin again where an adaptation firmed it; an adaptation's fit still
        # being made is of the model the stall just proved wrong: dropped)
        base, twin = ES.at_stall(self.world, self._base, self._base_key), self._as_twin
        self._fitting = None
        if fitted is not None:
            base, twin = ES.as_measured(self.world, ES.key(fitted)), True
            self._base_key = ES.key(fitted)
        elif not twin and inf["inferred"] != "stronger":
            twin = True
        repeats = EX.twin_grows(self.stall_at, X, self._stall_currents, self.world.vehicle)
        if repeats:             # stalled again in a turn where the twin's plans turned it
            base, twin = EX.grown(base, self.world, repeats), True
        inf["twin_margin"] = base.scenario.planner.margin if twin else None
        rebuilt = yield from self._replan_as(base, twin, marks)
        if twin and self.weaker_from is None:
            self.weaker_from = float(X[K.S_T])
        return rebuilt

    def _adapt(self, X: np.ndarray) -> bool:
        """``run.adapt_periods``: every that many periods driven, the vehicle refitted to
        the periods before (:func:`sbmpc.estimate.fit`) in the route worker, with the
        horizon planner for it where the fit is confident and says another vehicle than
        the one planned for (a factor 3 % off); taken up at the first period's end where
        it is ready (a robot never waits on it; a lockstep run does). Returns whether the
        plans are now made for the vehicle as measured."""
        if self._fitting is None:
            self._since_fit += 1
            if self._since_fit >= self.settings.adapt_periods and len(self.evidence.periods) >= ES.FIT_MIN_PERIODS:
                self._since_fit = 0
                snap = ES.Evidence()
                snap.periods.extend(self.evidence.periods)
                planned = (self._base_key, self._base.scenario.planner.margin)
                firm = ES.firms(self.settings, bool(self.stalls), self._as_twin)
                self._fitting = self._route_pool.submit(_refit, snap, self.world, self.cost, planned,
                                                        self._as_twin, self._marks, firm)
            return False
        if not (self.lockstep or self._fitting.done()):
            return False
        fut, self._fitting = self._fitting, None
        f, base, w, planner = fut.result()
        if planner is None:
            return False
        self.planner, self.plan_world, self.model, self._base = planner, w, EX.Executor(w, self.cost), base
        self._base_key = ES.key(f)
        self.planned_as = base.vehicle.name
        self.adapted.append({"t": round(float(X[K.S_T]), 3), "fit": f, "margin": base.scenario.planner.margin})
        return True

    def _planning_as(self, adapted: bool) -> str:
        """What a re-plan's reason adds once the planning model changed (a stall, an
        adaptation): as what the plans are made from here on."""
        return ("; adapted" if adapted else "") + (
            f"; planning as the margin's twin of {self.planned_as}" if self._as_twin else
            f"; planning as {self._base.vehicle.name}") + (
            f", {len(self._marks)} slope(s) kept off" if self._marks else "")

    def _replan_as(self, base: WO.World, twin: bool, marks: tuple):
        """The plans made from here on for ``base`` (or the margin's twin of it), with the
        slopes ``marks`` kept off: the horizon planner for that world built in the worker
        (holding the wheels meanwhile). Returns whether anything changed."""
        if (base, twin, marks) == (self._base, self._as_twin, self._marks):
            return False
        w = _planning_world(base, twin, marks)
        self.planner = yield _Await(self._horizon_pool.submit(HorizonPlanner.of, w, self.cost), "planning")
        self.plan_world, self.model = w, EX.Executor(w, self.cost)
        self._base, self._as_twin, self._marks = base, twin, marks
        if twin or base is not self.world:
            self.planned_as = base.vehicle.name
        return True

    def _back_off(self, X: np.ndarray):
        """Where no plan finds a way on: back along the way it came (the last of
        ``execution.RETRACE_PERIODS`` periods driven, reversed, each predicted by the
        guards first: :func:`sbmpc.execution.retrace`), as whole-route runs do after a
        stall; a vehicle stalled on a flank, or one that lost its run-up part way up a
        ramp steeper than it holds (no stall yet: every control from there stalls), has no
        plan from there, and has one from lower down (4 of 20 ``runup_ramp`` horizon runs
        stopped 3 m short on the ramp, their whole-route runs on the same truths reached,
        2026-12-07). The estimate at the end, or None (nothing driven yet, every retrace
        used, or held back). Each
        period is guarded again from the measured state before it is driven; one held back
        ends the backing there. A second back-off goes further back along the way, never
        forward again over the periods driven back (:func:`sbmpc.execution.back_along`)."""
        back, self._retraced = EX.back_along(self.guards, X, self._way, self._retraced, self._tilt)
        if back is None:
            return None
        for c in back:
            if self.guards and EX.held(self.guards, X, c, True, self._tilt):
                X = yield from self._brake(X)
                break
            X, _ = yield from self._drive(self._on_ticks(c), "backing")
        return X

    def _brake(self, X: np.ndarray):
        """After the guard held a period back: a moving vehicle cannot wait for the plan,
        so it brakes through a period (status ``held``) and the plan is made from where it
        comes to rest. The estimate then (X itself for a vehicle at rest)."""
        if not EX.moving(X):
            return X
        X, _ = yield from self._drive(self._on_ticks((0.0, 0.0, self.world.scenario.planner.period_s)), "held")
        return X

    def _same_stall(self, X: np.ndarray) -> bool:
        """Whether a stall reported at X is the last one again, not a new one: less than
        the stall test's ``STALL_TIME`` after it, where the vehicle stood. A restarted drive
        cannot fail that test again so soon; the report is the same stall seen twice
        (the estimate's model flags it a few ms before the drive's own protection trips,
        or the other way round). Counted twice, every such stall also marked the ground
        ahead a wall (a second stall within ``MARK_NEAR``): on ``hills_field`` four of six
        runs that failed on four stalls had one stall counted twice, 0.01-0.23 s apart."""
        if self._stall_t is None:
            return False
        x, y = self.stall_at[-1]
        # (a control period of STALL_TIME or more reports the second sighting at the next call)
        soon = X[K.S_T] - self._stall_t < K.STALL_TIME or self._calls == self._stall_call + 1
        return soon and math.hypot(X[K.S_X] - x, X[K.S_Y] - y) < SAME_STALL_M

    def _stalled_here(self, X: np.ndarray):
        """A stall counted and placed; the reason to stop once there are more than
        ``run.max_stalls``, else None."""
        self.stalls += 1
        self.stall_at.append((float(X[K.S_X]), float(X[K.S_Y])))
        self._stall_t, self._stall_call = float(X[K.S_T]), self._calls
        # each side's current at the stall, as measured (this call's sample), else estimated:
        # read after the fit, which a robot's later calls (its drive at rest) wait for
        row = self._samples[-1][1]
        self._stall_currents = ((row[K.R_IL], row[K.R_IR]) if not np.isnan(row[K.R_IL])
                                else (float(X[K.S_IL]), float(X[K.S_IR])))
        if EX.past_stall_limit(self.stall_at, X, self.settings):
            inf = self.evidence.infer(X)
            self.inferred.append(inf)
            return ES.stall_failure(self.stall_at, self._base.vehicle.name, inf)
        return None

    # ---- the policy ----------------------------------------------------------------
    def _run(self, X: np.ndarray):
        """The policy (module doc) as a generator of requests: it yields a period to
        drive (resumed with the estimate at the period's end and whether the drive
        stalled) or a plan to wait for (resumed with the plan), and returns (status,
        reason) where it ends."""
        world, rs = self.world, self.settings
        ps = world.scenario.planner
        st = self.horizon
        tol_yaw = math.radians(rs.tol_yaw_deg)
        window = max(2, int(round(EX.STUCK_HORIZONS * ps.horizon_s / ps.period_s)))
        togo = []                  # the terminal cost at the estimate, period by period
        guide = None               # [(wl, wr, d)]: the whole-route plan followed after a hand-over
        kept = True                # the plan followed keeps the margin
        held = False               # the last period was held back by the guard, nothing driven since
        settled = False            # the last period driven held the wheels at rest
        tracking = None            # the whole-route plan made beside that the horizon plans lead onto
        self._start_beside(X)
        # the first plan has its own budget: the set-up (the value, the turn cost) came with
        # the controller, before the robot's first call (it is recorded with the first plan)
        h = yield from self._await_horizon(X, None, ps.horizon_first_budget_s, "planning")
        h = self._made(h, "start", X, self.setup_s)

        def route(X, why):
            p = yield from self._whole_route(X, why)
            return p, (periods(p.controls, ps.period_s) if p.found else None), EX.keeps_margin(p)

        while True:
            X = self._X
            settle = guide is None and not h.found and not settled and EX.settles(X)
            if not settle and guide is None and (not h.found or (len(togo) > window and togo[-1] >= togo[-1 - window])):
                why = ("the horizon plan found no way on" if not h.found else
                       f"no progress in {window} periods (the terminal cost at the vehicle did not fall)")
                got = self._rejoin(X, why, tracking)
                if got is not None:
                    # the hand-over without waiting: horizon plans that lead onto the plan
                    # made beside and along it
                    self.planner, tracking = got[1], got[0]
                    togo.clear()
                    h = self._made((yield from self._await_horizon(X)), f"{why}: onto the whole-route plan "
                                   "made beside", X)
                    continue
                p, guide, kept = yield from route(X, f"{why}: whole-route plan")
                if not p.found:
                    Xb = yield from self._back_off(X)
                    if Xb is not None:
                        h = self._made((yield from self._await_horizon(Xb)), "backed off: no way on from "
                                       f"({X[K.S_X]:.2f}, {X[K.S_Y]:.2f})", Xb)
                        togo.clear()
                        continue
                    weaker = f"; {EX.weaker(self.stall_at, world.vehicle.name)}" if self.stall_at else ""
                    return "stopped", (f"no way on from ({X[K.S_X]:.2f}, {X[K.S_Y]:.2f}) at t = {X[K.S_T]:.1f} s "
                                       f"({why}): {p.reason}{weaker}")
                X = self._X
            if settle:
                control, status = (0.0, 0.0, ps.period_s), "settling"
            elif guide is not None:
                control, status = guide[0], "whole-route"
                if len(guide) == 1:
                    control = (control[0], control[1], max(control[2], ps.period_s))
            else:
                step = periods(h.controls, ps.period_s)
                control, status = step[0], "horizon" if tracking is None else "tracking"
                if h.goal and len(step) == 1:
                    control = (control[0], control[1], max(control[2], ps.period_s))
            stop = bool(self.guards) and EX.held(self.guards, X, control, kept, self._tilt)
            short = None
            if stop:
                # the guard: the period is not driven, but a first part of a horizon
                # plan's period may be (execution.shortened), and a plan made from there;
                # else a plan from where the vehicle stands: a horizon plan, then a
                # whole-route one, then back along the way it came, then it stops
                if guide is None and not settle and not EX.moving(X):
                    # (from rest only: a part driven at speed down a descent added the speed
                    # that braking then could not take off, and a map-family truth whose
                    # predictions braked in time rolled over, 2026-12-07)
                    short = EX.shortened(self.guards, X, control, kept, self._tilt, self.period_s)
            if short is not None:
                control = short
                st.shortened += 1
            elif stop:
                self.guarded += 1
                where = f"{EX.HELD} at ({X[K.S_X]:.2f}, {X[K.S_Y]:.2f})"
                X = yield from self._brake(X)
                if not held and guide is None:
                    st.from_measured += 1
                    h = self._made((yield from self._await_horizon(X, None, None, "held")), where, X)
                    held = True
                    continue
                failed = None
                if not (held and guide is not None):
                    p, guide, kept = yield from route(X, f"{where}: whole-route plan")
                    if p.found:
                        held = True
                        continue
                    failed = ("whole-route plan", p.reason)
                # the whole-route plan's first period held back too, or no whole-route plan
                # from there: back along the way it came where the guards let it, and
                # horizon plans from there (as after a whole-route plan that found no way
                # on); else it stops
                Xb = yield from self._back_off(X)
                if Xb is None:
                    return "stopped", EX.stopped(X, ps, failed)
                guide, kept, held = None, True, False
                togo.clear()
                h = self._made((yield from self._await_horizon(Xb)), f"backed off: {where}, and " + (
                    "no whole-route plan from there" if failed else "the whole-route plan's first period from "
                    "there too"), Xb)
                continue
            held = False
            settled = settle
            st.settled += int(settle)
            if guide is not None:
                guide.pop(0)
            control = self._on_ticks(control)
            _, _, P = self.model.step(X, control, record=False)
            nxt = (self._horizon_pool.submit(self.planner.plan, P.copy(), h if short is None else None, None)
                   if guide is None else None)           # made while the period is driven
            if guide is None and short is None:     # (h's first period was not driven whole)
                self._refresh_beside(X, h)
            X, stalled = yield from self._drive(control, status)
            dxy, dyaw, dv = EX.deviation(X, P)
            off = dxy > rs.tol_xy or dyaw > tol_yaw or dv > rs.tol_v
            rebuilt = adapted = False
            if stalled and self._same_stall(X):
                off = True      # the stall already counted: a plan from the restarted drive, nothing refitted
            elif stalled:
                failed = self._stalled_here(X)
                if failed:
                    return "stopped", failed
                off = True
                rebuilt = yield from self._as_weaker(X, control)
            elif rs.adapt_periods:
                adapted = rebuilt = self._adapt(X)
                off = off or adapted        # the next plan from the measured state, for the vehicle as measured
            now_as = self._planning_as(adapted) if rebuilt else ""
            if rebuilt:
                togo.clear()            # the terminal cost of another model
                tracking = None         # (the tracker was of the model replaced)
                self._offers.clear()    # (and so were the plans made beside)
                self._start_beside(X)
            if guide is not None and tracking is not None and (off or not guide):
                # off a whole-route plan made from where the vehicle stood (the tracker had
                # no way on there), or at its end short of the goal: the tracker's horizon
                # plans take over again (nothing waited for)
                why = "off the whole-route plan" if off else "the whole-route plan ended short of the goal"
                guide = None
                h = self._made((yield from self._await_horizon(X)), why, X)
                continue
            if guide is not None:
                if off or not guide:
                    p, guide, kept = yield from route(X, ("off the whole-route plan" if off else
                                                       "the whole-route plan ended short of the goal") + now_as)
                    if not p.found:
                        Xb = yield from self._back_off(X)
                        if Xb is None:
                            return "stopped", (f"no way on from ({X[K.S_X]:.2f}, {X[K.S_Y]:.2f}) at "
                                               f"t = {X[K.S_T]:.1f} s: {p.reason}")
                        p, guide, kept = yield from route(Xb, f"backed off: no way on from ({X[K.S_X]:.2f}, "
                                                          f"{X[K.S_Y]:.2f})")
                        if not p.found:
                            return "stopped", (f"no way on from ({Xb[K.S_X]:.2f}, {Xb[K.S_Y]:.2f}) at "
                                               f"t = {Xb[K.S_T]:.1f} s, after backing off: {p.reason}")
                continue
            togo.append(self.planner.to_go(X))
            if off:
                st.from_measured += 1
                why = ("stalled" if stalled else
                       f"off the prediction by {dxy:.2f} m, {math.degrees(dyaw):.1f} deg, {dv:.2f} m/s") + now_as
                h = self._made((yield from self._await_horizon(X, None if rebuilt else h)), why, X)
            else:
                h = self._made((yield _Await(nxt, "horizon")), EX.SETTLED if settle else "next period", P)


def _planning_world(base: WO.World, twin: bool, marks: tuple) -> WO.World:
    """What the controller's plans are made for: ``base`` (the file's vehicle, or as
    measured) with the slopes ``marks`` kept off (:func:`sbmpc.execution.marked`), as the
    margin's twin where ``twin`` (:func:`sbmpc.execution.twin_planner`)."""
    w = EX.marked(base, marks) if marks else base
    return EX.twin_planner(w) if twin else w


def _fit(evidence, world: WO.World, cost: str) -> dict | None:
    """:func:`sbmpc.estimate.fit`, None where it failed: a fit is evidence, never the
    reason a run stops."""
    try:
        return ES.fit(evidence, world, cost)
    except Exception:       # noqa: BLE001 - no fit: the stall is read by its sign alone
        return None


def _refit(evidence, world: WO.World, cost: str, planned: tuple, twin: bool, marks: tuple,
           firm: bool = False) -> tuple:
    """(fit, vehicle as measured, planning world, horizon planner) of the controller's
    adaptation (:meth:`Controller._adapt`); the last three None where the fit failed, is
    not confident or says the vehicle planned for (``planned``: its factors and margin;
    ``firm``: the margin firms, :func:`sbmpc.estimate.adapts`)."""
    f = _fit(evidence, world, cost)
    now = ES.adapts(world, f, planned, firm)
    if now is None:
        return f, None, None, None
    w = _planning_world(now, twin, marks)
    return f, now, w, HorizonPlanner.of(w, cost)


def _beside(world: WO.World, cost: str, X: np.ndarray, cancel, ahead: tuple = ()) -> tuple:
    """(plan, tracker, start, wall clock at its end [s, perf_counter]):
    :func:`sbmpc.planning.rejoin.beside` from the state the planning model predicts at the
    end of the periods ``ahead`` driven from X (the horizon plan's next periods); plan and
    tracker None where it failed, was called off or the prediction stalled: a plan made
    beside is an offer, never the reason a run stops. Run in the controller's third
    worker at the lowest CPU priority (:func:`_low`): the horizon plans the robot drives
    come first."""
    p = tr = None
    try:
        ex = EX.Executor(world, cost)
        for c in ahead:
            _, end, X = ex.step(X, c, record=False)
            if end < 0:
                break
        else:
            p, tr = RJ.beside(world, cost, X, cancel)
    except Exception:       # noqa: BLE001 - called off, or no plan from there: the hand-over plans as before
        p, tr = None, None
    return p, tr, X, time.perf_counter()


def _low() -> None:
    """The calling worker thread at the lowest CPU priority (nice 19), where the system
    allows it (Linux: a thread's own niceness)."""
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 19)
    except (AttributeError, OSError):      # not Linux, or not allowed: the default priority
        pass


__all__ = ["Controller", "PERIOD_RANGE", "STATUSES"]
