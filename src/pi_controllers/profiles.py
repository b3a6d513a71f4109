"""Setpoint profiles (steps and ramps): the shared piecewise signal of :mod:`phfdi.profiles`."""

from phfdi.profiles import Change as SetpointChange
from phfdi.profiles import Profile as SetpointProfile

__all__ = ["SetpointChange", "SetpointProfile"]
