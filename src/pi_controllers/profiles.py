"""Setpoint profiles (steps and ramps): the shared piecewise signal of :mod:`phfdi_base.profiles`."""

from phfdi_base.profiles import Change as SetpointChange
from phfdi_base.profiles import Profile as SetpointProfile

__all__ = ["SetpointChange", "SetpointProfile"]
