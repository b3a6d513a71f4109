"""Node parameters: declared from :class:`ParamSpec` lists, checked on launch and on every runtime change.

A node declares the :data:`COMMON_PARAMS` every node of the graph takes and its
own ``PARAMS``; a bad value at launch is one line (:class:`NodeStartError`,
exit status 2), a bad runtime change is refused with the reason and the old
value kept.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterUninitializedException,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

from phfdi_base.topics import LOOP_NODES

__all__ = ["COMMON_PARAMS", "NodeStartError", "ParamSpec", "ParametersMixin", "print_parameter_help"]


class NodeStartError(Exception):
    """The node cannot start: one line naming the problem (exit status 2)."""


@dataclass(frozen=True)
class ParamSpec:
    """A node parameter. ``default`` may be a callable of the loaded scenario."""

    name: str
    default: Any
    description: str
    range: tuple[float, float] | None = None
    choices: tuple[str, ...] | None = None
    runtime: bool = False  # may be changed while the node runs

    def default_for(self, spec) -> Any:
        return self.default(spec) if callable(self.default) else self.default

    def allowed(self) -> str:
        if self.range is not None:
            lo, hi = self.range
            if isinstance(self.default, int) and not isinstance(self.default, bool):
                return f"[{int(lo)}, {int(hi)}]"
            return f"[{lo:g}, {hi:g}]"
        if self.choices is not None:
            return "one of " + ", ".join(repr(c) for c in self.choices)
        return ""


#: parameters every node of the graph takes (the same values for all of them)
COMMON_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("part", "", "the node's part of the resolved scenario (JSON that phfdi launch writes); '' resolves "
                         "scenario, fault, fault_onset_s and overrides through the installed resolver"),
    ParamSpec("scenario", "paper", "scenario preset name or path of a scenario .yaml (every node loads the same)"),
    ParamSpec("fault", "", "fault from the library replacing the scenario's faults ('healthy' removes them); "
                           "'' keeps the scenario's"),
    ParamSpec("fault_onset_s", -1.0, "onset of the fault (s of simulated time); -1 keeps the fault's own onset",
              range=(-1.0, 1e9)),
    ParamSpec("overrides", [], "scenario overrides KEY=VALUE, as phfdi simulate --set"),
    ParamSpec("graph_nodes", list(LOOP_NODES), "names of the nodes of this graph; sample 0 waits until all are "
                                               "connected"),
    ParamSpec("connect_timeout_s", 60.0, "give up if the graph has not connected after this long (s, wall)",
              range=(0.1, 3600.0)),
    ParamSpec("executor", "events", "rclpy executor: events (fastest) or single_threaded",
              choices=("events", "single_threaded")),
)


def _param_type(value: Any) -> int:
    if isinstance(value, bool):
        return ParameterType.PARAMETER_BOOL
    if isinstance(value, int):
        return ParameterType.PARAMETER_INTEGER
    if isinstance(value, float):
        return ParameterType.PARAMETER_DOUBLE
    if isinstance(value, str):
        return ParameterType.PARAMETER_STRING
    if isinstance(value, list):
        return ParameterType.PARAMETER_STRING_ARRAY
    raise TypeError(f"unsupported parameter default {value!r}")


_TYPE_WORDS = {
    ParameterType.PARAMETER_BOOL: "a boolean (true or false)",
    ParameterType.PARAMETER_INTEGER: "an integer",
    ParameterType.PARAMETER_DOUBLE: "a double (write 2.0, not 2)",
    ParameterType.PARAMETER_STRING: "a string",
    ParameterType.PARAMETER_STRING_ARRAY: "a list of strings, e.g. \"[a, b]\"",
}



def common_params(runtime: Sequence[str]) -> tuple[ParamSpec, ...]:
    """:data:`COMMON_PARAMS`, those named in ``runtime`` changeable at runtime."""
    return tuple(ParamSpec(p.name, p.default, p.description, p.range, p.choices, True)
                 if p.name in runtime else p for p in COMMON_PARAMS)


class ParametersMixin(Node):
    """Declaring, reading and checking parameters (a part of :class:`~phfdi_base.ros.graph_node.GraphNode`)."""

    _specs: dict[str, ParamSpec]  # every parameter of the node, by name

    # ---- parameters -------------------------------------------------------------
    def _declare(self, specs: Sequence[ParamSpec], scenario) -> None:
        overrides = getattr(self, "_parameter_overrides", {})
        for p in specs:
            default = p.default_for(scenario)
            descriptor = ParameterDescriptor(name=p.name, type=_param_type(default), description=p.description,
                                             read_only=not p.runtime)
            if p.range is not None:
                lo, hi = p.range
                if isinstance(default, int) and not isinstance(default, bool):
                    descriptor.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
                else:
                    descriptor.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi),
                                                                          step=0.0)]
            if p.choices is not None:
                descriptor.additional_constraints = p.allowed()
            value = Parameter.Type.STRING_ARRAY if default == [] else default
            try:
                self.declare_parameter(p.name, value, descriptor)
            except InvalidParameterValueException:
                given = overrides[p.name].value if p.name in overrides else default
                raise NodeStartError(f"parameter {p.name} = {given!r} is outside the allowed range "
                                     f"{p.allowed()}") from None
            except InvalidParameterTypeException:
                given = overrides[p.name].value if p.name in overrides else default
                raise NodeStartError(f"parameter {p.name} must be {_TYPE_WORDS[descriptor.type]}, "
                                     f"got {given!r}") from None
            if p.choices is not None and self.param(p.name) not in p.choices:
                raise NodeStartError(f"parameter {p.name} = {self.param(p.name)!r} is not allowed: "
                                     f"{p.allowed()}")

    def _refuse_unknown_parameters(self) -> None:
        """One line for a parameter given at launch that this node does not have (a misspelt name was ignored
        without a word, e.g. ``--detector-param clear_after=60``); rclpy's own (use_sim_time, qos_overrides.*)
        pass."""
        import difflib

        given = getattr(self, "_parameter_overrides", {})
        unknown = sorted(n for n in given if n not in self._specs and not self.has_parameter(n)
                         and not n.startswith("qos_overrides."))
        if unknown:
            close = difflib.get_close_matches(unknown[0], list(self._specs), n=1)
            hint = f" (did you mean {close[0]}?)" if close else f"; it takes: {', '.join(sorted(self._specs))}"
            raise NodeStartError(f"unknown parameter {unknown[0]} for node {self.get_name()}{hint}")

    def param(self, name: str) -> Any:
        if self._specs[name].default == [] and not self.has_parameter(name):
            return []
        try:
            value = self.get_parameter(name).value
        except ParameterUninitializedException:  # an empty list declared by type: not given
            return []
        return [] if value is None and self._specs[name].default == [] else value

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        for p in params:
            spec = self._specs.get(p.name)
            if spec is not None and spec.choices is not None and p.value not in spec.choices:
                return SetParametersResult(successful=False,
                                           reason=f"{p.name} = {p.value!r} is not allowed: {spec.allowed()}")
        reason = self.check_parameters(params)
        if reason:
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _after_set_parameters(self, params: list[Parameter]) -> None:
        self.apply_parameters(params)

    def check_parameters(self, params: list[Parameter]) -> str | None:
        """Why a runtime change cannot be accepted (None: accepted). Ranges are checked already."""
        return None

    def apply_parameters(self, params: list[Parameter]) -> None:
        """Put accepted runtime changes into effect."""


def print_parameter_help(prog: str, summary: str, specs: Sequence[ParamSpec]) -> None:
    print(f"usage: python -m {prog} [--ros-args -p NAME:=VALUE ...]\n\n{summary}\n\nparameters:")
    for p in specs:
        default = "the scenario's" if callable(p.default) else repr(p.default)
        extra = f"; allowed {p.allowed()}" if p.allowed() else ""
        change = "; changeable at runtime" if p.runtime else ""
        print(f"  {p.name:22s} {p.description} (default {default}{extra}{change})")
