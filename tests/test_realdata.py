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
        train = rh.terrain_samples(BOREALTC / name, files[:k], v)
        held = rh.terrain_samples(BOREALTC / name, files[k:], v)
        assert train["wl"].size > 100 and held["wl"].size >= 10
        ter0 = load_terrain(rh.NOMINAL[name])
        fit = fit_friction(v, ter0, train["wl"], train["wr"], train["tau_l"], train["tau_r"], magnitudes=True)
        assert rh.rmse(v, fit["terrain"], held) < 0.8 * rh.rmse(v, ter0, held)
        mu[name] = fit["mu_sa"]
    assert mu["ICE"] < 0.5 * mu["FLOORING"]


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


def test_import_borealtc_on_a_real_asphalt_file(tmp_path, capsys):
    from dynamics.runs import read_run
    from sbmpc.commands.cli import main
    src = DRIVE.parent / "borealtc" / "ASPHALT" / "pro_00.csv"
    if not src.is_file():
        pytest.skip("the BorealTC runs are not beside the repository")
    out = tmp_path / "asphalt.csv"
    assert main(["import", "borealtc", str(src), "--out", str(out)]) == 0
    run = read_run(out)
    assert len(run) == 338 and run.meta["terrain"] == "asphalt" and run.meta["vehicle"] == "husky"
    assert main(["diagnose", str(out)]) == 0
    assert "cause:" in capsys.readouterr().out
