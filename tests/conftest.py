import pytest

from dynamics import Model, load_vehicle

# Hypothesis: few, deterministic examples; numba kernels are compiled once per run.
try:
    from hypothesis import HealthCheck, settings
    settings.register_profile("ci", max_examples=25, deadline=None, derandomize=True,
                              suppress_health_check=[HealthCheck.too_slow])
    settings.load_profile("ci")
except ImportError:  # pragma: no cover
    pass


def pytest_configure(config):
    """On both cores (pytest-xdist, the default: pyproject's addopts), the controller
    process compiles numba's main kernels once, into the on-disk cache, before the
    workers start: each worker compiling them at once took a fresh clone's suite from 11
    min 43 s (one process) to 12 min 33 s on two cores, 24 min of CPU (2026-12-06)."""
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    from pathlib import Path

    from dynamics.manoeuvres import straight
    from dynamics.simulate import simulate
    from sbmpc import scenario as SC
    from sbmpc.planning import plan as PL
    from sbmpc.planning import world as WO
    model = Model.load("p3at", "vinyl")
    simulate(model, *straight(model, 1.0, 1.0))
    PL.plan(WO.resolve(SC.load(Path(__file__).parents[1] / "scenarios" / "flat.yaml")), "energy")


@pytest.fixture(scope="session")
def p3at():
    return load_vehicle("p3at")


@pytest.fixture(scope="session")
def vinyl():
    return Model.load("p3at", "vinyl")


@pytest.fixture(scope="session")
def asphalt():
    return Model.load("p3at", "asphalt")
