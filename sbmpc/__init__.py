"""sbmpc: Sampling-Based Model Predictive Control for skid-steered robots on hilly terrain.

One call plans, compares or runs a scenario (a YAML file, a dict, or a heights array):
:func:`plan_scenario`, :func:`compare_scenario`, :func:`run_scenario`
(:mod:`sbmpc.api`; ``docs/python.md``); on a robot, :class:`Controller` (``step(t,
measurement) -> command``, :mod:`sbmpc.robot`; ``docs/robot.md``). The command line is ``sbmpc`` (``python -m sbmpc``).
"""
__version__ = "0.2.0"

_API = ("plan_scenario", "compare_scenario", "run_scenario", "load_scenario", "load_world")
_ROBOT = ("Controller", "Measurement", "Command")
__all__ = list(_API) + list(_ROBOT) + ["__version__"]


def __getattr__(name):
    # the API is imported on first use: `sbmpc --help` and `import sbmpc` stay fast
    if name in _API:
        from . import api
        return getattr(api, name)
    if name in _ROBOT:
        from . import robot
        return getattr(robot, name)
    raise AttributeError(f"module 'sbmpc' has no attribute {name!r}")
