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


@pytest.fixture(scope="session")
def p3at():
    return load_vehicle("p3at")


@pytest.fixture(scope="session")
def vinyl():
    return Model.load("p3at", "vinyl")


@pytest.fixture(scope="session")
def asphalt():
    return Model.load("p3at", "asphalt")
