"""The planner's edge on a map whose grade changes along the way, against the same edge
at the controller rate (1 ms): the step must take the grade at its midpoint."""
import math
from pathlib import Path

import pytest

from dynamics import kernels as K
from sbmpc.planning import check as CK
from sbmpc import scenario as SC
from sbmpc.planning import world as WO

SCEN = Path(__file__).resolve().parents[1] / "scenarios"


@pytest.fixture(scope="module")
def skirt():
    """steep_hill's start, 3 s into a straight run at 6 rad/s (1 kHz): on the hill's
    skirt, climbing about 6 deg towards it."""
    world = WO.resolve(SC.load(SCEN / "steep_hill.yaml"))
    X0 = WO.start_state(world)
    _, _, X, _ = CK.replay(world, "energy", [(6.0, 6.0, 3.0)], every=1 << 30, start=X0, dt=0.001)
    return world, X


@pytest.mark.parametrize("cmd", [(6.0, 7.0), (7.0, 6.0), (5.0, 8.6), (2.0, 6.0)])
def test_a_turn_up_a_hills_skirt_turns_as_at_the_controller_rate(skirt, cmd):
    """A 1 s turn up the skirt, the outer wheel at its current limit: the 20 ms edge turns
    within 0.2 % (and 0.003 deg) of the 1 ms one. With the grade held from each step's
    start it turned 1.4 % more for (6, 7) (0.865 against 0.853 deg), an error that
    halved with the step and summed over a 100 s plan to metres at the goal."""
    world, X = skirt
    turns = {}
    for dt in (0.02, 0.001):
        _, end, S, _ = CK.replay(world, "energy", [(cmd[0], cmd[1], 1.0)], every=1 << 30, start=X, dt=dt)
        assert end == 0
        turns[dt] = math.degrees(S[K.S_YAW] - X[K.S_YAW])
        if dt == 0.001 and cmd in ((6.0, 7.0), (7.0, 6.0)):
            # the regime: the outer wheel's current at the drive's limit
            outer = K.S_IR if cmd[1] > cmd[0] else K.S_IL
            assert abs(S[outer]) == pytest.approx(world.vehicle.current_limit, rel=1e-6)
    assert turns[0.02] == pytest.approx(turns[0.001], rel=2e-3, abs=3e-3)
    assert math.copysign(1.0, turns[0.001]) == math.copysign(1.0, cmd[1] - cmd[0])


def test_a_replay_without_a_record_drives_the_same_and_writes_nothing(skirt):
    """``skidsteer.replay`` with an empty record array (numba checks no bounds: it once
    wrote the start into row 0 regardless) returns 0 rows and the same end state, to
    the bit, as with every step recorded."""
    import numpy as np
    from sbmpc.planning import problem as PB
    from sbmpc.problems import skidsteer as SS
    world, X = skirt
    Q, data = PB.pack_world(world, "energy")
    cl, cr, n = np.array([6.0, 2.0]), np.array([7.0, 6.0]), np.array([50, 50], np.int64)
    full = np.zeros((101, K.NR))
    rows, S1, end1, e1 = SS.replay(Q, data, X, cl, cr, n, full)
    empty = np.zeros((0, K.NR))
    rows0, S0, end0, e0 = SS.replay(Q, data, X, cl, cr, n, empty)
    assert rows == 101 and rows0 == 0
    assert (end0, e0) == (end1, e1) and np.array_equal(S0, S1)
