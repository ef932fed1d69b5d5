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
