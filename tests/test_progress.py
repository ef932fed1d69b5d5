"""Progress lines of long searches: budget fractions, the best plan so far, time left."""
import pytest

from sbmpc import scenario as SC

from sbmpc.planning import problem as PB, world as WO
from sbmpc.commands.plan import Progress
from sbmpc.search.astar import Search


def test_progress_line_says_budget_share_best_plan_and_time_left():
    p = Progress("energy search", cost="energy")
    p.budgets(1000, 60.0)
    line = p.line(250, 2400, 2.0)
    assert "250 expansions of 1,000 (25 %)" in line and "2,400 nodes" in line
    assert "2.0 s of 60 s" in line and "no plan yet" in line
    # 250 expansions in 2 s: the node budget ends the search in at most 6 s more
    assert line.endswith("at most ~6 s left")
    assert "best plan so far 41.2 J" in p.line(250, 2400, 2.0, 41.23)
    # without budgets: no share, no time left
    bare = Progress("time search").line(10, 20, 0.5, 3.0)
    assert "%" not in bare and "left" not in bare and "best plan so far 3.0" in bare


@pytest.fixture(scope="module")
def flat_problem():
    world = WO.resolve(SC.load("scenarios/flat.yaml"))
    return PB.problem(world, "time")


def test_search_reports_the_incumbent_to_a_four_argument_callback(flat_problem):
    seen3, seen4 = [], []
    s = Search(flat_problem)
    s.bound(1e6)                                  # a warm start's incumbent
    s.run(400, chunk=16, progress=lambda i, n, t, best: seen4.append(best))
    assert seen4 and all(b is not None and b <= 1e6 for b in seen4)
    Search(flat_problem).run(400, chunk=16, progress=lambda i, n, t: seen3.append(i))
    assert seen3 and seen3 == sorted(seen3)
    seen0 = []
    Search(flat_problem).run(400, chunk=16, progress=lambda i, n, t, best=None: seen0.append(best))
    # no incumbent at the start: None until a goal is reached
    assert seen0 and seen0[0] is None
    seen_args = []
    Search(flat_problem).run(400, chunk=16, progress=lambda *a: seen_args.append(len(a)))
    assert seen_args and set(seen_args) == {3}        # *args callbacks keep three arguments


def test_the_search_states_its_own_budgets_to_the_progress_line(flat_problem):
    """The line shows the budgets the search runs under (a re-plan's shorter time
    budget, a command-line node budget), not the scenario's."""
    p = Progress("re-plan 1", cost="time")
    Search(flat_problem).run(400, 7.5, chunk=16, progress=p)
    assert (p.budget, p.time_budget) == (400, 7.5)
    assert "of 400 (" in p.line(100, 200, 1.0) and "1.0 s of 7.5 s" in p.line(100, 200, 1.0)
    Search(flat_problem).run(300, chunk=16, progress=p)           # no time budget
    assert (p.budget, p.time_budget) == (300, None)
