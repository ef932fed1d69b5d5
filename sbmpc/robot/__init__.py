"""The planner on a robot: the controller its loop calls, what it measures and commands,
and shadow runs on its bags.

* :class:`Controller` (:mod:`sbmpc.robot.controller`): ``step(t, measurement) -> command``
  at 10-20 Hz, the receding-horizon policy inside, the planning in worker threads;
* :class:`Measurement`, :class:`Command`, :func:`to_twist`, :func:`to_wheels`
  (:mod:`sbmpc.robot.messages`);
* :class:`Estimator` (:mod:`sbmpc.robot.estimator`): the model's state from measurements;
* :func:`shadow` (:mod:`sbmpc.robot.shadow`): the controller over a recorded drive.

``docs/robot.md`` walks through it; ``examples/ros2_node.py`` is a ROS 2 node around it.
"""
from .controller import Controller
from .estimator import Estimator
from .messages import Command, Measurement, to_twist, to_wheels

__all__ = ["Controller", "Command", "Estimator", "Measurement", "to_twist", "to_wheels"]
