"""dynamics: the closed-loop dynamic model of a skid-steered wheeled vehicle.

Yu, Chuy, Collins, Hollis, "Dynamic Modeling and Power Modeling of Robotic Skid-Steered
Wheeled Vehicles", IEEE Trans. Robotics 26(2), 2010. Every paper equation lives in one
named function that cites its number:

========================  ===========================================================
module                    holds
========================  ===========================================================
``params``                :class:`Vehicle`, :class:`Terrain`, YAML loading
``kinematics``            eqs. 1-3 and the inverse model of Fig. 8
``resistance``            eqs. 7-22: shear friction (exact and fast), rolling resistance
``body``                  eqs. 5, 23-25: mass matrix, gravity, wheel accelerations
``drive``                 Fig. 4 PID, eqs. 26-27 motor and controller, power
``kernels``               the compiled step and rollouts (the hot path)
``simulate``              :class:`Model`, :func:`simulate`, :class:`Trajectory`
``manoeuvres``            straight, circle, ramp, lemniscate (eqs. 29-30)
``limits``                steepest sustainable grade, top speed
``identify``              eq. 28: terrain parameters from steady torques
========================  ===========================================================
"""
from ._jitcache import refresh_once

refresh_once()     # numba's cache, consistent across files, before anything compiled loads

from .params import (ParameterError, Terrain, Vehicle, load_terrain, load_vehicle,
                     shipped_terrains, shipped_vehicles)
from .simulate import Model, Trajectory, simulate

__all__ = ["Model", "ParameterError", "Terrain", "Trajectory", "Vehicle", "load_terrain",
           "load_vehicle", "shipped_terrains", "shipped_vehicles", "simulate"]
