"""Units of recorded signals and scores, for the axes of every figure.

A variable's unit comes from its FMU's model description.  The controller declares none for u
(it is the same controller for a force and for a torque), so a controller output takes the unit of
the input that u drives: u, theta_j and w_hat (u = theta^T xi + w_hat, xi dimensionless) are in N
for the pendulum and in N.m for the manipulator.
"""
from __future__ import annotations

import functools

from fmpy import read_model_description

from .scenario_checks import resolve_fmu

#: controller outputs in the unit of u: the control itself, the rule weights and the error estimate
IN_UNITS_OF_U = ("u", "theta", "w_hat")


@functools.lru_cache(maxsize=None)
def _declared_units(fmu_path: str) -> dict:
    return {v.name: (v.unit or (v.declaredType.unit if v.declaredType is not None else None) or "")
            for v in read_model_description(fmu_path).modelVariables}


def _fmu_path(scenario, instance: str) -> str:
    return str(resolve_fmu(scenario.components[instance].fmu, scenario, None))


def variable_unit(scenario, dotted: str) -> str:
    """The unit of ``instance.variable`` in ``scenario`` ('' when dimensionless or unknown)."""
    instance, _, variable = dotted.partition(".")
    if instance not in scenario.components:
        return ""
    unit = _declared_units(_fmu_path(scenario, instance)).get(variable, "")
    if unit:
        return unit
    if instance == scenario.controller_instance and variable.startswith(IN_UNITS_OF_U):
        control = scenario.signals.get("u", f"{instance}.u")
        for connection in scenario.connections:
            if connection.source == control:
                return _declared_units(_fmu_path(scenario, connection.target_instance)).get(
                    connection.target_variable, "")
    return ""


def score_units(scenario) -> dict:
    """The unit of every score of harness/scores.py, with ||e|| counted in the unit of e."""
    u = variable_unit(scenario, scenario.signals.get("u", "")) or "u"
    e = variable_unit(scenario, scenario.signals.get("e", "")) or "e"
    return {"ts": "s", "es1_pct": "%", "es2_pct": "%", "ITAE": f"{e}.s2", "IAE": f"{e}.s",
            "Ec": f"({u})2.s" if "." in u or "/" in u else f"{u}2.s", "umax": u, "tv_u": f"{u}/s"}


def with_unit(name: str, unit: str) -> str:
    """``name (unit)``, or the bare name for a dimensionless quantity."""
    return f"{name} ({unit})" if unit else name
