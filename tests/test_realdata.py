"""The public Warthog runs (Norlab DRIVE). Skipped when ../shared/data/real is absent:
the files are never copied into the repository."""
from pathlib import Path

import numpy as np
import pytest

DRIVE = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "drive"
pytestmark = pytest.mark.skipif(not DRIVE.is_dir(), reason="../shared/data/real/drive absent")


def test_drive_windows_join_into_a_timeline_and_replay():
    from dynamics import load_terrain, load_vehicle
    from dynamics.discrepancy import noise_scale, replay
    from sbmpc.realdata import read_drive_windows
    run = read_drive_windows(DRIVE / "drive_warthog_asphalt_windows.csv", "asphalt")
    assert len(run) == 12000 and np.all(np.diff(run.t) > 0)
    segs = run.segments()
    assert 1 <= len(segs) < 300                        # windows joined where contiguous
    assert sum(b - a for a, b in segs) >= 0.95 * len(run)
    assert 0.01 < noise_scale(run["wl"]) < 2.0         # held 4 Hz samples: from the changes
    pred = replay(run, load_vehicle("warthog"), load_terrain("asphalt"))
    rmse = np.sqrt(np.nanmean((run["wl"] - pred["wl"]) ** 2))
    assert np.isfinite(rmse) and rmse < np.nanstd(run["wl"])     # the model tracks the commands


def test_drive_pose_is_chained_and_gives_the_kinematic_alpha():
    """The ICP pose, relative to each 2 s window's start in the files, is chained into one
    continuous pose; eq. 1 fitted on the first 70 % agrees with the last 30 %."""
    from dynamics import load_vehicle
    from dynamics.identify import fit_kinematics
    from sbmpc.realdata import read_drive_windows
    v = load_vehicle("warthog")
    run = read_drive_windows(DRIVE / "drive_warthog_gravel_windows.csv", "gravel")
    t = run.t
    step = np.hypot(np.diff(run["x"]), np.diff(run["y"]))
    starts = np.isclose(np.remainder(t[1:], 2.0), 0.0, atol=1e-6)     # a window's first sample
    assert starts.sum() > 100 and np.all(step[starts] < 1e-9)          # continues where the last ended
    assert np.nanmax(np.abs(np.diff(run["yaw"]))) < np.pi              # unwrapped
    train = t < t[0] + 0.7 * (t[-1] - t[0])
    fits = [fit_kinematics(t, run["wl"], run["wr"], run["x"], run["y"], run["yaw"], v.wheel_radius, v.width, m,
                           segment=run["segment"]) for m in (train, ~train)]
    assert 1.2 < fits[0]["alpha"] < 2.5
    assert fits[1]["alpha"] == pytest.approx(fits[0]["alpha"], rel=0.1)


BOREALTC = DRIVE.parent / "borealtc"


@pytest.mark.skipif(not BOREALTC.is_dir(), reason="../shared/data/real/borealtc absent")
def test_borealtc_eq28_friction_ranks_the_terrains_and_beats_the_nominal_on_heldout_files():
    """Eq. 28 on the Husky's steady stretches (unsigned currents): ice has far less
    turning friction than indoor flooring, and each fitted terrain predicts the torques
    of files it was not fitted on better than the nearest shipped terrain."""
    import importlib.util
    from dynamics import load_terrain, load_vehicle
    from dynamics.identify import fit_friction
    spec = importlib.util.spec_from_file_location("real_husky", Path(__file__).resolve().parents[1] / "bench" / "real_husky.py")
    rh = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(rh)
    v = load_vehicle("husky")
    mu = {}
    for name in ("FLOORING", "ICE"):
        files = sorted(p.name for p in (BOREALTC / name).glob("*.csv"))
        k = int(round(0.7 * len(files)))
        train = rh.terrain_samples(BOREALTC / name, files[:k], v.torque_constant)
        held = rh.terrain_samples(BOREALTC / name, files[k:], v.torque_constant)
        assert train["wl"].size > 100 and held["wl"].size >= 10
        ter0 = load_terrain(rh.NOMINAL[name])
        fit = fit_friction(v, ter0, train["wl"], train["wr"], train["tau_l"], train["tau_r"], magnitudes=True)
        assert rh.rmse(v, fit["terrain"], held) < 0.8 * rh.rmse(v, ter0, held)
        mu[name] = fit["mu_sa"]
    assert mu["ICE"] < 0.5 * mu["FLOORING"]


def _drive_like(path, windows=6, jump_at=3):
    """A DRIVE-format windows CSV (20 Hz, 40 samples a window, pose relative to each
    window's start) of a vehicle driving straight at 1 m/s, with a wheel-speed jump
    across the boundary into window ``jump_at``."""
    import numpy as np
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


def test_import_drive_on_the_real_asphalt_run():
    from pathlib import Path
    from dynamics.runs import read_run
    from sbmpc.commands.cli import main
    src = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "drive" / "drive_warthog_asphalt_windows.csv"
    if not src.is_file():
        pytest.skip("the DRIVE runs are not beside the repository")
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "asphalt.csv"
        assert main(["import", "drive", str(src), "--out", str(out)]) == 0
        run = read_run(out)
        assert len(run) == 12000 and run.meta["terrain"] == "asphalt"
