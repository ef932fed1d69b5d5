"""``sbmpc calibrate`` (:mod:`sbmpc.calibration`): the parameters a run excites fitted
jointly on the model's replay, the rest kept and said so, files that plan and run take,
and the add-on effect diagnosed on top with the base fitted jointly."""
from __future__ import annotations

import json

import numpy as np
import pytest

from dynamics.params import load_terrain, load_vehicle
from dynamics.runs import Run, write_run
from dynamics.synth import synth_run
from sbmpc.calibration import MIN_SECONDS, chosen
from sbmpc.commands.cli import main

P3AT, VINYL = load_vehicle("p3at"), load_terrain("vinyl")
# a vehicle 5-15 % off the shipped one in every parameter the calibration fits
OFF_V = {"mass": 1.12, "torque_constant": 0.92}
OFF_T = {"mu_roll": 1.15, "mu_sa": 1.10, "mu_op": 0.88}


def _truth(**scale):
    v = P3AT.replace(mass=P3AT.mass * OFF_V["mass"], inertia=P3AT.inertia * OFF_V["mass"],
                     torque_constant=P3AT.torque_constant * OFF_V["torque_constant"])
    t = VINYL.replace(**{k: getattr(VINYL, k) * f for k, f in OFF_T.items()})
    return v, t


@pytest.mark.slow
def test_a_vehicle_off_in_five_parameters_is_recovered_and_its_files_plan(tmp_path, capsys):
    """A 60 s generated drive (turns both ways, speed steps, torques and currents logged)
    of a P3-AT 8-15 % off in mass, torque constant, mu_roll, mu_sa and mu_op: every one is
    recovered within two standard errors (or 1 %), the held-out error falls from 6.6 noise
    units to the noise, the diagnosis on top is `none`, and the files are the shipped
    formats that load back to the calibrated values."""
    v, t = _truth()
    run, _ = synth_run("none", 21, vehicle=v, terrain=t, duration=60.0)
    src = tmp_path / "drive.csv"
    write_run(src, run)
    out = tmp_path / "cal"
    assert main(["calibrate", str(src), "--vehicle", "p3at", "--terrain", "vinyl", "--out", str(out),
                 "--effects", "viscous_friction,command_delay"]) == 0
    text = capsys.readouterr().out
    assert "calibrate, then diagnose, drive.csv: none" in text
    doc = json.loads((out / "calibration.json").read_text())
    truth = {"mass": v.mass, "torque_constant": v.torque_constant, "mu_roll": t.mu_roll, "mu_sa": t.mu_sa,
             "mu_op": t.mu_op}
    for name, want in truth.items():
        p = doc["params"][name]
        assert p["fitted"], (name, p)
        assert abs(p["value"] - want) <= max(2.0 * p["se"], 0.01 * want), (name, p, want)
    # the current limit is never reached apart from the torque constant: kept, and said why
    assert not doc["params"]["current_limit"]["fitted"] and "torque_constant" in doc["params"]["current_limit"]["kept"]
    h = doc["heldout"][str(src)]
    assert h["nominal"] > 5.0 and h["calibrated"] < 1.2
    v2, t2 = load_vehicle(str(out / "p3at_calibrated.yaml")), load_terrain(str(out / "vinyl_calibrated.yaml"))
    assert v2.mass == pytest.approx(doc["params"]["mass"]["value"])
    assert t2.mu_sa == pytest.approx(doc["params"]["mu_sa"]["value"])
    assert "fitted by sbmpc calibrate on drive.csv" in v2.sources["mass"]


@pytest.mark.slow
def test_a_hidden_effect_is_named_on_top_with_the_base_fitted_jointly(tmp_path, capsys):
    """The same kind of vehicle with a viscous friction hidden: calibrated alone, the base
    absorbs it (rolling resistance three times too large) and leaves over 3 noise units; each
    effect fitted jointly with the base names viscous_friction (within 5 % of the hidden
    coefficient), the base parameters back within 5 % of the truth's, and the vehicle file
    holds the joint fit with the effect."""
    v = P3AT.replace(mass=P3AT.mass * 0.9, inertia=P3AT.inertia * 0.9, torque_constant=P3AT.torque_constant * 1.07)
    t = VINYL.replace(mu_sa=VINYL.mu_sa * 0.92, mu_op=VINYL.mu_op * 1.1, mu_roll=VINYL.mu_roll * 0.9)
    run, hidden = synth_run("viscous_friction", 5, vehicle=v, terrain=t, duration=60.0)
    src = tmp_path / "drive.csv"
    write_run(src, run)
    out = tmp_path / "cal"
    assert main(["calibrate", str(src), "--vehicle", "p3at", "--terrain", "vinyl", "--out", str(out),
                 "--effects", "viscous_friction,command_delay"]) == 0
    doc = json.loads((out / "calibration.json").read_text())
    d = doc["diagnosis"][0]
    assert d["cause"] == "viscous_friction" and d["base_error"] > 3.0
    best = d["candidates"][0]
    assert best["params"]["c_Nms"] == pytest.approx(hidden["c_Nms"], rel=0.05)
    assert best["error"] < 1.2
    for name, want in (("mass", v.mass), ("torque_constant", v.torque_constant), ("mu_roll", t.mu_roll),
                       ("mu_sa", t.mu_sa), ("mu_op", t.mu_op)):
        assert best["base"][name] == pytest.approx(want, rel=0.05), name
    v2 = load_vehicle(str(out / "p3at_calibrated.yaml"))
    assert v2.viscous == pytest.approx(hidden["c_Nms"], rel=0.05) and v2.mass == pytest.approx(v.mass, rel=0.05)
    assert doc["with_effect"]["effect"] == "viscous_friction"


def test_what_the_runs_do_not_excite_is_kept_at_its_prior_and_said_so(tmp_path, capsys):
    """Wheel speeds alone (no efforts, no currents): the mass and the friction kept with
    the reason, the drive's reference acceleration fitted (it shapes every speed step);
    turns of one direction: the turning friction kept."""
    run, _ = synth_run("none", 3, duration=60.0)
    cols = {k: a for k, a in run.columns.items() if k not in ("tau_l", "tau_r", "i_l", "i_r")}
    src = tmp_path / "speeds.csv"
    write_run(src, Run(cols, run.meta, "speeds"))
    out = tmp_path / "cal"
    assert main(["calibrate", str(src), "--out", str(out), "--no-diagnose"]) == 0
    doc = json.loads((out / "calibration.json").read_text())
    for name in ("mass", "mu_roll", "mu_sa", "mu_op"):
        assert not doc["params"][name]["fitted"] and doc["params"][name]["kept"] == "no efforts or currents logged"
    assert doc["params"]["ref_accel"]["fitted"]
    exc = {"straight_s": 30.0, "left_turns_s": 20.0, "right_turns_s": 0.0, "accelerations_s": 10.0,
           "top_speed_s": 0.0, "efforts": True, "currents": False}
    why = chosen(exc)
    assert why["mass"] is True and why["mu_roll"] is True and why["torque_constant"] is True
    assert why["mu_sa"] == why["mu_op"] == "turns of one direction only, or none"
    assert chosen(dict(exc, accelerations_s=MIN_SECONDS / 2))["mass"] == "no accelerations"
    speeds = chosen(dict(exc, efforts=False, top_speed_s=10.0))
    assert speeds["torque_constant"] is True and speeds["mu_roll"] == "no efforts or currents logged"


def test_bad_arguments_get_one_line(tmp_path, capsys):
    run, _ = synth_run("none", 3, duration=30.0)
    src = tmp_path / "r.csv"
    write_run(src, run)
    assert main(["calibrate", str(src), "--out", str(tmp_path / "o"), "--only", "mass,wheels"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--only: expected parameters among mass" in err and "'wheels'" in err
    assert main(["calibrate", str(src), "--out", str(tmp_path / "o"), "--effects", "gremlins"]) == 2
    assert "--effects: expected effects among" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
    np.testing.assert_equal(len(list(tmp_path.iterdir())), 1)


@pytest.mark.slow
def test_a_grade_fixed_in_the_world_is_named_on_top_of_a_calibration():
    """The independent implementation's 90 s run on a plane rising 2.5 deg towards heading
    30 deg, calibrated, then the grade fitted jointly on top: with a logged pose it is
    fitted as a plane, felt along the logged heading, as diagnose does, and named with
    its grade and heading. Fitted along the body alone (before), calibrate-then-diagnose
    called the run unexplained (held-out error 10.7 noise units, the best candidate
    viscous friction)."""
    import sys
    import tempfile
    from pathlib import Path

    from dynamics.runs import read_run
    from sbmpc.calibration import calibrate, effects_on_top
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench" / "independent"))
    import sim
    truth = next(c[3] for c in sim.CASES if c[0] == "grade_2.5deg_world")
    with tempfile.TemporaryDirectory() as tmp:
        run = read_run(sim.write_case("grade_2.5deg_world", tmp)[0])
    cal = calibrate([run], P3AT, VINYL, only=["mass", "mu_roll"])
    d = effects_on_top(cal, [run], effects=("grade",))[0]
    assert d["cause"] == "grade"
    c = d["candidates"][0]
    assert c["params"]["grade_deg"] == pytest.approx(truth["grade_deg"], abs=0.15)
    assert c["params"]["toward_deg"] == pytest.approx(truth["toward_deg"], abs=3.0)
    assert c["error"] < 0.5 * d["base_error"]


def _independent_case(stem):
    """The independent implementation's 90 s run ``stem`` (batch 20240) and its truth."""
    import sys
    import tempfile
    from pathlib import Path

    from dynamics.runs import read_run
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench" / "independent"))
    import sim
    truth = next(c[3] for c in sim.CASES if c[0] == stem)
    with tempfile.TemporaryDirectory() as tmp:
        return read_run(sim.write_case(stem, tmp)[0]), truth


@pytest.mark.slow
def test_on_top_of_a_calibration_a_tyre_is_judged_on_the_pose_and_a_late_sag_on_the_held_out_part():
    """Calibrate, then diagnose, judged as diagnose judges (discrepancy.judge): the
    independent implementation's 7 % small left tyre is fitted to the logged pose and named
    on it (scales within 0.02 of the truth; on the wheel channels alone its batch 31000
    twin was fitted as 0.82 and 0.89), and its voltage sag, which acts only late in the
    run where the training part cannot see it, is fitted on the held-out part and named
    with the higher bar (before: `unexplained`, the sag 0.81 from an uninformed fit)."""
    from sbmpc.calibration import calibrate, effects_on_top
    run, truth = _independent_case("wheel_radius_left_7pct")
    cal = calibrate([run], P3AT, VINYL, only=["mass", "mu_roll"])
    d = effects_on_top(cal, [run], effects=("wheel_radius",))[0]
    assert d["cause"] == "wheel_radius" and d["decided_on"] == "pose"
    c = d["candidates"][0]
    assert c["params"]["scale_left"] == pytest.approx(truth["scale_left"], abs=0.02)
    assert c["params"]["scale_right"] == pytest.approx(truth["scale_right"], abs=0.02)
    assert c["pose_gain"] >= 0.5
    run, truth = _independent_case("voltage_sag_1.0")
    cal = calibrate([run], P3AT, VINYL, only=["mass", "mu_roll"])
    d = effects_on_top(cal, [run], effects=("voltage_sag",))[0]
    assert d["cause"] == "voltage_sag" and d["decided_on"] == "heldout_only"
    assert d["candidates"][0]["params"]["sag_V_per_kJ"] == pytest.approx(truth["sag_V_per_kJ"], abs=0.15)
    assert d["per_channel"]["wl"]["with_effect"] < d["per_channel"]["wl"]["base"]
