"""Measured runs: the CSV reader, and the diagnosis finding effects hidden in generated data."""
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dynamics import load_terrain, load_vehicle
from dynamics.discrepancy import CANDIDATES, MARGIN, calibrate, diagnose, noise_scale, replay, start_points
from dynamics.runs import Run, RunError, read_run, write_run
from dynamics.synth import STRENGTHS, synth_run
from sbmpc.commands.cli import main

P3AT, VINYL = load_vehicle("p3at"), load_terrain("vinyl")
DURATION = 60.0
# a second seed of a case the quick loop (pytest -m "not slow") already runs: CI runs it
SLOW = pytest.mark.slow


# ---- the run CSV -------------------------------------------------------------------
def test_run_csv_round_trip_with_gaps_and_segments(tmp_path):
    t = np.arange(0, 2, 0.01)
    cols = {"t": t, "wl_cmd": np.ones_like(t), "wr_cmd": np.ones_like(t), "wl": np.sin(t), "wr": np.cos(t),
            "segment": (t >= 1).astype(float)}
    cols["wl"][5] = np.nan
    p = tmp_path / "r.csv"
    write_run(p, Run(cols, {"vehicle": "p3at"}))
    run = read_run(p)
    assert run.meta["vehicle"] == "p3at"
    assert np.isnan(run["wl"][5]) and run["wr"][5] == pytest.approx(math.cos(0.05), abs=1e-5)
    assert run.segments() == [(0, 100), (100, 200)]
    # a logging gap also starts a segment
    cols2 = {k: np.delete(v, np.arange(50, 80)) for k, v in cols.items() if k != "segment"}
    assert len(Run(cols2).segments()) == 2


@pytest.mark.parametrize("text, words", [
    ("t,wl_cmd,wr_cmd,wl\n0,1,1,1\n", "found no wr"),
    ("t,wl_cmd,wr_cmd,wl,wr\n0,1,1,1,1\n0.01,1,1,fast,1\n", "line 3, column wl: expected a number, found 'fast'"),
    ("t,wl_cmd,wr_cmd,wl,wr\n0,1,1,1,1\n0.02,1,1,1,1\n0.01,1,1,1,1\n", "line 4, column t: expected time to increase"),
    ("# vehicle: p3at\n", "empty file"),
    ("t,wl_cmd,wr_cmd,wl,wr\n", "found none"),
    ("t,wl_cmd,wr_cmd,wl,wr\n0,1,1,1\n", "expected 5 cells, found 4"),
])
def test_bad_run_files_name_line_and_column(tmp_path, capsys, text, words):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(RunError) as e:
        read_run(p)
    assert words in str(e.value) and str(p) in str(e.value)
    assert main(["diagnose", str(p)]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err and err.count("\n") == 1
    assert p.read_text() == text                   # never modified


@given(st.integers(20, 400), st.integers(3, 8), st.integers(1, 3))
@settings(max_examples=30, deadline=None)
def test_a_quantised_signal_stepping_one_way_has_its_rounding_noise(n, hold, m):
    """A wheel speed logged in quanta of 1/127 m/s that holds for a few samples and then
    steps, always the same way (BorealTC's Husky at a steady speed): the median absolute
    deviation of its steps is 0, and its noise was taken as 1e-9 (held-out errors of 6e7
    noise units). It is the rounding noise of its step, step / sqrt(12)."""
    q = 1.0 / 127.0 / 0.13
    y = 2.0 + m * q * (np.arange(n) // hold)
    assert noise_scale(y) == pytest.approx(m * q / math.sqrt(12.0), rel=1e-9)


def test_noise_scale_recovers_white_noise_on_a_stepping_signal():
    rng = np.random.default_rng(0)
    y = np.repeat(rng.uniform(-5, 5, 40), 100) + rng.normal(0, 0.05, 4000)
    assert noise_scale(y) == pytest.approx(0.05, rel=0.1)


def test_replay_of_a_clean_run_is_exact():
    run, _ = synth_run("none", 1, duration=20.0, noise=False)
    pred = replay(run, P3AT, VINYL)
    for c in ("wl", "wr", "tau_l", "tau_r"):
        assert np.max(np.abs(pred[c] - run[c])) < 0.05, c


# ---- effects hidden in generated data ------------------------------------------------
TOLERANCE = {   # absolute tolerance on the fitted parameter
    "command_delay": {"delay_s": 0.004},
    "actuator_lag": {"lag_s": 0.012},
    "wheel_radius": {"scale_left": 0.01, "scale_right": 0.01},
    "viscous_friction": {"c_Nms": 0.03},
    "no_load_current": {"i0_A": 0.03},
    "voltage_sag": {"sag_V_per_kJ": 0.15},
    "shear_relaxation": {"tau_s": 0.08},
    "grade": {"grade_deg": 0.3},
    "turning_friction": {"mu_scale": 0.03},
}


@pytest.mark.parametrize("effect, seed", [(e, 11 + i) for i, e in enumerate(CANDIDATES)])
def test_the_hidden_effect_is_named_and_its_parameter_recovered(effect, seed):
    run, hidden = synth_run(effect, seed, duration=DURATION)
    d = diagnose(run, P3AT, VINYL)
    assert d.cause == effect, [(c.effect, round(c.gain, 3)) for c in d.candidates[:3]]
    assert d.gain >= MARGIN
    fitted = d.candidates[0].params
    for name, tol in TOLERANCE[effect].items():
        assert fitted[name] == pytest.approx(hidden[name], abs=tol), (name, fitted, hidden)
    # the extended model explains the held-out part within about the noise
    assert d.candidates[0].heldout_error < 1.3
    # and its wheel-speed residuals are white (Ljung-Box Q of 20 lags under the chi-square
    # 99 % point, 37.6), or whiter than the baseline's when those were not
    assert d.candidates[0].whiteness_q < max(d.baseline_whiteness_q, 37.6)


@pytest.mark.parametrize("seed", [21, pytest.param(22, marks=SLOW), pytest.param(23, marks=SLOW)])
def test_no_false_alarm_on_runs_without_an_effect(seed):
    run, _ = synth_run("none", seed, duration=DURATION)
    d = diagnose(run, P3AT, VINYL)
    assert d.cause == "none"
    assert d.baseline_error < 1.3
    assert max(c.gain for c in d.candidates) < 0.5 * MARGIN


@pytest.mark.parametrize("seed, duration", [(0, 1.0), (0, 2.0), (21, 1.5)])
def test_a_short_clean_run_from_rest_is_none(seed, duration):
    """The replay starts from the first measured wheel speeds in steady state; from rest
    their noise made a difference of a few hundredths of a rad/s, a steady turn whose
    full turning resistance the PID integrals then held for seconds: clean runs of 1-2 s
    were named turning_friction (gains 0.5-0.8)."""
    run, _ = synth_run("none", seed, duration=duration)
    d = diagnose(run, P3AT, VINYL)
    assert d.cause == "none", (d.cause, max(c.gain for c in d.candidates))


def test_start_points_begin_at_the_guess_and_spread_over_the_bounds():
    pts = start_points([2.0, 50.0], [1.0, 10.0], [3.0, 90.0], 6)
    assert pts.shape == (6, 2)
    assert np.array_equal(pts[0], [2.0, 50.0])
    assert np.all(pts >= [1.0, 10.0]) and np.all(pts <= [3.0, 90.0])
    assert len({tuple(p) for p in pts}) == 6                 # no start twice
    assert np.array_equal(pts, start_points([2.0, 50.0], [1.0, 10.0], [3.0, 90.0], 6))


def test_calibration_from_several_starts_escapes_a_flat_start():
    """A P3-AT whose reference rate limit is 0.6 m/s^2 (1.0 assumed). Started at 2.55 the
    residual is flat (the current limit binds, not the rate limit) and the fit stays
    there; a second start over the bounds finds 0.6."""
    v, ter = load_vehicle("p3at"), load_terrain("vinyl")
    run, _ = synth_run("none", 3, vehicle=v.replace(ref_accel=0.6), duration=20.0)
    guess = v.replace(ref_accel=2.55)
    _, one, opt1 = calibrate(run, guess, ter, {"ref_accel": (0.1, 5.0)}, starts=1)
    assert len(opt1) == 1 and abs(one["ref_accel"][0] - 0.6) > 1.0
    fitted, cal, opt = calibrate(run, guess, ter, {"ref_accel": (0.1, 5.0)}, starts=3)
    value, se = cal["ref_accel"]
    assert abs(value - 0.6) < max(3 * se, 0.003)
    assert fitted.ref_accel == value
    assert len(opt) == 3 and [o["cost"] for o in opt] == sorted(o["cost"] for o in opt)
    assert opt[0]["ref_accel"] == value and opt[-1]["cost"] > 10 * opt[0]["cost"]


def test_start_speeds_drop_noise_sized_turns_and_keep_real_ones():
    from dynamics.discrepancy import start_speeds
    assert start_speeds(0.061, 0.053, 0.05, 0.05) == (0.0, 0.0)          # rest, within noise
    assert start_speeds(2.03, 1.97, 0.05, 0.05) == (2.0, 2.0)            # straight, within noise
    assert start_speeds(2.5, 1.5, 0.05, 0.05) == (2.5, 1.5)              # a real turn
    assert start_speeds(-0.5, 0.5, 0.05, 0.05) == (-0.5, 0.5)            # a pivot
    assert start_speeds(0.10, 0.16, 0.01, 0.01) == (0.10, 0.16)          # slow, a turn above the noise
    assert start_speeds(0.12, 0.13, 0.01, 0.01) == (0.125, 0.125)        # slow, straight within the noise
    assert start_speeds(-12.50, -12.89, 0.35, 0.36) == (-12.50, -12.89)   # held 4 Hz log: the cap, a real turn
    assert start_speeds(0.18, 0.18, 0.38, 0.38) == (0.18, 0.18)          # moving, above the cap


def test_a_held_log_is_told_from_a_white_one():
    """replay straightens noise-sized starts only on logs with white noise: a held (slower
    sensor) or quantised log's noise estimate is made of its own steps."""
    from dynamics.discrepancy import is_held
    rng = np.random.default_rng(0)
    white = 3.0 + rng.normal(0.0, 0.05, 500)
    assert not is_held(white)
    assert is_held(np.repeat(white[::5], 5))                          # a 4 Hz sensor logged at 20 Hz
    smooth = 3.0 + 0.5 * np.sin(np.arange(500) / 65.0) + rng.normal(0.0, 0.005, 500)
    assert is_held(np.round(smooth * 0.13 * 127) / 127 / 0.13)       # BorealTC's 1/127 m/s quantum


def test_effect_strengths_cover_the_vocabulary():
    assert set(STRENGTHS) == set(CANDIDATES) | {"none"}


# ---- the commands ------------------------------------------------------------------
def test_cli_synth_then_diagnose_writes_json_vehicle_and_report(tmp_path, capsys):
    csv = tmp_path / "run.csv"
    assert main(["synth", "--effect", "wheel_radius", "--seed", "5", "--out", str(csv), "--duration", "40"]) == 0
    js, rep = tmp_path / "d.json", tmp_path / "rep"
    assert main(["diagnose", str(csv), "--json", str(js), "--report", str(rep)]) == 0
    out = capsys.readouterr().out
    assert "cause: wheel_radius" in out
    doc = json.loads(js.read_text())
    assert doc["schema"] == "sbmpc.diagnosis/1" and doc["cause"] == "wheel_radius"
    assert doc["candidates"][0]["effect"] == "wheel_radius"
    assert [c["gain"] for c in doc["candidates"]] == sorted((c["gain"] for c in doc["candidates"]), reverse=True)
    for key in ("heldout_error", "rmse"):
        assert key in doc["baseline"]
    ext = load_vehicle(doc["extended_vehicle"])
    assert min(ext.radius_scale_left, ext.radius_scale_right) < 0.96
    assert ext.name == "p3at+wheel_radius"      # not "p3at": a run it drives must not read as the model's own
    for f in ("report.md", "replay.png", "residuals.png"):
        assert (rep / f).stat().st_size > 500
    # the extended vehicle is accepted by simulate
    assert main(["simulate", "--vehicle", doc["extended_vehicle"], "--v", "0.5", "--duration", "2"]) == 0


def test_pose_error_is_reported_and_falls_with_the_extension():
    """A flat tyre turns the vehicle: the relative pose error of the baseline shows it in
    the heading, and the extended model removes most of it; a run without pose columns
    has no pose error."""
    from dynamics.discrepancy import pose_error
    run, _ = synth_run("wheel_radius", 4, duration=DURATION)
    d = diagnose(run, P3AT, VINYL, effects=("wheel_radius", "viscous_friction"))
    b, e = d.pose["baseline"], d.pose["extended"]
    assert d.cause == "wheel_radius"
    assert e["rot_rmse_rad"] < 0.3 * b["rot_rmse_rad"] and e["trans_rmse_m"] < b["trans_rmse_m"]
    assert d.to_json()["pose_error"]["baseline"]["window_s"] == 2.0
    # the measured run against itself: no error at all
    exact = {c: run[c] for c in ("x", "y", "yaw")}
    assert pose_error(run, exact)["trans_rmse_m"] == 0.0
    no_pose = Run({k: run[k] for k in ("t", "wl_cmd", "wr_cmd", "wl", "wr")})
    assert pose_error(no_pose, exact) is None


def test_fits_at_a_bound_and_rivals_are_named():
    """A fit that ends at the edge of its candidate's range is flagged (a bound of 0, the
    model without the effect, is not); rivals within 0.02 of the named cause's gain are
    named with it."""
    from dynamics.discrepancy import CANDIDATES, at_bound
    assert at_bound("turning_friction", {"mu_scale": 0.1002}) == ("mu_scale",)
    assert at_bound("wheel_radius", {"scale_left": 1.0, "scale_right": 0.701}) == ("scale_right",)
    assert at_bound("command_delay", {"delay_s": 0.0}) == ()
    assert at_bound("viscous_friction", {"c_Nms": -0.9959}) == ("c_Nms",)
    assert at_bound("grade", {"grade_deg": 3.0}) == ()
    assert set(CANDIDATES) >= {"turning_friction", "wheel_radius"}


def test_a_caveat_says_which_way_the_fit_pressed():
    """The caveat of a fit at its lower bound says the data may want less (the DRIVE
    asphalt run's mu_scale 0.1002 was told 'more'), at its upper bound more; the report's
    parameter says which bound."""
    from types import SimpleNamespace
    from dynamics.discrepancy import CANDIDATES, Candidate, at_bound, bound_side
    from sbmpc.commands.diagnose import _at, caveats
    names, lo, hi, _, _ = CANDIDATES["turning_friction"]
    i = names.index("mu_scale")
    for value, side, want in ((lo[i] + 0.0002, "lower", "less than"), (hi[i] - 0.0002, "upper", "more than")):
        params = {n: (value if n == "mu_scale" else 0.5 * (a + b)) for n, a, b in zip(names, lo, hi)}
        c = Candidate("turning_friction", params, {n: 0.01 for n in names}, 1.0, 0.3, -50.0, 10.0,
                      at_bound=at_bound("turning_friction", params))
        assert bound_side("turning_friction", "mu_scale", value) == side
        assert _at(c, "mu_scale") == f" (at its {side} bound)"
        (line,) = caveats(SimpleNamespace(cause="turning_friction", candidates=[c], rivals=()))
        assert f"the {side} bound of mu_scale" in line and f"may want {want} the candidate allows" in line


def _speeds_and_pose_only(run):
    keep = ("t", "wl_cmd", "wr_cmd", "wl", "wr", "x", "y", "yaw")
    return Run({k: run[k] for k in keep if k in run.columns}, run.meta, run.source)


@pytest.mark.parametrize("seed", [5, pytest.param(8, marks=SLOW)])
def test_a_tyre_seen_only_in_the_pose_is_found(seed):
    """With wheel speeds and pose only (no torques, no currents), a smaller tyre leaves
    the wheel speeds as commanded: only the ground motion shows it. The wheel_radius
    candidate fitted to the relative pose errors finds it and its size."""
    run, hidden = synth_run("wheel_radius", seed, duration=DURATION)
    run = _speeds_and_pose_only(run)
    d = diagnose(run, P3AT, VINYL)
    assert d.cause == "wheel_radius", [(c.effect, round(c.gain, 3), c.pose_gain) for c in d.candidates[:3]]
    best = next(c for c in d.candidates if c.effect == "wheel_radius")
    assert best.fitted_on == "pose" and best.pose_gain >= 0.5
    for name in ("scale_left", "scale_right"):
        assert best.params[name] == pytest.approx(hidden[name], abs=0.015), (best.params, hidden)


@pytest.mark.parametrize("seed", [21, pytest.param(22, marks=SLOW)])
def test_no_false_alarm_from_the_pose(seed):
    run, _ = synth_run("none", seed, duration=DURATION)
    d = diagnose(_speeds_and_pose_only(run), P3AT, VINYL)
    assert d.cause == "none", [(c.effect, round(c.gain, 3), c.pose_gain) for c in d.candidates[:3]]


# ---- the decision weighs the evidence (issue: effects only some channels or parts see) --
@pytest.mark.parametrize("effect, seed, params", [
    ("voltage_sag", 6, {"sag_V_per_kJ": 0.3}),        # held-out gain 0.12: under the old fixed 10 % bar at 0.25
    ("shear_relaxation", 7, {"tau_s": 0.15}),        # short: the profile over the time constant finds it
])
def test_small_effects_are_named_on_the_evidence(effect, seed, params):
    run, _ = synth_run(effect, seed, duration=DURATION, params=params)
    d = diagnose(run, P3AT, VINYL)
    assert d.cause == effect and d.decided_on == "heldout"
    c = d.candidates[0]
    assert c.evidence < -100 and c.bic_delta < -100
    name, value = next(iter(params.items()))
    assert c.params[name] == pytest.approx(value, abs=0.05)


def test_an_effect_the_held_out_part_cannot_test_is_named_on_the_training_part():
    """Seed 8's last 30 % drives almost straight: a 5 % easier turning friction moves the
    held-out prediction by a thousandth of the noise there, but the training part's turns
    show it with a BIC fall in the thousands (-500 counting samples by their
    autocorrelation)."""
    run, _ = synth_run("turning_friction", 8, duration=DURATION, params={"mu_scale": 0.95})
    d = diagnose(run, P3AT, VINYL)
    assert d.cause == "turning_friction" and d.decided_on == "training"
    c = d.candidates[0]
    assert c.reach < 0.05 and c.bic_delta < -1000 and c.train_evidence < -200
    assert c.params["mu_scale"] == pytest.approx(0.95, abs=0.03)


def test_an_effect_the_training_part_cannot_test_is_fitted_and_named_on_the_held_out_part():
    """Seed 19 drives gently for its first 70 %: a sag of 1 V/kJ never limits the drive
    there (the training prediction moves by 0.000 noise units, its BIC change is the
    parameter's penalty alone), and only the held-out part's faster turns meet the
    sagging voltage limit. The training fit is uninformed there; fitted on the held-out
    part (the whole run replayed: the sag grows with the energy drawn since the start),
    it finds 1.0 and the held-out evidence is in the thousands."""
    run, _ = synth_run("voltage_sag", 19, duration=DURATION, params={"sag_V_per_kJ": 1.0})
    d = diagnose(run, P3AT, VINYL)
    assert d.cause == "voltage_sag" and d.decided_on == "heldout_only"
    c = d.candidates[0]
    assert c.fitted_on == "heldout" and c.train_reach < 0.05 and c.bic_delta > -10
    assert c.gain > 0.2 and c.evidence < -1000
    assert c.params["sag_V_per_kJ"] == pytest.approx(1.0, abs=0.05)
    # the same commands without the sag: the held-out fit finds nothing to name
    clean, _ = synth_run("none", 19, duration=DURATION)
    d = diagnose(clean, P3AT, VINYL)
    assert d.cause == "none" and d.decided_on is None


@pytest.mark.parametrize("seed, kw", [
    (21, {"step_s": 0.005}),      # the same model integrated as the continuous loop at 5 ms
    pytest.param(23, {"step_s": 0.01}, marks=SLOW),   # ... and at 10 ms: held-out gain 0.04 for a 3 ms lag
    (24, {"mass": 1.01}),         # a parameter 1 % off
])
def test_a_right_but_not_identical_model_is_none(seed, kw):
    vehicle = P3AT.replace(mass=P3AT.mass * kw["mass"]) if "mass" in kw else P3AT
    run, _ = synth_run("none", seed, vehicle=vehicle, duration=DURATION, step_s=kw.get("step_s"))
    d = diagnose(run, P3AT, VINYL)
    assert d.cause == "none", [(c.effect, round(c.gain, 3), round(c.evidence, 1)) for c in d.candidates[:3]]


def test_diagnose_in_python_names_a_bad_argument():
    """From Python, diagnose took a NaN or a 10 rad pitch (cause 'none' with NaN errors),
    an empty run (IndexError), effects='grade' (KeyError 'g') or an unknown effect
    (KeyError); each is now one error naming the argument."""
    from dynamics import ParameterError
    run, _ = synth_run("none", 0, duration=10.0)
    v, t = load_vehicle("p3at"), load_terrain("vinyl")
    for kw, err, says in [(dict(pitch=float("nan")), ParameterError, "pitch: expected the run's grade in radians"),
                          (dict(pitch=10.0), ParameterError, "within [-0.785, 0.785]"),
                          (dict(effects="grade"), ParameterError, "effects: expected a sequence of candidate names"),
                          (dict(effects=("bogus",)), ParameterError, "found 'bogus'"),
                          (dict(terrain="vinyl"), ParameterError, "terrain: expected a Terrain"),
                          (dict(threads=0), ParameterError, "threads: expected a count of threads >= 1, found 0")]:
        with pytest.raises(err, match=says.replace("[", r"\[").replace("(", r"\(")):
            diagnose(run, v, kw.pop("terrain", t), **kw)
    empty = Run({k: a[:0] for k, a in run.columns.items()}, dict(run.meta), "empty.csv")
    with pytest.raises(RunError, match="empty.csv: expected at least 50 samples to diagnose, found 0"):
        diagnose(empty, v, t)
    d = diagnose(run, v, t, effects=["grade"])                  # a list of names is fine
    assert [c.effect for c in d.candidates] == ["grade"]


def test_the_candidates_fitted_side_by_side_are_those_fitted_one_after_another():
    """diagnose fits its candidates on several threads (the replay runs without the GIL):
    every fitted number, the verdict and the order are those of one thread; a run with a
    logged pose, so the grade is also fitted as a plane fixed in the world; each
    candidate's progress is reported once."""
    run, _ = synth_run("grade", 17, duration=20.0)
    assert "yaw" in run.columns
    seen = []
    one = diagnose(run, P3AT, VINYL, threads=1)
    many = diagnose(run, P3AT, VINYL, threads=3, progress=lambda i, n, e: seen.append((i, n, e)))
    assert json.dumps(many.to_json(), sort_keys=True) == json.dumps(one.to_json(), sort_keys=True)
    assert [c.effect for c in many.candidates] == [c.effect for c in one.candidates]
    assert sorted(seen) == [(i, len(CANDIDATES), e) for i, e in enumerate(CANDIDATES)]


def test_the_report_says_what_the_terminal_says(tmp_path, capsys):
    """report.md left out the caveats, gave a pose-fitted cause's pose gain with no word
    of the pose, and printed 'nan' where a short run gives no standard error."""
    run, _ = synth_run("wheel_radius", 1, duration=60.0)
    write_run(tmp_path / "wr.csv", run)
    assert main(["diagnose", str(tmp_path / "wr.csv"), "--report", str(tmp_path / "rep")]) == 0
    out = capsys.readouterr().out
    report = (tmp_path / "rep" / "report.md").read_text()
    cause = next(line for line in out.splitlines() if line.startswith("cause: "))
    assert "fitted to and decided on the pose" in cause
    assert f"**{cause.replace('cause: ', 'Cause: ', 1)}**" in report
    for line in out.splitlines():
        if line.startswith("caveat: "):
            assert f"Caveat: {line[8:]}." in report
    assert "(pose " in report and "nan" not in report


def test_a_column_with_one_value_is_refused(tmp_path, capsys):
    """wl set to 1 in every row gave a noise scale of 1e-9, a baseline error of 2e8 and
    the cause 'none' without a word; such a column is named."""
    run, _ = synth_run("none", 0, duration=10.0)
    run.columns["wl"] = np.ones_like(run["wl"])
    write_run(tmp_path / "flat_wl.csv", run)
    assert main(["diagnose", str(tmp_path / "flat_wl.csv")]) == 2
    assert "column wl: expected a measured signal, found 1 in every row" in capsys.readouterr().err


@settings(max_examples=200, deadline=None)
@given(st.floats(0.0, 50.0), st.floats(0.0, 50.0))
def test_the_explained_share_is_the_excess_variance_removed(base, err):
    """Errors in noise units: the excess over the noise is base^2 - 1; the share removed
    lies in [0, 1], is 1 at or below the noise, 0 where the candidate does no better, and
    falls as the candidate's error grows."""
    from dynamics.discrepancy import explained_share
    s = explained_share(base, err)
    assert 0.0 <= s <= 1.0
    if base > 1.0:
        assert (s == 1.0) == (err <= 1.0)
        if err >= base:
            assert s == 0.0
        assert explained_share(base, err + 0.1) <= s
    else:
        assert s == 0.0


@pytest.mark.slow
def test_runs_of_an_independent_implementation_unexplained_and_named(tmp_path, capsys):
    """Runs made by an independent implementation of the paper (bench/independent/sim.py,
    small modelling differences from ours). With no effect hidden its held-out error is
    3.9 noise units, and the best candidate explains 2 % of the excess over the noise:
    'unexplained', with that candidate as a hint and where the residual sits. With a
    viscous drag on top, the drag explains 99 % of it and is named."""
    import json
    import sys
    from pathlib import Path
    import jsonschema
    from sbmpc import schemas
    from dynamics.discrepancy import SHARE_MIN
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench" / "independent"))
    import sim
    out = {}
    for i in (1, 8):                                 # none_b, viscous_0.3 of base seed 20240
        stem, effect, eff, _ = sim.CASES[i]
        seed = 20240 + 17 * i
        cl, cr, _ = sim.random_commands(np.random.default_rng([seed, 1]), 90.0)
        res = sim.simulate(cl, cr, effects=eff)
        path = tmp_path / f"{stem}.csv"
        sim.write_csv(str(path), res, cl, cr, 10, np.random.default_rng([seed, 2]),
                      {"vehicle": "p3at", "terrain": "vinyl", "slope_deg": 0, "note": "independent"})
        out[effect] = (path, diagnose(read_run(path), P3AT, VINYL))
    path, d = out["none"]
    assert d.cause == "unexplained" and d.baseline_error > 2.0
    assert d.hint in CANDIDATES and d.share < SHARE_MIN
    assert d.residual["excess"] == pytest.approx(np.sqrt(d.baseline_error ** 2 - 1.0))
    assert set(d.residual["where"]) >= {"steady", "transient", "straight", "turning"}
    assert d.extended_vehicle == P3AT                 # nothing is extended
    j = tmp_path / "d.json"
    assert main(["diagnose", str(path), "--json", str(j)]) == 0
    text = capsys.readouterr().out
    assert "cause: unexplained (the model misses" in text and f"the best, {d.hint}" in text
    doc = json.loads(j.read_text())
    jsonschema.validate(doc, schemas.diagnosis())
    assert doc["cause"] == "unexplained" and doc["hint"] == d.hint and doc["share_threshold"] == SHARE_MIN
    _, v = out["viscous_friction"]
    assert v.cause == "viscous_friction" and v.share > 0.9 and v.hint is None


# ---- a grade fixed in the world, felt along the logged heading --------------------------
@settings(max_examples=60, deadline=None)
@given(g=st.floats(0.0, 0.35), toward=st.floats(-math.pi, math.pi), yaw=st.floats(-10.0, 10.0))
def test_a_plane_is_felt_along_the_heading(g, toward, yaw):
    """heading_pitch: up the steepest direction the vehicle feels the plane's whole grade,
    down it the same grade negative, across it none; any heading at most the steepest;
    world_grade gives back the grade and the heading that climbs it."""
    from dynamics.discrepancy import heading_pitch, world_grade
    se, sn = g * math.cos(toward), g * math.sin(toward)
    assert float(heading_pitch(toward, se, sn)) == pytest.approx(math.atan(g), abs=1e-12)
    assert float(heading_pitch(toward + math.pi, se, sn)) == pytest.approx(-math.atan(g), abs=1e-12)
    assert float(heading_pitch(toward + math.pi / 2, se, sn)) == pytest.approx(0.0, abs=1e-12)
    assert abs(float(heading_pitch(yaw, se, sn))) <= math.atan(g) + 1e-12
    p, _ = world_grade(se, sn)
    assert p["grade_deg"] == pytest.approx(math.degrees(math.atan(g)), abs=1e-9)
    if g > 1e-6:
        d = (p["toward_deg"] - math.degrees(toward)) % 360.0
        assert min(d, 360.0 - d) < 1e-6


def test_a_replay_takes_one_pitch_per_sample():
    """A pitch per sample that is one grade throughout replays as that grade does; one that
    changes half-way slows the climb from there on (the uphill wheels' speed falls)."""
    run, _ = synth_run("none", 4, P3AT, VINYL, duration=12.0)
    n = len(run)
    one = replay(run, P3AT, VINYL, math.radians(5.0))
    per = replay(run, P3AT, VINYL, np.full(n, math.radians(5.0)))
    for c in ("wl", "wr", "tau_l", "tau_r"):
        assert np.allclose(one[c], per[c], equal_nan=True)
    steps = np.where(run.t >= run.t[0] + 6.0, math.radians(12.0), 0.0)
    flat = replay(run, P3AT, VINYL, 0.0)
    late = replay(run, P3AT, VINYL, steps)
    first = run.t < run.t[0] + 5.9
    assert np.allclose(late["wl"][first], flat["wl"][first])
    assert not np.allclose(late["tau_l"][~first], flat["tau_l"][~first], atol=0.05)


@pytest.mark.slow
def test_a_grade_fixed_in_the_world_found_from_the_logged_heading():
    """The independent implementation drives a 90 s run on a plane rising 2.5 deg towards
    heading 30 deg (the pitch it feels changes with every turn). A grade along the body
    fitted 2.07 deg and predicted the held-out part worse than none (gain -0.38); fitted
    as a plane, felt along the logged heading, it is named with its grade and heading,
    and the held-out pose error falls."""
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench" / "independent"))
    import sim
    truth = next(c[3] for c in sim.CASES if c[0] == "grade_2.5deg_world")
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        run = read_run(sim.write_case("grade_2.5deg_world", tmp)[0])
    d = diagnose(run, P3AT, VINYL)
    assert d.cause == "grade" and d.decided_on == "heldout"
    c = d.candidates[0]
    assert c.params["grade_deg"] == pytest.approx(truth["grade_deg"], abs=0.1)
    assert c.params["toward_deg"] == pytest.approx(truth["toward_deg"], abs=2.0)
    assert d.extended_slope is not None and d.to_json()["extended_grade_toward_deg"] == pytest.approx(30.0, abs=2.0)
    assert d.pose["extended"]["rot_rmse_rad"] < 0.2 * d.pose["baseline"]["rot_rmse_rad"]
    # without the pose the grade is one along the body, as before
    bare = Run({k: run[k] for k in ("t", "wl_cmd", "wr_cmd", "wl", "wr", "tau_l", "tau_r")}, run.meta)
    b = diagnose(bare, P3AT, VINYL, effects=("grade",))
    assert set(b.candidates[0].params) == {"grade_deg"} and b.extended_slope is None
