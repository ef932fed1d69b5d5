"""What the simulation gets wrong on a measured run, and why.

1. :func:`replay` drives the closed-loop model with the logged commands, each segment
   from its measured initial wheel speeds (the controller in steady state there), and
   samples the prediction at the logged times.
2. Errors are per channel (wheel speeds; torques, or currents when torques are absent)
   in units of that channel's sensor noise, estimated from the data itself (the
   spread of sample-to-sample differences), so 1.0 means "explained within the noise".
3. Every candidate of :data:`CANDIDATES`, a physical change to the closed-loop model
   with one or two parameters, is fitted on the training part (the first 70 % of the
   run in time, at most its first FIT_WINDOW_S seconds) by least squares, or by a grid where the objective is flat between
   steps (the delay, down to one replay step). It is then scored on the held-out last
   30 %.
4. The cause is the candidate with the largest held-out gain (1 - extended / baseline
   error) when the evidence for it is very strong (:func:`_decides`): gain at least
   :data:`MARGIN`, and the BIC falls by more than :data:`EVIDENCE` on the training part
   and on the held-out part (:func:`heldout_evidence`: the likelihood ratio of the
   held-out residuals, their samples counted by their autocorrelation). Otherwise the
   cause is ``none``.

Evidence reported with each candidate: the held-out error and gain, the BIC change on
the training part, the parameters with standard errors (from the least-squares
Jacobian), and the Ljung-Box whiteness statistic of the held-out residuals before and
after. The diagnosis also reports the baseline's error by regime (steady or transient,
straight or turning, early or late) and the peak cross-correlation of the residuals
with the commands over lags, and, when the run logs a pose (x, y, yaw), the relative
pose error of the baseline and of the extended model on the held-out part
(:func:`pose_error`: the predicted motion over 2 s windows against the measured one;
the replay starts each segment at its measured pose). The pose is reported, not fitted:
dead-reckoned pose errors grow with time and would outweigh the drive's channels.

Candidates that depend on where the vehicle points use the logged heading where the run
has one: with a pose, ``grade`` is also fitted as a plane fixed in the world
(:func:`heading_pitch`: the grade felt along the logged heading, never a predicted
heading that drifts), and the form with the lower training BIC is kept.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from .params import Terrain, Vehicle
from .runs import Run, currents_unsigned, pose_updates
from .simulate import Model, simulate
from .synth import apply

MARGIN = 0.05          # least held-out gain that names a cause (with the evidence below)
EVIDENCE = 10.0        # held-out BIC change (heldout_evidence) below -EVIDENCE: very strong evidence
REACH_MIN = 0.05       # noise units: a candidate that moves the held-out prediction less is untested there
TRAINING_EVIDENCE = 200.0   # evidence (heldout_evidence) on the one part that names an effect the
                            # other part cannot test
TIE = 0.02             # gains closer than this to the named cause's: a rival within noise
SHARE_MIN = 0.5        # a cause is named where it explains at least this share of the excess over the noise
                       # (runs of an independent implementation, bench/bench_independent.py: the right causes
                       # explained 0.58-1.0 of it; turning_friction named on a run with no effect, 0.17)
EXCESS_MIN = 2.0       # noise units: a held-out baseline error above this leaves something to explain (our
                       # own runs without an effect: below 1.3; the independent implementation's: 1.4-3.9)
AT_BOUND = 0.01        # a fit within this fraction of its range from a bound "ends at the bound"
TRAIN_FRACTION = 0.7
FIT_WINDOW_S = 120.0   # s: fits use at most the first 120 s of the training part (speed)
REPLAY_DT = 0.001      # s: the controller period of the P3-AT; the replay uses the vehicle's own

PROFILED = {"actuator_lag": 0.005, "shear_relaxation": 0.02}   # time constants: profile from this [s]
PROFILE_POINTS = 9

# name -> (parameter names, lower bounds, upper bounds, start, grid step or 0)
CANDIDATES = {
    "command_delay": (("delay_s",), (0.0,), (0.5,), (0.1,), 0.025),
    "actuator_lag": (("lag_s",), (0.0,), (0.3,), (0.03,), 0.0),
    "wheel_radius": (("scale_left", "scale_right"), (0.7, 0.7), (1.3, 1.3), (1.0, 1.0), 0.0),
    "viscous_friction": (("c_Nms",), (-1.0,), (3.0,), (0.1,), 0.0),
    "voltage_sag": (("sag_V_per_kJ",), (0.0,), (5.0,), (0.3,), 0.0),
    "shear_relaxation": (("tau_s",), (0.0,), (2.0,), (0.2,), 0.0),
    "grade": (("grade_deg",), (-20.0,), (20.0,), (0.0,), 0.0),
    # sbmpc's own candidate: one scale on the terrain's mu_sa and mu_op (turning friction)
    "turning_friction": (("mu_scale",), (0.1,), (3.0,), (1.0,), 0.0),
    # the motors' no-load current (last: the order seeds tests/test_diagnose.py's runs)
    "no_load_current": (("i0_A",), (0.0,), (20.0,), (0.5,), 0.0),
}
# ``grade`` as a plane fixed in the world (runs with a pose): its rise per metre east and
# north [-] (tangents; +-0.36 is 20 deg), the pitch from the logged heading (heading_pitch)
WORLD_GRADE = "grade (world)"
WORLD_GRADE_SPEC = (("slope_east", "slope_north"), (-0.36, -0.36), (0.36, 0.36), (0.0, 0.0), 0.0)


def _spec(key: str) -> tuple:
    """A candidate's (parameter names, lower bounds, upper bounds, start, grid step)."""
    return WORLD_GRADE_SPEC if key == WORLD_GRADE else CANDIDATES[key]


def has_pose(run: Run) -> bool:
    """Whether the run logs a pose: x, y and yaw, each with a value (``Run.__contains__``)."""
    return all(c in run for c in ("x", "y", "yaw"))


def heading_pitch(yaw, slope_east: float, slope_north: float) -> np.ndarray:
    """The grade beta [rad] of eq. 24 that a vehicle feels along its heading ``yaw``
    [rad] (counter-clockwise from east), shape of ``yaw``, on a plane z = slope_east x +
    slope_north y (tangents [-]): the plane's rise per metre along the heading is
    slope_east cos(yaw) + slope_north sin(yaw), so beta = atan of that. Driving up its
    steepest direction the vehicle feels atan(hypot(slope_east, slope_north)), across it
    nothing."""
    yaw = np.asarray(yaw, float)
    return np.arctan(slope_east * np.cos(yaw) + slope_north * np.sin(yaw))


def world_grade(slope_east: float, slope_north: float, se=(math.nan, math.nan)) -> tuple:
    """The plane's steepest grade and the heading that climbs it, {"grade_deg",
    "toward_deg"} [deg] (toward in [0, 360)), and their standard errors from those of the
    slopes ``se`` (first-order propagation; the heading's is NaN on a flat plane)."""
    h = math.hypot(slope_east, slope_north)
    g = math.degrees(math.atan(h))
    toward = math.degrees(math.atan2(slope_north, slope_east)) % 360.0 if h > 0 else 0.0
    se_e, se_n = se
    if h > 1e-12:
        se_g = math.degrees(math.hypot(slope_east * se_e, slope_north * se_n) / h / (1.0 + h * h))
        se_t = math.degrees(math.hypot(slope_north * se_e, slope_east * se_n) / (h * h))
    else:
        se_g, se_t = math.degrees(max(se_e, se_n)), math.nan
    return {"grade_deg": g, "toward_deg": toward}, {"grade_deg": se_g, "toward_deg": se_t}


def _least_squares(fun, x0, lo, hi, diff_step: float, max_nfev: int, with_cost: bool = False) -> tuple:
    """Bounded least squares of the residual vector ``fun(x)``: (x, standard errors from
    the Jacobian at the optimum, NaN where it is singular), and half the residual sum of
    squares at x when ``with_cost``."""
    res = least_squares(fun, np.clip(np.asarray(x0, float), lo, hi), bounds=(np.asarray(lo, float), np.asarray(hi, float)),
                        diff_step=diff_step, x_scale="jac", max_nfev=max_nfev)
    J = res.jac
    m, k = J.shape
    s2 = float(np.sum(res.fun ** 2)) / max(m - k, 1)
    try:
        se = np.sqrt(np.maximum(np.diag(np.linalg.inv(J.T @ J) * s2), 0.0))
    except np.linalg.LinAlgError:
        se = np.full(k, math.nan)
    return (res.x, se, float(res.cost)) if with_cost else (res.x, se)


def start_points(x0, lo, hi, n: int) -> np.ndarray:
    """``n`` starting points for a bounded fit, shape (n, k): ``x0`` first, then the
    points of an unscrambled Halton sequence spread over the box [lo, hi] (deterministic:
    the same fit gives the same answer)."""
    x0, lo, hi = (np.asarray(a, float) for a in (x0, lo, hi))
    pts = [np.clip(x0, lo, hi)]
    if n > 1:
        from scipy.stats import qmc
        u = qmc.Halton(d=x0.size, scramble=False).random(2 * n)[1:]   # its first point is the origin
        far = [p for p in lo + u * (hi - lo) if np.any(np.abs(p - pts[0]) > 1e-6 * (hi - lo))]
        pts.extend(far[:n - 1])
    return np.array(pts)


def calibrate(run: Run, vehicle: Vehicle, terrain: Terrain, fields: dict, mask=None, max_nfev: int = 30,
              starts: int = 1) -> tuple:
    """Least-squares calibration of vehicle fields ({name: (low, high)}) on the wheel-speed
    (and torque or current) replay of ``run`` (restricted to ``mask``).

    ``starts``: the fit is run from the vehicle's own values and from ``starts - 1``
    further points spread over the bounds (``start_points``), each for at most
    ``max_nfev`` replays, and the lowest residual kept: a replay's residual has several
    local minima over saturation limits, and one start may settle in another. Returns
    the calibrated vehicle, {name: (value, standard error)} and the optima reached,
    best first: [{"cost": half the residual sum of squares (noise units), name: value,
    ...}, ...]."""
    chans = channels(run)
    scales = {c: noise_scale(run[c]) for c in chans}
    mask = np.ones(len(run), bool) if mask is None else mask
    names = list(fields)
    x0 = np.array([getattr(vehicle, n) for n in names], float)
    lo = np.array([fields[n][0] for n in names], float)
    hi = np.array([fields[n][1] for n in names], float)

    def fun(x):
        v = vehicle.replace(**dict(zip(names, map(float, x))))
        return _residuals(run, replay(run, v, terrain), chans, scales, mask)

    fits = sorted((_least_squares(fun, p, lo, hi, 1e-2, max_nfev, with_cost=True)
                   for p in start_points(x0, lo, hi, max(int(starts), 1))), key=lambda f: f[2])
    x, se, _ = fits[0]
    v = vehicle.replace(**dict(zip(names, map(float, x))))
    optima = [{"cost": c, **{n: float(a) for n, a in zip(names, xs)}} for xs, _, c in fits]
    return v, {n: (float(a), float(e)) for n, a, e in zip(names, x, se)}, optima


def channels(run: Run) -> tuple:
    """The channels compared: wheel speeds, and torques (or currents when no torques)."""
    ch = ["wl", "wr"]
    if "tau_l" in run and "tau_r" in run:
        ch += ["tau_l", "tau_r"]
    elif "i_l" in run and "i_r" in run:
        ch += ["i_l", "i_r"]
    return tuple(ch)


def is_held(y: np.ndarray) -> bool:
    """Whether a sampled signal is held or quantised: most sample-to-sample differences
    are exactly zero (a slower sensor logged at a faster rate, or coarse steps)."""
    d = np.diff(y[np.isfinite(y)])
    return d.size >= 3 and np.count_nonzero(d) < 0.5 * d.size


def noise_scale(y: np.ndarray) -> float:
    """Standard deviation of white sensor noise on a sampled signal, from the median
    absolute sample-to-sample difference (robust to the signal's own steps)."""
    d = np.diff(y[np.isfinite(y)])
    if d.size < 3:
        return 1.0
    nz = d[d != 0.0]
    floor = 1e-9
    if nz.size < 0.5 * d.size:      # a held (slower sensor) or quantised signal: use its changes
        d = nz if nz.size >= 3 else d
        if nz.size:
            # at least the rounding noise of its smallest step (the quantum) / sqrt(12): a
            # quantised speed whose steps mostly go one way has a median absolute deviation
            # of 0 (BorealTC's Husky at a steady speed: errors of 6e7 noise units)
            floor = max(floor, float(np.min(np.abs(nz))) / math.sqrt(12.0))
    s = 1.4826 * float(np.median(np.abs(d - np.median(d)))) / math.sqrt(2.0)
    return s if s > floor else floor


def replay(run: Run, vehicle: Vehicle, terrain: Terrain, pitch=0.0, dt: float = REPLAY_DT) -> dict:
    """Predicted channels at the run's times (NaN where no segment covers them; the
    currents as magnitudes where the run logs them so, :func:`dynamics.runs.currents_unsigned`).
    ``pitch`` [rad]: the grade, one for the run or one per sample (each step of the
    replay takes the last sample's)."""
    model = Model(vehicle, terrain, dt)
    per_sample = np.ndim(pitch) > 0
    n = len(run)
    out = {c: np.full(n, np.nan) for c in ("wl", "wr", "tau_l", "tau_r", "i_l", "i_r", "x", "y", "yaw")}
    pose = has_pose(run)
    t_all = run.t
    noise = (noise_scale(run["wl"]), noise_scale(run["wr"]))
    white = not (is_held(run["wl"]) or is_held(run["wr"]))
    for a, b in run.segments():
        t = t_all[a:b]
        cl = _ffill(run["wl_cmd"][a:b])
        cr = _ffill(run["wr_cmd"][a:b])
        k = int(round((t[-1] - t[0]) / dt)) + 1
        tk = t[0] + dt * np.arange(k)
        j = np.clip(np.searchsorted(t, tk + 1e-9, side="right") - 1, 0, len(t) - 1)
        measured = np.isfinite(run["wl"][a]) and np.isfinite(run["wr"][a])
        w0l = run["wl"][a] if np.isfinite(run["wl"][a]) else cl[0]
        w0r = run["wr"][a] if np.isfinite(run["wr"][a]) else cr[0]
        if measured and white:         # (a held or quantised log's noise is its own steps)
            w0l, w0r = start_speeds(float(w0l), float(w0r), *noise)
        p0 = [float(run[c][a]) if pose and np.isfinite(run[c][a]) else 0.0 for c in ("x", "y", "yaw")]
        p = _ffill(np.asarray(pitch, float)[a:b])[j] if per_sample else pitch
        S = model.state(float(w0l), float(w0r), float(p[0]) if per_sample else p, p0[0], p0[1], p0[2])
        tr = simulate(model, cl[j], cr[j], state=S, pitch=p, record_dt=dt, dt=dt)
        ts = t[0] + tr.t
        for c in out:
            out[c][a:b] = np.interp(t, ts, tr.data[c])
    if currents_unsigned(run):      # a log of magnitudes is compared with magnitudes
        out["i_l"], out["i_r"] = np.abs(out["i_l"]), np.abs(out["i_r"])
    return out


START_NOISE_CAP = 0.1   # rad/s: the most start_speeds takes for noise (a few mm/s at the rim)


def start_speeds(wl: float, wr: float, noise_l: float, noise_r: float) -> tuple:
    """The wheel speeds [rad/s] a segment's replay starts from, in steady state (``Model.state``),
    given the first measured ones and the sensors' noise [rad/s]. A difference between
    the wheels within twice its noise is taken as none, and speeds within twice their
    noise of zero as rest: a steady turn holds the full sliding turning resistance in the
    PID integrals at any yaw rate (eq. 28's friction does not fade with the rate), so a
    noise-sized difference would start a straight run in a turn that the PID takes
    seconds to unwind (a clean 2 s run from rest was named turning_friction). Each
    bound is at most START_NOISE_CAP, and :func:`replay` applies it only to logs with
    white noise: on held or quantised ones (the Warthog's 4 Hz speeds, BorealTC's
    1/127 m/s) the noise estimate is made of the signal's own steps (0.35 rad/s), a real
    start of 12.5 and 12.9 rad/s is a turn, and straightening such starts moved the
    Warthog's sand calibration to another optimum (47 A instead of 64 A)."""
    if abs(wl - wr) < min(2.0 * math.hypot(noise_l, noise_r), START_NOISE_CAP):
        wl = wr = 0.5 * (wl + wr)
    if abs(wl) < min(2.0 * noise_l, START_NOISE_CAP) and abs(wr) < min(2.0 * noise_r, START_NOISE_CAP):
        wl = wr = 0.0
    return wl, wr


def _ffill(x: np.ndarray) -> np.ndarray:
    x = x.copy()
    ok = np.isfinite(x)
    if not ok.any():
        return np.zeros_like(x)
    idx = np.where(ok, np.arange(len(x)), 0)
    np.maximum.accumulate(idx, out=idx)
    x = x[idx]
    x[~np.isfinite(x)] = x[ok][0]
    return x


@dataclass
class Candidate:
    effect: str
    params: dict
    stderr: dict
    heldout_error: float
    gain: float
    bic_delta: float
    whiteness_q: float
    at_bound: tuple = ()      # parameters whose fit ended at a bound of the candidate's range
    fitted_on: str = "channels"   # "pose": fitted to the relative pose errors; "heldout": to the
                                  # channels of the held-out part (the training part cannot see it)
    pose_gain: float | None = None   # 1 - held-out RPE extended / baseline (the better of heading, translation)
    evidence: float = math.nan   # held-out BIC change (heldout_evidence): below -EVIDENCE names the cause
    reach: float = math.nan      # held-out RMS change of the prediction from the baseline's, noise units
    train_evidence: float = math.nan   # as ``evidence``, on the training part
    train_reach: float = math.nan      # as ``reach``, on the training part
    train_error: float = math.nan      # as ``heldout_error``, on the training part
    key: str = ""             # the fitted form (CANDIDATES' name, or WORLD_GRADE) and its parameters
    x: tuple = ()             # in that form's units (_model_for); set by diagnose


def at_bound(effect: str, params: dict) -> tuple:
    """The parameters of a fitted candidate that ended at (within AT_BOUND of its range
    from) a bound: the fit may want a value the candidate does not allow. A bound of 0
    (no delay, no lag, no sag) is the model without the effect, not a limit. ``effect``
    may be WORLD_GRADE with its slopes as ``params``."""
    names, lo, hi, _, _ = _spec(effect)
    out = []
    for n, a, b in zip(names, lo, hi):
        x = params[n]
        tol = AT_BOUND * (b - a)
        if (a != 0.0 and x - a <= tol) or (b != 0.0 and b - x <= tol):
            out.append(n)
    return tuple(out)


def bound_side(effect: str, name: str, value: float) -> str:
    """'lower' or 'upper': the bound of ``effect``'s range for parameter ``name`` that
    ``value`` is nearer (for :func:`at_bound`'s parameters: the one the fit ended at)."""
    names, lo, hi, _, _ = CANDIDATES[effect]
    a, b = lo[names.index(name)], hi[names.index(name)]
    return "lower" if value - a <= b - value else "upper"


@dataclass
class Diagnosis:
    """The result of :func:`diagnose` (docs/formats.md diagnosis JSON via :meth:`to_json`)."""

    channels: tuple
    scales: dict
    baseline_error: float
    baseline_rmse: dict
    baseline_whiteness_q: float
    candidates: list
    cause: str
    gain: float
    where: dict = field(default_factory=dict)
    xcorr: dict = field(default_factory=dict)
    extended_vehicle: Vehicle | None = None
    extended_pitch_deg: float = 0.0
    extended_terrain: Terrain | None = None
    pose: dict = field(default_factory=dict)     # {"baseline": RPE, "extended": RPE} on the held-out part
    rivals: tuple = ()     # other candidates within TIE of the named cause's gain (also above MARGIN)
    decided_on: str | None = None   # "heldout", "training" (the held-out part cannot test it),
                                    # "heldout_only" (the training part cannot) or "pose"
    share: float | None = None      # the share of the excess over the noise the best candidate explains
    hint: str | None = None         # cause "unexplained": the candidate that explains the most of it
    residual: dict = field(default_factory=dict)   # what is left to explain: size and where it sits
    extended_slope: tuple | None = None   # cause grade as a plane fixed in the world: (slope_east,
                                          # slope_north) [-]; extended_pitch_deg is then its steepest grade

    def extended_pitch(self, run: Run):
        """The grade [rad] of the extended model on ``run``: one number, or one per sample
        from the logged heading for a grade fixed in the world."""
        if self.extended_slope is None:
            return math.radians(self.extended_pitch_deg)
        return _world_pitch(run, self.extended_slope)

    @property
    def extended_toward_deg(self) -> float | None:
        """For a grade fixed in the world, the heading [deg] that climbs it; else None."""
        return None if self.extended_slope is None else world_grade(*self.extended_slope)[0]["toward_deg"]

    def to_json(self, extended_path: str | None = None) -> dict:
        return {
            "schema": "sbmpc.diagnosis/1",
            "baseline": {"heldout_error": self.baseline_error, "rmse": self.baseline_rmse,
                         "whiteness_q": self.baseline_whiteness_q, "where": self.where, "xcorr": self.xcorr},
            "candidates": [{"effect": c.effect, "params": c.params, "stderr": c.stderr,
                            "heldout_error": c.heldout_error, "gain": c.gain, "bic_delta": c.bic_delta,
                            "whiteness_q": c.whiteness_q, "at_bound": list(c.at_bound), "fitted_on": c.fitted_on,
                            "pose_gain": c.pose_gain,
                            "evidence": None if math.isnan(c.evidence) else c.evidence,
                            "reach": None if math.isnan(c.reach) else c.reach,
                            "train_evidence": None if math.isnan(c.train_evidence) else c.train_evidence,
                            "train_reach": None if math.isnan(c.train_reach) else c.train_reach}
                           for c in self.candidates],
            "cause": self.cause,
            "explained_share": self.share,
            "share_threshold": SHARE_MIN,
            "hint": self.hint,
            "residual": self.residual,
            "rivals": list(self.rivals),
            "gain": self.gain,
            "margin": MARGIN,
            "evidence_threshold": EVIDENCE,
            "decided_on": self.decided_on,
            "channels": list(self.channels),
            "noise_scales": self.scales,
            "extended_vehicle": extended_path,
            "extended_grade_deg": self.extended_pitch_deg,
            "extended_grade_toward_deg": self.extended_toward_deg,
            "pose_error": self.pose,
            "extended_terrain": None if self.extended_terrain is None else
            {"name": self.extended_terrain.name, "mu_sa": self.extended_terrain.mu_sa,
             "mu_op": self.extended_terrain.mu_op},
        }


def _world_pitch(run: Run, slope) -> np.ndarray:
    """The grade [rad] per sample of ``run`` on the plane ``slope`` (slope_east,
    slope_north), felt along the run's logged heading (:func:`heading_pitch`)."""
    return heading_pitch(_ffill(run["yaw"]), float(slope[0]), float(slope[1]))


def _residuals(run, pred, chans, scales, mask):
    parts = []
    for c in chans:
        r = (run[c] - pred[c]) / scales[c]
        parts.append(r[mask])
    r = np.concatenate(parts)
    return r[np.isfinite(r)]


def effective_samples(r: np.ndarray, max_lag: int = 200) -> float:
    """Effective number of independent samples of a residual series [-]: n / (1 + 2 sum
    rho_k) over the lags k up to where the autocorrelation rho_k first falls below 0.05
    (at most ``max_lag``; Bartlett). Residuals that a model explains down to white noise
    count fully; a slow remaining misfit counts as few samples."""
    r = r[np.isfinite(r)]
    n = r.size
    if n < 8:
        return float(n)
    r = r - r.mean()
    den = float(np.dot(r, r))
    if den <= 0.0:
        return float(n)
    s = 0.0
    for k in range(1, min(max_lag, n // 4) + 1):
        rho = float(np.dot(r[:-k], r[k:])) / den
        if rho < 0.05:
            break
        s += rho
    return n / (1.0 + 2.0 * s)


def heldout_evidence(run, pred, chans, scales, mask, gain: float, k: int) -> float:
    """The held-out evidence for a candidate as a BIC change [-] (negative: for it):
    2 n_eff ln(1 - gain) + k ln(n_eff), the Gaussian likelihood ratio of the held-out
    residuals in noise units with the samples counted as independent only as far as the
    extended model's residuals are (:func:`effective_samples`, summed over channels),
    less the candidate's k parameters. Below -10: very strong evidence."""
    if gain >= 1.0:
        return -math.inf
    n_eff = sum(effective_samples(((run[c] - pred[c]) / scales[c])[mask]) for c in chans)
    return 2.0 * n_eff * math.log(1.0 - gain) + k * math.log(max(n_eff, 1.0))


def _error(run, pred, chans, scales, mask):
    """Mean over channels of the RMS residual in noise units."""
    errs = []
    for c in chans:
        r = ((run[c] - pred[c]) / scales[c])[mask]
        r = r[np.isfinite(r)]
        errs.append(math.sqrt(float(np.mean(r * r))) if r.size else math.nan)
    return float(np.nanmean(errs))


POSE_WINDOW_S = 2.0   # s: window of the relative pose error


def pose_residuals(run: Run, pred: dict, mask=None, window_s: float = POSE_WINDOW_S):
    """Per window (see :func:`pose_error`): the translation error [m], the heading error
    [rad] and the distance driven [m] of the measured motion, or None without a pose."""
    if not has_pose(run):
        return None
    t = run.t
    seg = np.zeros(len(t), int)
    for k, (a, b) in enumerate(run.segments()):
        seg[a:b] = k
    x, y, yaw = run["x"], run["y"], run["yaw"]
    fresh, upd = pose_updates(x, y, yaw)
    i = np.arange(len(t))
    j = np.searchsorted(t, t + window_s - 1e-9)
    ok = (j < len(t)) & (mask if mask is not None else True)
    i, j = i[ok], j[ok]
    if fresh.mean() < 0.9:
        # a pose held between updates (scan matching): windows run between update samples
        ok = fresh[i]
        i, j = i[ok], upd[j[ok]]
        ok = t[j] - t[i] >= 0.5 * window_s
        i, j = i[ok], j[ok]
    ok = seg[i] == seg[j]
    i, j = i[ok], j[ok]
    if i.size == 0:
        return None

    def rel(x, y, yaw):
        dx, dy = x[j] - x[i], y[j] - y[i]
        c, s_ = np.cos(yaw[i]), np.sin(yaw[i])
        return c * dx + s_ * dy, -s_ * dx + c * dy, yaw[j] - yaw[i]
    mx, my, myaw = rel(run["x"], run["y"], run["yaw"])
    px, py, pyaw = rel(pred["x"], pred["y"], pred["yaw"])
    et = np.hypot(mx - px, my - py)
    er = np.remainder(myaw - pyaw + np.pi, 2 * np.pi) - np.pi
    good = np.isfinite(et) & np.isfinite(er)
    if not good.any():
        return None
    return et[good], er[good], np.hypot(mx, my)[good]


def pose_error(run: Run, pred: dict, mask=None, window_s: float = POSE_WINDOW_S) -> dict | None:
    """Relative pose error (RPE, the odometry benchmarks' metric) of a replay over
    windows of ``window_s`` [s] within segments: how far the predicted motion over a
    window, seen from its start pose, differs from the measured one. Returns
    {"window_s", "trans_rmse_m", "rot_rmse_rad", "trans_per_m"} (trans_per_m: the
    translation error per metre driven), or None when the run has no pose or no window.
    Windows start where ``mask`` is true. A pose held between updates (fewer than 90 %
    of the samples change it) is compared only between update samples."""
    r = pose_residuals(run, pred, mask, window_s)
    if r is None:
        return None
    et, er, dist = r
    return {"window_s": window_s, "trans_rmse_m": float(np.sqrt(np.mean(et ** 2))),
            "rot_rmse_rad": float(np.sqrt(np.mean(er ** 2))),
            "trans_per_m": float(np.sum(et) / max(float(np.sum(dist)), 1e-9))}


POSE_GAIN = 0.5     # a pose-only cause must halve the held-out relative pose error ...
POSE_CHANNEL_SLACK = 0.02   # ... without worsening the other channels by more than this


def _pose_candidate(run, vehicle, terrain, pitch, train, held, chans, scales, base_err, bic0, pe_base):
    """The wheel_radius candidate fitted to the pose (:func:`fit_wheel_radius_to_pose`),
    scored on the held-out part on the channels and on the relative pose error."""
    names = CANDIDATES["wheel_radius"][0]
    x, se = fit_wheel_radius_to_pose(run, vehicle, terrain, pitch, train)
    v, ter, p = _model_for("wheel_radius", x, vehicle, terrain, names)
    pred = replay(run, v, ter, p + pitch)
    pe = pose_error(run, pred, held)
    if pe is None:
        return None
    g_rot = 1.0 - pe["rot_rmse_rad"] / max(pe_base["rot_rmse_rad"], 1e-12)
    g_tr = 1.0 - pe["trans_rmse_m"] / max(pe_base["trans_rmse_m"], 1e-12)
    pose_gain = max(g_rot, g_tr) if min(g_rot, g_tr) >= -0.1 else min(g_rot, g_tr)
    err = _error(run, pred, chans, scales, held)
    params = {n: float(a) for n, a in zip(names, x)}
    gain = _gain(err, base_err)
    return Candidate("wheel_radius", params, {n: float(a) for n, a in zip(names, se)}, err, gain,
                     _bic(_residuals(run, pred, chans, scales, train), len(names)) - bic0,
                     ljung_box(((run["wl"] - pred["wl"]) / scales["wl"])[held]), at_bound("wheel_radius", params),
                     "pose", float(pose_gain), key="wheel_radius", x=tuple(float(a) for a in x))


def fit_wheel_radius_to_pose(run: Run, vehicle: Vehicle, terrain: Terrain, pitch: float, train) -> tuple:
    """The wheel radius scales that best explain the training part's relative pose
    errors (per window: heading in units of its noise, translation in units of its
    noise, both estimated from the baseline's residual spread at the smallest windows),
    by least squares: a tyre's radius shows in the ground motion (the pose), not in the
    wheel speeds the other channels measure. Returns (x, standard errors)."""
    names, lo, hi, x0, _ = CANDIDATES["wheel_radius"]
    last = int(np.flatnonzero(train)[-1]) + 1
    last = min(last, int(np.searchsorted(run.t, run.t[0] + FIT_WINDOW_S)) + 1)
    part = run.slice(0, last)
    tmask = train[:last]
    s_rot = max(noise_scale(part["yaw"]) * math.sqrt(2.0), 1e-4)
    s_tr = max(math.hypot(noise_scale(part["x"]), noise_scale(part["y"])) * math.sqrt(2.0), 1e-4)

    def fun(x):
        v, ter, p = _model_for("wheel_radius", x, vehicle, terrain, names)
        r = pose_residuals(part, replay(part, v, ter, p + pitch), tmask)
        if r is None:
            return np.zeros(1)
        et, er, _ = r
        return np.r_[er / s_rot, et / s_tr]
    return _least_squares(fun, x0, lo, hi, 1e-3, 40)


def ljung_box(r: np.ndarray, lags: int = 20) -> float:
    """Ljung-Box Q statistic of a residual series (large = not white)."""
    r = r[np.isfinite(r)]
    n = r.size
    if n <= lags + 1:
        return math.nan
    r = r - r.mean()
    den = float(np.dot(r, r))
    if den <= 0.0:                 # a constant residual: no autocorrelation to test
        return 0.0
    q = 0.0
    for k in range(1, lags + 1):
        rho = float(np.dot(r[k:], r[:-k])) / den
        q += rho * rho / (n - k)
    return n * (n + 2) * q


def _model_for(effect, x, vehicle, terrain, names, run=None):
    """(vehicle, terrain, pitch) of a candidate at parameters x; WORLD_GRADE's pitch is
    one per sample of ``run``, from its logged heading (:func:`heading_pitch`)."""
    if effect == WORLD_GRADE:
        return vehicle, terrain, _world_pitch(run, x)
    return apply(vehicle, effect, dict(zip(names, x)), terrain)


def fit_candidate(effect, run, vehicle, terrain, chans, scales, train, window_s: float = FIT_WINDOW_S):
    """Fit one candidate on the samples of the mask ``train`` (the training part, or the
    held-out part of a candidate the training part cannot test), replaying the run from
    its start to the mask's last sample but at most ``window_s`` [s]: (x, standard
    errors).

    One parameter: a bounded Brent search of the residual sum of squares, after a coarse
    grid where the objective is flat between steps (the delay, down to one replay step:
    a delay is resolved to the replay's step, 1 ms, not to the log's samples), or within
    the bracket of the best point of a profile over the parameter (time constants:
    log-spaced from PROFILED's smallest value, and 0); the standard error from the
    curvature of that sum at the optimum. Two parameters: least squares, the
    standard errors from its Jacobian."""
    names, lo, hi, x0, step = _spec(effect)
    last = int(np.flatnonzero(train)[-1]) + 1
    last = min(last, int(np.searchsorted(run.t, run.t[0] + window_s)) + 1)
    part = run.slice(0, last)
    tmask = train[:last]

    def fun(x):
        v, ter, pitch = _model_for(effect, x, vehicle, terrain, names, part)
        return _residuals(part, replay(part, v, ter, pitch), chans, scales, tmask)

    if len(names) == 1:
        from scipy.optimize import minimize_scalar
        cost = lambda a: float(np.sum(fun([a]) ** 2))
        a_lo, a_hi = lo[0], hi[0]
        if step > 0:
            # piecewise constant (whole replay steps): nested grids down to one replay step
            g, st = None, step
            grid = np.arange(lo[0], hi[0] + 1e-12, st)
            while True:
                costs = [cost(a) for a in grid]
                g = float(grid[int(np.argmin(costs))])
                if st <= REPLAY_DT * 1.001:
                    break
                st = max(st / 5.0, REPLAY_DT)
                grid = np.arange(max(lo[0], g - 5 * st), min(hi[0], g + 5 * st) + 1e-12, st)
            return np.array([g]), np.array([REPLAY_DT / math.sqrt(12.0)])
        if effect in PROFILED:
            # a profile over the time constant first (log-spaced, and 0): the objective
            # has local minima over it; then the bracket around the profile's best
            grid = np.r_[0.0, np.geomspace(PROFILED[effect], hi[0], PROFILE_POINTS)]
            costs = [cost(a) for a in grid]
            j = int(np.argmin(costs))
            a_lo, a_hi = float(grid[max(j - 1, 0)]), float(grid[min(j + 1, len(grid) - 1)])
        res = minimize_scalar(cost, bounds=(a_lo, a_hi), method="bounded",
                              options={"xatol": 1e-4 * max(abs(hi[0] - lo[0]), 1e-3)})
        x = float(res.x)
        h = max(1e-3 * (hi[0] - lo[0]), 1e-6)
        c0, cp, cm = res.fun, cost(min(x + h, hi[0])), cost(max(x - h, lo[0]))
        curv = (cp - 2 * c0 + cm) / (h * h)
        m = fun([x]).size
        se = math.sqrt(2.0 * c0 / max(m - 1, 1) / curv) if curv > 0 else math.nan
        return np.array([x]), np.array([se])
    if effect == WORLD_GRADE:
        # the residual has local minima over the drive's saturation (a fit from a level
        # plane stopped at 0.4 deg on a 2.5 deg one): start from the best of a polar grid
        # and difference steps of 0.01 (0.6 deg): steps of 0.001 stopped at 2.7 deg, 17 deg off
        x0 = min(_slope_grid(), key=lambda x: float(np.sum(fun(x) ** 2)))
        return _least_squares(fun, x0, lo, hi, 1e-2, 40)
    return _least_squares(fun, x0, lo, hi, 1e-3, 40)


SLOPE_GRID_DEG = (1.5, 4.0, 8.0, 14.0)   # grades [deg] of the world grade's starting grid, 8 headings each


def _slope_grid() -> list:
    """(slope_east, slope_north) of a level plane and of planes rising SLOPE_GRID_DEG
    towards 8 headings 45 deg apart."""
    out = [(0.0, 0.0)]
    for g in SLOPE_GRID_DEG:
        s = math.tan(math.radians(g))
        out.extend((s * math.cos(a), s * math.sin(a)) for a in np.arange(8) * (math.pi / 4))
    return out


def _bic(r, k):
    """Bayesian information criterion of residuals r with k parameters (a floor of 1e-300
    on the mean square keeps an exact fit finite)."""
    n = r.size
    if n == 0:
        return math.nan
    return n * math.log(max(float(np.sum(r * r)) / n, 1e-300)) + k * math.log(n)


def _where(run, pred, chans, scales):
    """Baseline error by regime: steady vs transient, straight vs turning, early vs late."""
    cl, cr = run["wl_cmd"], run["wr_cmd"]
    t = run.t
    change = np.r_[True, (np.abs(np.diff(cl)) + np.abs(np.diff(cr))) > 1e-9]
    last = np.maximum.accumulate(np.where(change, np.arange(len(t)), 0))
    since = t - t[last]
    masks = {
        "transient": since < 1.0, "steady": since >= 1.0,
        "straight": np.abs(cl - cr) <= 0.05 * (np.abs(cl) + np.abs(cr) + 1e-9),
        "turning": np.abs(cl - cr) > 0.05 * (np.abs(cl) + np.abs(cr) + 1e-9),
        "early": t < t[0] + 0.5 * (t[-1] - t[0]), "late": t >= t[0] + 0.5 * (t[-1] - t[0]),
    }
    return {k: _error(run, pred, chans, scales, m) for k, m in masks.items() if m.any()}


def _xcorr(run, pred, scales, max_lag_s=1.0):
    """Peak cross-correlation of the wheel-speed residuals with the commanded wheel-speed
    changes over lags of +-max_lag_s (a delay or lag shows as a peak at a positive lag)."""
    t = run.t
    dt = float(np.median(np.diff(t)))
    L = min(int(round(max_lag_s / dt)), len(t) // 2 - 1)     # lags shorter than half the run
    best = (0.0, 0.0)
    for c in ("l", "r"):
        r = (run[f"w{c}"] - pred[f"w{c}"]) / scales[f"w{c}"]
        u = np.r_[0.0, np.diff(_ffill(run[f"w{c}_cmd"]))]
        ok = np.isfinite(r)
        r = np.where(ok, r - np.nanmean(r), 0.0)
        u = u - u.mean()
        den = math.sqrt(float(np.dot(r, r)) * float(np.dot(u, u))) or 1.0
        for lag in range(-L, L + 1):
            rho = float(np.dot(r[max(lag, 0):len(r) + min(lag, 0)], u[max(-lag, 0):len(u) - max(lag, 0)])) / den
            if abs(rho) > abs(best[0]):
                best = (rho, lag * dt)
    return {"peak_rho": best[0], "lag_s": best[1]}


def _decides(c: Candidate) -> str | None:
    """On what candidate c names the cause, if it does: "heldout" when its held-out gain
    is at least MARGIN (what a right but not identical model leaves: another
    integration step, parameters a few per cent off, gains up to about 0.04 on
    generated runs) and the evidence for it is very strong on both parts of the run:
    the training BIC and the held-out BIC (:func:`heldout_evidence`, samples counted by
    their autocorrelation) each fall by more than EVIDENCE. When one part cannot test
    it (its prediction there moves by less than REACH_MIN noise units from the
    baseline's), the other decides alone, with a much higher bar (its evidence, samples
    counted by their autocorrelation, falls by more than TRAINING_EVIDENCE): "training"
    when the held-out part cannot (say a turning effect and a held-out part that drives
    straight; the fit has seen these data), "heldout_only" when the training part
    cannot (say a voltage sag that grows with the energy drawn and limits the drive only
    late in the run: :func:`diagnose` then fits it on the held-out part,
    ``fitted_on="heldout"``), there also with a gain of at least MARGIN. Else None."""
    if c.reach < REACH_MIN:
        return "training" if c.train_evidence < -TRAINING_EVIDENCE else None
    if c.gain < MARGIN:
        return None
    if c.fitted_on == "heldout":
        return "heldout_only" if c.evidence < -TRAINING_EVIDENCE else None
    if c.bic_delta < -EVIDENCE and not c.evidence >= -EVIDENCE:
        return "heldout"
    return None


def explained_share(base_err: float, err: float) -> float:
    """The share of the baseline's excess over the noise that a candidate explains: errors
    are RMS in noise units, so the excess variance is base_err^2 - 1, and the candidate
    leaves err^2 - 1 of it (0 below the noise). 0 where there is no excess."""
    excess = base_err * base_err - 1.0
    if not excess > 0.0:
        return 0.0
    return float(min(max((excess - max(err * err - 1.0, 0.0)) / excess, 0.0), 1.0))


def _sides(run, pred, chans, scales, mask) -> dict:
    """Held-out error [noise units] of the left and the right channels."""
    out = {}
    for side, tag in (("left", "l"), ("right", "r")):
        cs = [c for c in chans if c.endswith(tag)]
        if cs:
            out[side] = _error(run, pred, cs, scales, mask)
    return out


def _gain(err: float, base_err: float) -> float:
    """The fraction of the baseline's error a candidate removes (0 where the baseline's
    error is 0: a run with nothing to explain, say every signal zero)."""
    return 1.0 - err / base_err if base_err > 0 else 0.0


def _pick(cands: list) -> tuple:
    """(best candidate, what it was decided on or None): the largest held-out gain among
    those decided on the held-out part with the training part's support, else among
    those the held-out part decided alone (their gains are on data their fit saw), else
    the strongest training evidence among those decided on the training part alone,
    else the largest gain (not named)."""
    held = [c for c in cands if _decides(c) == "heldout"]
    if held:
        return max(held, key=lambda c: c.gain), "heldout"
    only = [c for c in cands if _decides(c) == "heldout_only"]    # gains on data their fit saw:
    if only:                                                     # after the out-of-sample ones
        return max(only, key=lambda c: c.gain), "heldout_only"
    train = [c for c in cands if _decides(c) == "training"]
    if train:
        return min(train, key=lambda c: c.train_evidence), "training"
    return (max(cands, key=lambda c: c.gain), None) if cands else (None, None)


def scored(key: str, x, se, run: Run, vehicle: Vehicle, terrain: Terrain, pitch, base: dict, chans, scales,
           train, held, fitted_on: str = "channels") -> Candidate:
    """The candidate of form ``key`` (a CANDIDATES name, or WORLD_GRADE) at parameters
    ``x`` (standard errors ``se``) on top of ``vehicle`` and ``terrain``, scored against
    the baseline's replay ``base`` on the training and held-out masks: held-out error and
    gain, the training BIC change, the held-out and training evidence and reach
    (:func:`_decides` judges them). ``pitch`` [rad]: the run's constant grade."""
    names = _spec(key)[0]
    v, ter, p = _model_for(key, x, vehicle, terrain, names, run)
    pred = replay(run, v, ter, p + pitch)
    err = _error(run, pred, chans, scales, held)
    base_err, base_train = _error(run, base, chans, scales, held), _error(run, base, chans, scales, train)
    raw = {n: float(a) for n, a in zip(names, x)}
    if key == WORLD_GRADE:               # reported as the plane's grade and its heading
        params, stderr = world_grade(float(x[0]), float(x[1]), tuple(map(float, se)))
        bound = ("grade_deg",) if at_bound(key, raw) else ()
    else:
        params, stderr, bound = raw, {n: float(a) for n, a in zip(names, se)}, at_bound(key, raw)
    gain = _gain(err, base_err)
    train_error = _error(run, pred, chans, scales, train)
    return Candidate("grade" if key == WORLD_GRADE else key, params, stderr, err, gain,
                     _bic(_residuals(run, pred, chans, scales, train), len(names))
                     - _bic(_residuals(run, base, chans, scales, train), 0),
                     ljung_box(((run["wl"] - pred["wl"]) / scales["wl"])[held]), bound,
                     fitted_on=fitted_on,
                     evidence=heldout_evidence(run, pred, chans, scales, held, gain, len(names)),
                     reach=_error(base, pred, chans, scales, held),
                     train_evidence=heldout_evidence(run, pred, chans, scales, train, _gain(train_error, base_train),
                                                     len(names)),
                     train_reach=_error(base, pred, chans, scales, train),
                     train_error=train_error, key=key, x=tuple(float(a) for a in x))


def unseen_in_training(c: Candidate, run: Run, vehicle: Vehicle, terrain: Terrain, pitch, base: dict, chans, scales,
                       train, held) -> Candidate:
    """``c`` (a candidate :func:`scored` on top of ``vehicle`` and ``terrain``), or, where
    the training part cannot see it and so it is not decided (a voltage sag that limits
    the drive only late in the run: its fit there is uninformed), the same form fitted on
    the held-out part, replaying the whole run, ``fitted_on="heldout"`` (:func:`_decides`
    judges it as data the fit has seen). Shared by :func:`diagnose` and
    :func:`sbmpc.calibration.effects_on_top`."""
    if not (c.train_reach < REACH_MIN <= c.reach and _decides(c) is None):
        return c
    x, se = fit_candidate(c.key, run, vehicle, terrain, chans, scales, held, math.inf)
    return scored(c.key, x, se, run, vehicle, terrain, pitch, base, chans, scales, train, held, "heldout")


def judge(cands: list, pose: Candidate | None = None) -> tuple:
    """(the candidates by held-out gain, the best, what it was decided on or None): the
    choice among fitted candidates (:func:`_pick`), shared by :func:`diagnose` and
    :func:`sbmpc.calibration.effects_on_top`. ``pose``: the wheel_radius candidate
    fitted to a logged pose (:func:`_pose_candidate`). A tyre's radius shows in the
    ground motion, which the wheel speeds, torques and currents barely see: with a pose,
    it replaces the channel fit of wheel_radius and is judged on the pose; it is the
    cause when it halves the held-out pose error (``POSE_GAIN``) without worsening the
    channels, unless the channels name another effect; a wheel_radius the channels named
    without the pose's support is not the cause."""
    cands = sorted(cands, key=lambda c: -c.gain)
    best, decided = _pick(cands)
    if pose is None:
        return cands, best, decided
    cands = sorted([c for c in cands if c.effect != "wheel_radius"] + [pose], key=lambda c: -c.gain)
    if pose.pose_gain >= POSE_GAIN and pose.gain >= -POSE_CHANNEL_SLACK and (decided is None or best.effect == "wheel_radius"):
        return cands, pose, "pose"
    if decided and best.effect == "wheel_radius":      # the channels' verdict without the pose's support
        best, decided = _pick(cands)
    return cands, best, decided


def share_of(best: Candidate, decided: str | None, base_err: float, base_train: float) -> float:
    """The share of the baseline's excess that ``best`` explains, on the evidence it was
    decided on: the pose's gain for a cause decided on the pose, the training part's
    errors (``base_train``: the baseline's) for one decided there, else the held-out
    part's (``base_err``)."""
    if decided == "pose":
        return float(best.pose_gain)
    if decided == "training":
        return explained_share(base_train, best.train_error)
    return explained_share(base_err, best.heldout_error)


MIN_SAMPLES, MIN_SEGMENT = 50, 20     # samples of a run, of its longest segment, to diagnose it


def check_run_length(run: Run) -> None:
    """A RunError unless ``run`` holds MIN_SAMPLES samples and a segment of MIN_SEGMENT
    to replay (the command line calls it before it loads the models)."""
    from .runs import RunError
    if len(run) < MIN_SAMPLES:
        raise RunError(f"{run.source or 'run'}: expected at least {MIN_SAMPLES} samples to diagnose, found {len(run)}")
    segs = run.segments()
    longest = max((b - a for a, b in segs), default=0)
    if longest < MIN_SEGMENT:
        raise RunError(f"{run.source or 'run'}: expected a segment of at least {MIN_SEGMENT} samples to replay, found "
                       f"{len(segs)} segment(s) of at most {longest} (a 'segment' value per row, or gaps in t?)")


def _checked_threads(threads) -> int:
    """:func:`diagnose`'s ``threads``: a count >= 1 (None: one a CPU core)."""
    import os
    from .params import ParameterError
    if threads is None:
        return max(1, os.cpu_count() or 1)
    if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
        raise ParameterError(f"threads: expected a count of threads >= 1, found {threads!r:.30}")
    return int(threads)


def _checked_arguments(run, vehicle, terrain, pitch, effects):
    """:func:`diagnose`'s arguments checked (the command line checks the same before
    calling it); returns ``effects`` as a tuple or None."""
    from .params import ParameterError, checked_number
    if not isinstance(run, Run):
        raise ParameterError(f"run: expected a dynamics.runs.Run (read_run), found {type(run).__name__}")
    check_run_length(run)
    # a constant column has no noise to measure errors in (1e-9: errors of 1e8): a stuck
    # sensor, unless the vehicle was told to stand still and it reads 0 (nothing to explain)
    from .runs import RunError
    standing = all(c in run and not np.any(run[c]) for c in ("wl_cmd", "wr_cmd"))
    for c in channels(run):
        if np.ptp(run[c]) == 0.0 and not (standing and run[c][0] == 0.0):
            raise RunError(f"{run.source or 'run'}, column {c}: expected a measured signal, found {run[c][0]:g} in "
                           "every row")
    for name, value, cls in (("vehicle", vehicle, Vehicle), ("terrain", terrain, Terrain)):
        if not isinstance(value, cls):
            raise ParameterError(f"{name}: expected a {cls.__name__} (dynamics.load_{name}), found {type(value).__name__}")
    checked_number("pitch", pitch, "the run's grade in radians within [-0.785, 0.785] (45 deg)",
                   -math.pi / 4, math.pi / 4)
    if effects is None:
        return None
    if isinstance(effects, str) or not all(isinstance(e, str) for e in effects) or not len(effects):
        raise ParameterError(f"effects: expected a sequence of candidate names ({', '.join(CANDIDATES)}), "
                             f"found {effects!r:.60}")
    unknown = [e for e in effects if e not in CANDIDATES]
    if unknown:
        raise ParameterError(f"effects: expected names among {', '.join(CANDIDATES)}, found {unknown[0]!r}")
    return tuple(effects)


def diagnose(run: Run, vehicle: Vehicle, terrain: Terrain, pitch: float = 0.0,
             effects: tuple | None = None, progress=None, threads: int | None = None) -> Diagnosis:
    """Diagnose a measured run (module doc). ``progress(i, n, effect)`` is called before
    each candidate's fit, from the thread that fits it. ``pitch`` [rad] is the run's
    constant grade; ``effects`` the names of the candidates to fit (default: every one of
    CANDIDATES). The candidates are fitted side by side on ``threads`` threads (default:
    one a CPU core; the model's replay runs without the GIL), each fit as it is alone, so
    the diagnosis is the same on any number. A run too short to diagnose is a RunError, a
    bad argument a ParameterError, each naming it."""
    effects = _checked_arguments(run, vehicle, terrain, pitch, effects)
    threads = _checked_threads(threads)
    chans = channels(run)
    scales = {c: noise_scale(run[c]) for c in chans}
    t = run.t
    split = t[0] + TRAIN_FRACTION * (t[-1] - t[0])
    train, held = t < split, t >= split
    base = replay(run, vehicle, terrain, pitch)
    base_err = _error(run, base, chans, scales, held)
    r_base_train = _residuals(run, base, chans, scales, train)
    base_train = _error(run, base, chans, scales, train)
    bic0 = _bic(r_base_train, 0)
    q0 = ljung_box(((run["wl"] - base["wl"]) / scales["wl"])[held])
    rmse = {c: float(np.sqrt(np.nanmean(((run[c] - base[c]))[held] ** 2))) for c in chans}
    todo = effects or tuple(CANDIDATES)

    def fitted(key):
        c = scored(key, *fit_candidate(key, run, vehicle, terrain, chans, scales, train), run, vehicle, terrain,
                   pitch, base, chans, scales, train, held)
        return unseen_in_training(c, run, vehicle, terrain, pitch, base, chans, scales, train, held)

    def candidate(i, eff):
        if progress is not None:
            progress(i, len(todo), eff)
        c = fitted(eff)
        if eff == "grade" and has_pose(run):
            # a grade depends on where the vehicle points: with a logged heading, also as
            # a plane fixed in the world; the form the training part supports better
            w = fitted(WORLD_GRADE)
            c = w if w.bic_delta < c.bic_delta else c
        return c

    if threads == 1 or len(todo) == 1:
        cands = [candidate(i, eff) for i, eff in enumerate(todo)]
    else:
        from concurrent.futures import ThreadPoolExecutor
        with ThreadPoolExecutor(max_workers=min(threads, len(todo))) as pool:
            cands = list(pool.map(candidate, range(len(todo)), todo))
    pe_base = pose_error(run, base, held)
    pose = None
    if pe_base is not None and "wheel_radius" in todo:
        pose = _pose_candidate(run, vehicle, terrain, pitch, train, held, chans, scales, base_err, bic0, pe_base)
    cands, best, decided = judge(cands, pose)
    named = decided is not None
    # how much of what the baseline misses the best candidate explains: a cause is named
    # only where that is substantial; where a large residual is left, the verdict says so
    share, hint, unexplained = None, None, False
    if best is not None:
        share = share_of(best, decided, base_err, base_train)
        # the residual judged is the held-out part's (a cause decided on the training part
        # may act in a short stretch of it: the independent voltage sag explained 6 % of
        # that part's excess, with a BIC change of -467)
        if base_err > EXCESS_MIN and (not named or share < SHARE_MIN):
            unexplained, hint, named, decided = True, best.effect, False, None
    residual = {}
    if unexplained or (not named and base_err > EXCESS_MIN):
        where = _where(run, base, chans, scales)
        residual = {"heldout_error": base_err, "excess": math.sqrt(max(base_err * base_err - 1.0, 0.0)),
                    "where": where, "sides": _sides(run, base, chans, scales, held),
                    "most_in": max((k for k in where if k not in ("early", "late")), key=lambda k: where[k],
                                   default=None)}
    if named:                                  # the named cause heads the list
        cands.remove(best)
        cands.insert(0, best)
    ext_v, ext_t, ext_pitch, ext_p, slope = vehicle, terrain, 0.0, 0.0, None
    if named:
        key, x = best.key, best.x             # (every candidate diagnose makes has its form)
        ext_v, ext_t, ext_pitch = _model_for(key, x, vehicle, terrain, _spec(key)[0], run)
        if key == WORLD_GRADE:
            slope, ext_p = x, best.params["grade_deg"]
        else:
            ext_p = math.degrees(ext_pitch)
    pose = {}
    pe = pose_error(run, base, held)
    if pe is not None:
        pose["baseline"] = pe
        ext = replay(run, ext_v, ext_t, ext_pitch + pitch) if named else base
        pose["extended"] = pose_error(run, ext, held)
    rivals = tuple(c.effect for c in cands[1:] if named and _decides(c) and best.gain - c.gain < TIE
                   and (c.fitted_on == "heldout") == (best.fitted_on == "heldout"))   # like with like
    gain = (best.pose_gain if best.fitted_on == "pose" else best.gain) if named else 0.0
    cause = best.effect if named else ("unexplained" if residual else "none")
    return Diagnosis(chans, scales, base_err, rmse, q0, cands, cause,
                     gain, _where(run, base, chans, scales), _xcorr(run, base, scales),
                     ext_v, ext_p, ext_t, pose, rivals, decided, share, hint, residual, slope)
