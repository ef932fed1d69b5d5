"""What the periods a vehicle drove say of it against the planning model (``sbmpc run``):
the sign of a stall (:meth:`Evidence.infer`: weaker, stronger, as planned) and the
vehicle as measured (:meth:`Evidence.fit`: its mass, battery voltage, grip and rolling
resistance, current limit fitted online to the periods driven, the calibration's least squares on a
window of the run).
"""
from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np

from dynamics import kernels as K

from .execution import Executor, weaker
from .planning import world as WO


EVIDENCE_PERIODS = 20      # periods before a stall whose currents and speeds say what the vehicle is
EVIDENCE_TOL = 0.03        # relative: a current or speed ratio this far from 1 says weaker or stronger


class Evidence:
    """What the periods a vehicle drove say of it against the planning model: per period
    (not ending in a stall), the mean |current| of both sides and the mean |speed|,
    measured and predicted from the same start (the last EVIDENCE_PERIODS kept)."""

    def __init__(self):
        from collections import deque
        self.rows = deque(maxlen=EVIDENCE_PERIODS)
        self.periods = deque(maxlen=EVIDENCE_PERIODS)    # (measured start state, control, measured record)

    def add(self, measured: np.ndarray, predicted: np.ndarray, X0: np.ndarray | None = None,
            control: tuple | None = None) -> None:
        """A period's records (rows of K.CHANNELS), the measured and the predicted; with
        the measured state X0 it began from and its ``control`` (wl, wr, duration_s), kept
        for :meth:`fit`."""
        k = min(len(measured), len(predicted))
        if k < 2:
            return
        if X0 is not None and control is not None:
            idx = np.arange(0, len(measured), FIT_EVERY)
            self.periods.append((X0.copy(), tuple(control), measured[idx].copy(), idx))
        self._compare(measured[:k], predicted[:k])

    def add_samples(self, measured: np.ndarray, predicted: np.ndarray, X0: np.ndarray, control: tuple,
                    idx: np.ndarray) -> None:
        """A period as a robot's loop measures it: rows of K.CHANNELS at the controller
        steps ``idx`` from the period's start (the robot's calls; what it did not measure
        NaN), the prediction's rows at the same steps, the state X0 (the estimate) it
        began from and its ``control`` (:class:`sbmpc.robot.Controller`)."""
        k = min(len(measured), len(predicted), len(idx))
        if k < 2:
            return
        self.periods.append((X0.copy(), tuple(control), measured[:k].copy(), np.asarray(idx[:k], np.int64)))
        self._compare(measured[:k], predicted[:k])

    def _compare(self, m: np.ndarray, p: np.ndarray) -> None:
        """A period's mean |current| and |speed|, measured and predicted (where measured)."""
        ok = ~np.isnan(m[:, K.R_IL]) & ~np.isnan(m[:, K.R_IR]) & ~np.isnan(m[:, K.R_V])
        if ok.sum() < 2:
            return
        m, p = m[ok], p[ok]
        self.rows.append((float(np.abs(m[:, K.R_IL]).mean() + np.abs(m[:, K.R_IR]).mean()),
                          float(np.abs(p[:, K.R_IL]).mean() + np.abs(p[:, K.R_IR]).mean()),
                          float(np.abs(m[:, K.R_V]).mean()), float(np.abs(p[:, K.R_V]).mean())))

    def infer(self, X: np.ndarray) -> dict:
        """What a stall at the measured state X says (issue: a vehicle that stalls is not
        always weaker): ``weaker`` where the periods before it drew more current than the
        planning model predicted or drove slower (ratios beyond EVIDENCE_TOL), ``stronger``
        where they drew less at the predicted speed (lighter, or less resistance: the
        stall came from where and how the plan drove it, not from a weaker drive),
        ``as planned`` in between, ``unknown`` without such periods (a stall in a fresh
        plan's first period)."""
        out = {"t": round(float(X[K.S_T]), 3), "x": round(float(X[K.S_X]), 3), "y": round(float(X[K.S_Y]), 3),
               "periods": len(self.rows), "current_ratio": None, "speed_ratio": None, "inferred": "unknown"}
        rows = np.array(self.rows, float).reshape(-1, 4)
        if not len(rows) or rows[:, 1].sum() <= 1e-9 or rows[:, 3].sum() <= 1e-9:
            return out
        ri = rows[:, 0].sum() / rows[:, 1].sum()
        rv = rows[:, 2].sum() / rows[:, 3].sum()
        out.update(current_ratio=round(float(ri), 4), speed_ratio=round(float(rv), 4))
        if ri > 1.0 + EVIDENCE_TOL or rv < 1.0 - EVIDENCE_TOL:
            out["inferred"] = "weaker"
        elif ri < 1.0 - EVIDENCE_TOL:
            out["inferred"] = "stronger"
        else:
            out["inferred"] = "as planned"
        return out


def inference_note(inf: dict) -> str:
    """A stall's inference (:meth:`Evidence.infer`) in words."""
    if inf["inferred"] == "unknown":
        return "no period driven before it to compare with the planning model"
    return (f"over the {inf['periods']} periods before it the vehicle drew {inf['current_ratio']:.2f} x the "
            f"predicted current at {inf['speed_ratio']:.2f} x the predicted speed: {inf['inferred']}")


def stall_failure(stalls: list, name: str, inferred: dict | None) -> str:
    """Why a run failed after its stalls: weaker than the planning model, unless what was
    measured before the last stall says otherwise (:meth:`Evidence.infer`)."""
    if inferred is None or inferred["inferred"] in ("weaker", "unknown"):
        return weaker(stalls, name) + (f" ({inference_note(inferred)})" if inferred else "")
    where = ", ".join(f"({a:.1f}, {b:.1f})" for a, b in stalls)
    return (f"the vehicle stalled {len(stalls)} time{'s' if len(stalls) > 1 else ''}, at {where}, where the plans of "
            f"{name} predicted it would get through; {inference_note(inferred)}: the ways the plans took there do "
            f"not hold for it at the controller rate, though it is not weaker than the planning model")


FIT = ("mass", "v_max", "current_limit", "grip", "mu_roll")   # what the online fit scales (fit)
FIT_PRIOR = 0.15          # relative sd of the fit's prior: the factors stay near 1 unless the periods say
FIT_BOUNDS = (0.5, 2.0)   # the least and largest factor
FIT_EVERY = 20            # compare every 20th row of a period (20 ms at 1 kHz)
FIT_SCALE = (0.3, 0.3, 0.15)   # rad/s of a wheel speed, A of a current per A of current limit x this: the residuals' units
FIT_MIN_PERIODS = 3


def scaled(world: WO.World, f: dict) -> WO.World:
    """``world`` with its vehicle's mass and inertia times ``f['mass']``, its ``v_max``
    (the battery voltage, eq. 27) and ``current_limit`` times theirs, every terrain's
    mu_sa and mu_op times ``f['grip']`` and mu_roll times ``f['mu_roll']`` (missing: 1)."""
    v = world.vehicle
    m, vm, im = f.get("mass", 1.0), f.get("v_max", 1.0), f.get("current_limit", 1.0)
    g, r = f.get("grip", 1.0), f.get("mu_roll", 1.0)
    ts = tuple(t.replace(mu_sa=t.mu_sa * g, mu_op=t.mu_op * g, mu_roll=t.mu_roll * r) for t in world.terrains)
    return replace(world, vehicle=v.replace(mass=v.mass * m, inertia=v.inertia * m, v_max=v.v_max * vm,
                                            current_limit=v.current_limit * im), terrains=ts)


def fit(evidence: "Evidence", world: WO.World, cost: str) -> dict | None:
    """The vehicle as the periods driven measured it: factors of ``FIT`` (mass with
    inertia, v_max, current limit, grip, mu_roll) on the planning ``world``'s, by least squares of each
    period replayed from the measured state it began from, at the controller rate,
    against the wheel speeds and currents measured (every FIT_EVERY-th row; units
    FIT_SCALE; a period weighs as one sample per channel), with a prior of relative sd FIT_PRIOR around 1 (a factor the periods do
    not excite stays near 1). Returns {factor: value, "se": {factor: relative standard
    error}, "cost": final cost, "periods": n}, or None with fewer than FIT_MIN_PERIODS
    periods."""
    from scipy.optimize import least_squares
    periods = list(evidence.periods)
    if len(periods) < FIT_MIN_PERIODS:
        return None
    imax = world.vehicle.current_limit
    sw, si = FIT_SCALE[0], FIT_SCALE[2] * imax

    def residuals(u):
        f = dict(zip(FIT, np.exp(u)))
        ex = Executor(scaled(world, f), cost)
        out = [u / FIT_PRIOR]
        for X0, control, meas, idx in periods:
            rec, _, _ = ex.step(X0, control)
            sim = rec[idx[idx < len(rec)]]
            if len(sim) < len(meas):        # the model stalled or tipped before the period's end: it stays there
                sim = np.vstack([sim, np.repeat(sim[-1:], len(meas) - len(sim), axis=0)])
            n = len(meas)
            w = 1.0 / np.sqrt(n)        # a period weighs as one sample per channel (its rows are correlated)
            out += [w * (sim[:n, K.R_WL] - meas[:n, K.R_WL]) / sw, w * (sim[:n, K.R_WR] - meas[:n, K.R_WR]) / sw,
                    w * (sim[:n, K.R_IL] - meas[:n, K.R_IL]) / si, w * (sim[:n, K.R_IR] - meas[:n, K.R_IR]) / si]
        return np.nan_to_num(np.concatenate(out))       # (a channel a robot did not measure: no residual)
    lo, hi = np.log(FIT_BOUNDS[0]), np.log(FIT_BOUNDS[1])
    res = least_squares(residuals, np.zeros(len(FIT)), bounds=(np.full(len(FIT), lo), np.full(len(FIT), hi)),
                        diff_step=1e-3, max_nfev=40)
    out = {k: round(float(np.exp(x)), 4) for k, x in zip(FIT, res.x)}
    # standard errors (relative: the factors are fitted as logarithms) from the Jacobian,
    # the residuals' scale estimated from the fit (the prior rows included: at most FIT_PRIOR)
    J = res.jac
    dof = max(1, len(res.fun) - len(FIT))
    try:
        cov = np.linalg.inv(J.T @ J) * (2.0 * res.cost / dof)
        se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        se = np.full(len(FIT), FIT_PRIOR)
    out.update(se={k: round(float(e), 4) for k, e in zip(FIT, se)}, cost=round(float(res.cost), 3),
               periods=len(periods))
    return out


def key(fitted: dict) -> tuple:
    """A fit's factors (:data:`FIT`) rounded to 0.01: the key of :func:`as_measured`
    (re-plans share its grids and value)."""
    return tuple(round(fitted[k], 2) for k in FIT)


def as_measured(world: WO.World, factors: tuple, margin: float | None = None) -> WO.World:
    """The planning world scaled by the online fit's factors (:data:`FIT`, :func:`scaled`),
    named by those beyond 2 %, its ``planner.margin`` ``margin`` where given and not the
    file's (:func:`firmed_margin`). Cached per world, factors (rounded to 0.01: re-plans
    share its grids and value) and margin (the file's margin given is none given: one
    world)."""
    if margin is not None and margin == world.scenario.planner.margin:
        margin = None
    return _as_measured(world, tuple(factors), margin)


@functools.lru_cache(maxsize=16)
def _as_measured(world: WO.World, factors: tuple, margin: float | None) -> WO.World:
    f = dict(zip(FIT, factors))
    w = scaled(world, f)
    said = [f"{k} x{x:.2f}" for k, x in f.items() if abs(x - 1.0) > 0.02]
    ps = world.scenario.planner
    if margin is not None:
        w = replace(w, scenario=replace(w.scenario, planner=replace(ps, margin=float(margin))))
        said.append(f"margin {margin:.2f}")
    return replace(w, vehicle=w.vehicle.replace(
        name=f"{world.vehicle.name} as measured" + (f" ({', '.join(said)})" if said else "")))


MARGIN_FLOOR = 0.05   # the least planner.margin an estimate leaves (below)
MARGIN_SE = 2.0       # ... and the standard errors of the twin's factors it covers


def firmed_margin(world: WO.World, f: dict) -> float:
    """``planner.margin`` for plans made for the vehicle as fitted (:func:`fit`): the
    margin's twin scales mass (with inertia) and grip, which the fit now knows to its
    standard errors, so the margin covers ``MARGIN_SE`` of the larger of the two (rounded
    up to 0.01), never more than the file's and never less than ``MARGIN_FLOOR``: the fit
    says nothing of the map's error (5 cm of height error is about 1.4 deg of slope on
    hills_field), nor of the ground ahead of where the vehicle drove. A factor the periods
    do not excite keeps the prior's standard error (``FIT_PRIOR`` 0.15), and the file's
    margin with it."""
    m = world.scenario.planner.margin
    se = max(f["se"]["mass"], f["se"]["grip"])
    return min(m, max(MARGIN_FLOOR, math.ceil(100.0 * MARGIN_SE * se - 1e-9) / 100.0))


def adapts(world: WO.World, f: dict | None, planned: tuple, firm: bool) -> WO.World | None:
    """The vehicle as measured (:func:`as_measured`) that an adaptation plans for from
    here on, or None where the fit ``f`` (:func:`fit`; None: none) is not
    :func:`confident` or says the vehicle planned for: ``planned`` = (its factors
    (:func:`key`), its margin), the factors each within 3 % and the margin the same. With
    ``firm`` (``run.firm_margin``, and no stall in this run: after one the plans are made
    for the margin's twin, the model having proved wrong) the margin firms with the
    estimate (:func:`firmed_margin`); else the file's stays."""
    if f is None or not confident(f):
        return None
    margin = firmed_margin(world, f) if firm else world.scenario.planner.margin
    factors, was = planned
    if max(abs(a - b) for a, b in zip(key(f), factors)) <= 0.03 and abs(margin - was) < 0.005:
        return None
    return as_measured(world, key(f), margin)


def firms(settings, stalled: bool, twin: bool) -> bool:
    """Whether an adaptation's margin firms with its estimate (:func:`adapts`' ``firm``):
    ``run.firm_margin`` (``settings``: the run settings) and before any stall of the run,
    the plans not made for the margin's twin (after a stall the model proved wrong)."""
    return bool(settings.firm_margin) and not stalled and not twin


def at_stall(world: WO.World, base: WO.World, factors: tuple) -> WO.World:
    """The vehicle whose margin's twin a stall's plans are made for: ``base`` (``world``
    itself, or as measured with ``factors``, :func:`key`) with the file's margin. A stall
    shows the model wrong where the plans drove it: a margin an adaptation firmed
    (:func:`adapts`) goes back to the file's, and the twin scales by 1 + that."""
    if base is world or base.scenario.planner.margin == world.scenario.planner.margin:
        return base
    return as_measured(world, factors)


def confident(f: dict, tol: float = 0.05) -> bool:
    """Whether a fit (:func:`fit`) pins every factor it moved more than 3 % from 1 to a
    relative standard error within ``tol``."""
    return all(f["se"][k] <= tol for k in FIT if abs(f[k] - 1.0) > 0.03)
