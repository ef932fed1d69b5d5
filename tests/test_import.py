"""`sbmpc import drive|borealtc` on small files in each dataset's format, made here (the
real runs are never copied into the repository; tests/test_realdata.py uses them when
they are beside it)."""
import numpy as np
import pytest

from dynamics.runs import read_run
from sbmpc.commands.cli import main


def _drive_like(path, windows=6, jump_at=3):
    """A DRIVE-format windows CSV (20 Hz, 40 samples a window, pose relative to each
    window's start) of a vehicle driving straight at 1 m/s, with a wheel-speed jump
    across the boundary into window ``jump_at``."""
    rows = []
    for w in range(windows):
        for k in range(40):
            t = 0.05 * k
            wl = wr = 3.0 + (4.0 if w >= jump_at else 0.0)
            rows.append([w, w // 2, 1, k, t, wl, wr, wl, wr, t * 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    head = ("window,calib_step,steady,k,t,cmd_left,cmd_right,left_wheel_vel,right_wheel_vel,"
            "icp_x,icp_y,icp_z,icp_roll,icp_pitch,icp_yaw,imu_yaw")
    path.write_text(head + "\n" + "\n".join(",".join(f"{v:g}" for v in r) for r in rows) + "\n")
    return path


def test_import_drive_writes_a_run_csv_that_diagnose_reads(tmp_path, capsys):
    from dynamics.runs import read_run
    from sbmpc.commands.cli import main
    src = _drive_like(tmp_path / "drive_warthog_gravel_windows.csv")
    before = src.read_bytes()
    assert main(["import", "drive", str(src), "--out", str(tmp_path / "run.csv")]) == 0
    assert "terrain packed_dirt" in capsys.readouterr().out
    run = read_run(tmp_path / "run.csv")
    assert run.meta["vehicle"] == "warthog" and run.meta["terrain"] == "packed_dirt" and "gravel" in run.meta["note"]
    assert len(run) == 240 and len(run.segments()) == 2            # the jump breaks the timeline once
    assert abs(run["x"][-1] - (6 * 1.95)) < 1e-6                    # the windows' poses chained
    assert src.read_bytes() == before
    assert main(["import", "drive", str(src), "--out", str(src)]) == 2
    assert "is an input" in capsys.readouterr().err
    odd = _drive_like(tmp_path / "mystery.csv")
    assert main(["import", "drive", str(odd), "--out", str(tmp_path / "r2.csv")]) == 2
    assert "--terrain: expected the run's terrain" in capsys.readouterr().err


def _borealtc_like(path, n=200, rate=6.5):
    """A BorealTC-format pro_XX.csv: a Husky driving forward, then backward, then turning
    on the spot, at the dataset's 6.5 Hz with its 1/127 m/s speed quantum and unsigned
    currents."""
    t = np.arange(n) / rate
    third = n // 3
    v_l = np.r_[np.full(third, 0.5), np.full(third, -0.4), np.full(n - 2 * third, 0.3)]
    v_r = np.r_[np.full(third, 0.5), np.full(third, -0.4), np.full(n - 2 * third, -0.3)]
    v_l, v_r = np.round(v_l * 127) / 127, np.round(v_r * 127) / 127
    cur = np.r_[np.full(third, 4.0), np.full(third, 3.0), np.full(n - 2 * third, 12.0)]
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = [f"{a:.9g},{c:g},{c:g},{l:.9g},{r:.9g}" for a, c, l, r in zip(t, cur, v_l, v_r)]
    path.write_text("time,curL,curR,velL,velR\n" + "\n".join(rows) + "\n")
    return path


def test_import_borealtc_writes_an_unsigned_run_that_diagnose_reads(tmp_path, capsys):
    src = _borealtc_like(tmp_path / "SANDY_LOAM" / "pro_03.csv")
    before = src.read_bytes()
    out = tmp_path / "run.csv"
    assert main(["import", "borealtc", str(src), "--out", str(out)]) == 0
    assert "terrain grass" in capsys.readouterr().out                  # SANDY_LOAM's nearest shipped terrain
    run = read_run(out)
    assert src.read_bytes() == before
    assert run.meta["vehicle"] == "husky" and run.meta["terrain"] == "grass" and "SANDY_LOAM" in run.meta["note"]
    assert len(run) == 200 and len(run.segments()) == 1
    assert np.allclose(run["wl"][:10], np.round(0.5 * 127) / 127 / 0.13, atol=1e-5)   # m/s over the 0.13 m radius
    assert np.array_equal(run["wl_cmd"], run["wl"]) and np.array_equal(run["wr_cmd"], run["wr"])
    # the currents stay magnitudes, and the file says so (the replay compares magnitudes)
    assert run.meta["currents"] == "unsigned" and np.all(run["i_l"] > 0) and np.all(run["i_r"] > 0)
    rc = main(["diagnose", str(out)])
    assert rc == 0 and "cause:" in capsys.readouterr().out


def test_import_borealtc_names_what_is_wrong(tmp_path, capsys):
    odd = _borealtc_like(tmp_path / "somewhere" / "pro_00.csv")
    assert main(["import", "borealtc", str(odd), "--out", str(tmp_path / "r.csv")]) == 2
    assert "--terrain: expected the run's terrain (the folder name 'somewhere'" in capsys.readouterr().err
    assert main(["import", "borealtc", str(odd), "--terrain", "ICE", "--out", str(tmp_path / "r.csv")]) == 0
    assert read_run(tmp_path / "r.csv").meta["terrain"] == "vinyl"
    capsys.readouterr()
    bad = tmp_path / "ASPHALT" / "pro_01.csv"
    bad.parent.mkdir()
    bad.write_text("time,curL,velL\n0,1,0.1\n0.15,1,0.1\n")
    assert main(["import", "borealtc", str(bad), "--out", str(tmp_path / "r2.csv")]) == 2
    err = capsys.readouterr().err
    assert "expected the BorealTC columns" in err and "curR" in err and "Traceback" not in err
    assert not (tmp_path / "r2.csv").exists()
    for name, text, says in [("empty", "", "cannot be read"),
                             ("header_only", "time,curL,curR,velL,velR\n", "with data rows, found the header alone"),
                             ("one_row", "time,curL,curR,velL,velR\n0,1,1,0.1,0.1\n", "fewer than 2 rows"),
                             ("inf", "time,curL,curR,velL,velR\n0,1,1,0.1,0.1\n0.15,1,1,inf,0.1\n", "column velL"),
                             ("text", "time,curL,curR,velL,velR\n0,1,1,0.1,0.1\n0.15,x,1,0.1,0.1\n", "column curL"),
                             ("backwards", "time,curL,curR,velL,velR\n0.3,1,1,0.1,0.1\n0.15,1,1,0.1,0.1\n",
                              "data row 2, column time: expected strictly increasing times, found 0.15 after 0.3")]:
        f = tmp_path / "ASPHALT" / f"{name}.csv"
        f.write_text(text)
        assert main(["import", "borealtc", str(f), "--out", str(tmp_path / f"{name}_run.csv")]) == 2, name
        err = capsys.readouterr().err
        assert says in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, (name, err)


def test_import_drive_names_what_is_wrong(tmp_path, capsys):
    """A bad cell is named by its line and column (it was written as an empty time, and
    diagnose refused the file); a terrain that is neither DRIVE's nor a shipped one, and
    a folder given as the source, are refused before anything is written."""
    src = _drive_like(tmp_path / "drive_warthog_sand_windows.csv")
    lines = src.read_text().splitlines()
    cells = lines[7].split(",")
    cells[4] = "x"                                   # the t of the 7th sample: line 8 of the file
    bad = tmp_path / "drive_warthog_asphalt_windows.csv"
    bad.write_text("\n".join(lines[:7] + [",".join(cells)] + lines[8:]) + "\n")
    out = tmp_path / "run.csv"
    for argv, says in [([str(bad)], f"{bad}, line 8, column t: expected a finite number"),
                       ([str(src), "--terrain", "lava"], "--terrain: expected a DRIVE terrain (asphalt, gravel, sand), "
                                                         "or a shipped terrain name or terrain file, found 'lava'"),
                       ([str(tmp_path)], f"{tmp_path}: expected a DRIVE windows CSV file, found a folder")]:
        assert main(["import", "drive", *argv, "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert says in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
        assert not out.exists()
    assert main(["import", "drive", str(src), "--terrain", "vinyl", "--out", str(out)]) == 0   # a shipped name
    assert read_run(out).meta["terrain"] == "vinyl"
    assert main(["import", "drive", str(src), "--terrain", "GRAVEL", "--out", str(out)]) == 0  # any case, as BorealTC's
    assert read_run(out).meta["terrain"] == "packed_dirt"
    capsys.readouterr()
    # the header alone (exit 3 before), a row written twice (imported, then refused by diagnose),
    # a row cut short (a two-line message), an empty file ('list index out of range')
    head = lines[0]
    for name, text, says in [("header", head + "\n", "with data rows, found the header alone"),
                             ("twice", "\n".join(lines[:6] + [lines[5]] + lines[6:]) + "\n",
                              "expected one row per time, found window 0 t = 0.2 s twice"),
                             ("cut", "\n".join(lines[:9] + [",".join(lines[9].split(",")[:7])] + lines[10:]) + "\n",
                              "line 10 has 7 cells where the header names 16"),
                             ("empty", "", "(no header row)")]:
        f = tmp_path / f"drive_warthog_sand_{name}.csv"
        f.write_text(text)
        assert main(["import", "drive", str(f), "--out", str(tmp_path / f"{name}.csv")]) == 2, name
        err = capsys.readouterr().err
        assert says in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err, (name, err)


def test_a_terrain_file_named_in_a_runs_header_is_found_beside_the_run(tmp_path, capsys, monkeypatch):
    """import --terrain sub/t.yaml --out sub/run.csv wrote '# terrain: sub/t.yaml', which
    diagnose read from the current folder: run from sub/ it was not found. The header
    names the file from the run's folder, and diagnose reads it from there."""
    src = _borealtc_like(tmp_path / "ASPHALT" / "pro_02.csv")
    sub = tmp_path / "sub"
    sub.mkdir()
    (sub / "t.yaml").write_text("base: asphalt\nname: mine\nmu_roll: 0.05\n")
    monkeypatch.chdir(tmp_path)
    assert main(["import", "borealtc", str(src), "--terrain", "sub/t.yaml", "--out", "sub/run.csv"]) == 0
    assert read_run(sub / "run.csv").meta["terrain"] == "t.yaml"
    monkeypatch.chdir(sub)
    assert main(["diagnose", "run.csv", "--json", "d.json"]) == 0
    monkeypatch.chdir(tmp_path)
    assert main(["diagnose", "sub/run.csv"]) == 0
    capsys.readouterr()
    monkeypatch.setenv("SBMPC_MAX_RUN_ROWS", "abc")                      # was a ValueError, exit 3
    assert main(["diagnose", "sub/run.csv"]) == 2
    assert "environment variable SBMPC_MAX_RUN_ROWS: expected a positive whole number, found 'abc'" in capsys.readouterr().err


def test_a_bad_cell_is_named_by_its_line_behind_blank_comment_and_hash_header_lines(tmp_path, capsys):
    lines = _drive_like(tmp_path / "src.csv").read_text().splitlines()
    cells = lines[3].split(",")
    cells[5] = ""                                    # cmd_left of the 3rd sample
    text = "\n".join(["", "#" + lines[0], "# a comment", lines[1], "", lines[2], ",".join(cells)] + lines[4:]) + "\n"
    bad = tmp_path / "drive_warthog_asphalt_windows.csv"
    bad.write_text(text)                             # the bad cell is on line 7
    assert main(["import", "drive", str(bad), "--out", str(tmp_path / "r.csv")]) == 2
    assert f"{bad}, line 7, column cmd_left: expected a finite number" in capsys.readouterr().err


def test_borealtc_from_python_checks_the_radius_and_names_the_terrain_by_its_folder(tmp_path):
    """read_borealtc(wheel_radius=0) gave infinite wheel speeds; read_borealtc_run without
    a terrain wrote '# terrain: ' and diagnose silently took vinyl."""
    import pytest
    from dynamics.runs import RunError
    from sbmpc.realdata import read_borealtc, read_borealtc_run
    src = _borealtc_like(tmp_path / "ASPHALT" / "pro_04.csv")
    with pytest.raises(RunError, match=r"wheel_radius: expected a radius in \(0, 5\] m, found 0"):
        read_borealtc(src, wheel_radius=0)
    assert read_borealtc_run(src).meta["terrain"] == "asphalt"
    assert "terrain" not in read_borealtc_run(_borealtc_like(tmp_path / "elsewhere" / "pro_05.csv")).meta


def test_an_unsigned_current_log_is_replayed_as_magnitudes(tmp_path):
    """A driver that logs current magnitudes (BorealTC's Husky): with ``# currents:
    unsigned`` the replay of the generating model matches the log within its noise
    forwards, backwards and in a pivot, where signed it would miss twice the current
    wherever a wheel drives backwards. A metadata value other than signed or unsigned is
    refused."""
    from dynamics.discrepancy import _error, channels, noise_scale, replay
    from dynamics.params import load_terrain, load_vehicle
    from dynamics.runs import Run, RunError, write_run
    from dynamics.synth import synth_run
    run, _ = synth_run("none", 3, load_vehicle("husky"), load_terrain("asphalt"), duration=30.0)
    assert np.any(run["i_l"] < -1.0) and np.any(run["i_r"] < -1.0)     # the drive brakes and reverses
    cols = {k: v for k, v in run.columns.items() if not k.startswith("tau")}      # a log of currents
    cols.update(i_l=np.abs(run["i_l"]), i_r=np.abs(run["i_r"]))
    path = tmp_path / "unsigned.csv"
    write_run(path, Run(cols, dict(run.meta, currents="unsigned"), "unsigned.csv"))
    unsigned = read_run(path)
    signed = Run(unsigned.columns, {k: v for k, v in unsigned.meta.items() if k != "currents"}, "signed")
    v, t = load_vehicle("husky"), load_terrain("asphalt")
    chans = channels(unsigned)
    assert chans == ("wl", "wr", "i_l", "i_r")
    scales = {c: noise_scale(run[c]) for c in chans}          # the signed log's noise
    every = np.ones(len(run), bool)
    pred = replay(unsigned, v, t)
    assert np.all(pred["i_l"][np.isfinite(pred["i_l"])] >= 0.0)
    assert _error(unsigned, pred, chans, scales, every) < 1.5
    assert _error(signed, replay(signed, v, t), chans, scales, every) > 3.0
    text = path.read_text().replace("# currents: unsigned", "# currents: absolute")
    path.write_text(text)
    with pytest.raises(RunError, match="metadata currents: expected signed or unsigned, found 'absolute'"):
        read_run(path)
