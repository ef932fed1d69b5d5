import json
import subprocess
import sys

import pytest

from sbmpc.commands.cli import main

KEYS = ["t", "x", "y", "z", "yaw", "v", "yaw_rate", "wl", "wr", "tau_l", "tau_r", "power_W", "energy_J"]


def test_circle_json_and_plot(tmp_path, capsys):
    out, png = tmp_path / "c.json", tmp_path / "c.png"
    assert main(["simulate", "--v", "0.3", "--radius", "-1.0", "--duration", "4", "--json", str(out), "--plot", str(png)]) == 0
    doc = json.loads(out.read_text())
    traj = doc["trajectory"]
    assert set(KEYS) <= set(traj)
    assert max(b - a for a, b in zip(traj["t"], traj["t"][1:])) <= 0.05 + 1e-9
    assert len({len(traj[k]) for k in KEYS}) == 1
    assert doc["stalled"] is False
    assert traj["yaw_rate"][-1] < 0           # negative radius turns right
    assert png.stat().st_size > 10_000
    assert "circle on vinyl" in capsys.readouterr().out


def test_a_command_beyond_the_drive_is_noted(capsys):
    """A 2 m circle at 1 m/s on vinyl (the outer wheel needs 10 rad/s, the drive gives
    8.3): the vehicle drives nearly straight, and the summary says the drive ended short
    of the command (it printed stalled False and nothing else); at 0.6 m/s it turns as
    commanded, with no note."""
    assert main(["simulate", "--v", "1.0", "--radius", "2", "--duration", "5"]) == 0
    out = capsys.readouterr().out
    assert "note: the drive stays short of the commanded wheel speeds" in out and "right 8.2" in out
    assert "left" not in out.split("stays short")[1].split(":")[0]      # the left wheel reached its 8.18 rad/s
    for argv in (["--v", "0.6", "--radius", "2", "--duration", "5"],      # reached
                 ["--v", "0.5", "--duration", "0.3"],                     # still accelerating: no verdict
                 ["--v", "0.5", "--radius", "1", "--duration", "0.5"],    # overshoot is not short
                 ["--v", "0.3", "--duration", "0.0004"]):                # under half a step: no steps (was exit 3)
        assert main(["simulate", *argv]) == 0
        assert "note:" not in capsys.readouterr().out, argv


def test_ramp_reports_crossing_and_stall(tmp_path):
    out = tmp_path / "r.json"
    assert main(["simulate", "--terrain", "vinyl", "--v", "1.2", "--slope-deg", "17", "--v0", "0.3", "--length", "1",
                 "--duration", "4", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["crossed"] is False and doc["stalled"] is True


def test_open_loop_option_drives_the_closed_loops_current_profile(tmp_path):
    """The command line's --open-loop (Fig. 16): the open-loop model driven by the
    current profile the closed loop applies; the JSON says so. (The model's open loop
    itself is tested against eqs. 25-27 in test_closed_loop.)"""
    out = tmp_path / "o.json"
    assert main(["simulate", "--v", "0.5", "--open-loop", "--duration", "5", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["open_loop"] is True and doc["open_loop_input"] == "closed-loop current profile"
    assert doc["summary"]["final_speed_mps"] > 0


@pytest.mark.parametrize("argv, words", [
    (["simulate", "--v", "0.2", "--radius", "0"], "--radius"),
    (["simulate", "--terrain", "lava", "--v", "1"], "terrain 'lava'"),
    (["simulate", "--radius", "2"], "--v"),
    (["simulate", "--v", "1", "--slope-deg", "10", "--v0", "0.5"], "--length"),
    (["simulate", "--v", "1", "--slope-deg", "80", "--v0", "0.5", "--length", "2"], "--slope-deg"),
    (["simulate", "--v", "1", "--duration", "-1"], "--duration"),
    (["simulate", "--v", "1", "--json", "/no/such/dir/x.json"], "--json"),
    (["simulate", "--v", "1", "--slope-deg", "10", "--v0", "1", "--length", "1e300"], "--length: expected a length in (0, 10000]"),
    (["simulate", "--v", "1", "--slope-deg", "60", "--v0", "1", "--length", "1"], "strictly between -60 and 60"),
    (["simulate", "--v", "1", "--dt", "2"], "--dt: expected a step between"),
])
def test_bad_options_exit_2_with_one_line(argv, words, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err and "Traceback" not in err


def test_negative_values_need_no_equals_sign(capsys):
    """argparse took '-1e3' (and '-1,3') for an option and refused it; such values of the
    signed options are read as values."""
    assert main(["simulate", "--v", "0.3", "--radius", "-1e3", "--duration", "1"]) == 0
    assert "radius_m               -1000" in capsys.readouterr().out
    from pathlib import Path
    flat = Path(__file__).resolve().parents[1] / "scenarios" / "flat.yaml"
    assert main(["plan", str(flat), "--start", "-1,3"]) == 2
    err = capsys.readouterr().err
    assert "start (--start): expected (x, y) at least" in err and "found (-1, 3)" in err


def test_a_lemniscate_shorter_than_one_step_still_runs(capsys):
    """--duration under half a step rounded the lemniscate to no steps (an IndexError, exit 3)."""
    assert main(["simulate", "--lemniscate", "--dt", "0.05", "--duration", "0.001"]) == 0
    assert "lemniscate on vinyl" in capsys.readouterr().out


def test_unknown_option_and_module_entry():
    res = subprocess.run([sys.executable, "-m", "sbmpc", "simulate", "--vx", "1"], capture_output=True, text=True)
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and "unrecognized arguments: --vx" in res.stderr


def test_bad_vehicle_file_names_file_and_key(tmp_path, capsys):
    bad = tmp_path / "v.yaml"
    bad.write_text("mass: -1\n")
    assert main(["simulate", "--vehicle", str(bad), "--v", "1"]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "'mass'" in err
    assert bad.read_text() == "mass: -1\n"


def test_plot_format_follows_the_suffix_and_a_bad_one_is_refused_before_any_work(tmp_path, capsys):
    """A --plot path without a suffix ended in exit 3 (matplotlib read the temporary
    file's '.tmp' as the format), and one ending in .txt did too, after --json had been
    written. No suffix is PNG, .pdf is PDF, anything else exit 2 with nothing written."""
    assert main(["simulate", "--v", "0.5", "--duration", "0.5", "--plot", str(tmp_path / "plot")]) == 0
    assert (tmp_path / "plot").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["simulate", "--v", "0.5", "--duration", "0.5", "--plot", str(tmp_path / "p.PDF")]) == 0
    assert (tmp_path / "p.PDF").read_bytes()[:5] == b"%PDF-"
    capsys.readouterr()
    assert main(["simulate", "--v", "0.5", "--duration", "0.5", "--plot", str(tmp_path / "p.txt"),
                 "--json", str(tmp_path / "s.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert "--plot" in err and ".png" in err and "p.txt" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "s.json").exists() and not (tmp_path / "p.txt").exists()
