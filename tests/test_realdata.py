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
