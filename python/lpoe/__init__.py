"""lpoe-calib: kinematic calibration of serial robots from laser-tracker measurements.

Local Product of Exponentials model (Gao et al. 2022); lengths in mm, angles in rad; numpy float64
arrays in and out. Errors in user input raise ``lpoe.Error`` (a ``ValueError``) whose message names
the file and line.
"""
from ._lpoe import *  # noqa: F401,F403
from ._lpoe import Calibration, Error, Model, Measurements  # noqa: F401

__all__ = [name for name in dir() if not name.startswith("_")]
