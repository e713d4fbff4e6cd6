"""An independent in-process oracle: the same closed loop without FMI.

plant -> reference -> controller -> plant on the same communication grid
with the same held-input scheme as the master: at each communication point
t_n the outputs are evaluated (feedthrough: in dependency order; jacobi:
from the inputs set at the previous point), then the controller integrates
theta with ``theta += h * dtheta(t_n)`` and the plant integrates with
fixed-step RK4 while u is held.  It calls the same pure functions the FMUs
run (``fmu_src.afc_math``, ``plants.<name>.model``, ``plants.plant_integration``),
so co-simulation and oracle must agree to rounding.
"""
from __future__ import annotations

import math

import numpy as np

from harness.fmu_build import catalog as fmu_catalog
from fmu_src import afc_math
from plants import plant_integration
from plants import registry as plant_registry

from ..scenario import Scenario


def _parameters(scenario: Scenario, instance: str) -> dict:
    spec = scenario.components[instance]
    defaults = {v.name: v.start for v in fmu_catalog.model_class(spec.fmu).VARIABLES if v.causality == "parameter"}
    return {**defaults, **spec.parameters}


def simulate_oracle(scenario: Scenario, algorithm: str = "feedthrough") -> dict:
    """{"time": t, "instance.variable": array, ...} of the closed loop (no FMI)."""
    plant = _parameters(scenario, "plant")
    model = plant_registry.oracle_model(scenario.components["plant"].fmu, plant)  # plants/registry.py
    derivative, plant_params, plant_extra = model.derivative, model.params, model.extra
    reference = _parameters(scenario, "reference")
    controller = _parameters(scenario, "controller")
    amplitude, omega = reference["amplitude"], reference["omega"]
    variant = controller["variant"]
    gamma, m_theta, delta, gamma_w = (controller["gamma"], controller["m_theta"], controller["delta"],
                                      controller["gamma_w"])
    start, step, steps = scenario.start, scenario.step, scenario.steps
    max_internal_step = plant["max_internal_step"]

    def reference_outputs(t, y, dy):
        ym = amplitude * math.sin(omega * t)
        dym = amplitude * omega * math.cos(omega * t)
        return ym, dym, ym - y, dym - dy

    x1, x2 = float(plant["x1_start"]), float(plant["x2_start"])
    # initial values propagated in dependency order (both algorithms)
    ym, dym, e, de = reference_outputs(start, x1, x2)
    if controller.get("initial_error", 1) == 2:  # pinned by the parameters e0, de0
        error0 = (controller["e0"], controller["de0"])
    else:  # consistent start inputs: the latch keeps them
        error0 = (e, de)
    p = afc_math.controller_parameters(controller, error0, start)
    if p["order"] != 2:
        raise ValueError(f"the oracle knows second-order plants, not order = {p['order']}")
    theta, w_hat = [float(controller["theta0"])] * p["rules"], 0.0
    held_reference = (x1, x2)
    held_controller = ((e, de), (ym, dym))
    held_u = afc_math.controller_output((e, de), (ym, dym), start, theta, w_hat, p)[0]

    names = ["plant.y", "plant.dy", "reference.ym", "reference.dym", "reference.e", "reference.de",
             "controller.u", "controller.E", "controller.dE", "controller.alpha1", "controller.alpha2",
             *(f"controller.theta{j + 1}" for j in range(len(theta))),
             "controller.w_hat", *plant_extra(start, x1, x2)]
    table = np.empty((steps + 1, len(names)))
    for n in range(steps + 1):
        t = start + n * step
        if algorithm == "jacobi":
            ym, dym, e, de = reference_outputs(t, *held_reference)
            u, modified, alpha, _ = afc_math.controller_output(*held_controller, t, theta, w_hat, p)
        else:
            ym, dym, e, de = reference_outputs(t, x1, x2)
            u, modified, alpha, _ = afc_math.controller_output((e, de), (ym, dym), t, theta, w_hat, p)
        diagnostics = (*modified, *alpha)
        table[n] = (x1, x2, ym, dym, e, de, u, *diagnostics, *theta, w_hat if variant == afc_math.VARIANT_FAE else 0.0,
                    *plant_extra(t, x1, x2).values())
        if n == steps:
            break
        held_reference, held_controller, held_u = (x1, x2), ((e, de), (ym, dym)), u
        # controller: theta over [t, t + h] from E, dE, xi at t with its inputs as now set
        _, modified, _, xi = afc_math.controller_output(*held_controller, t, theta, w_hat, p)
        tau = afc_math.adaptation_signal(modified, p["p_b"])
        theta = afc_math.adapted_weights(theta, tau, xi, gamma, m_theta, delta, step)
        if variant == afc_math.VARIANT_FAE:
            w_hat += step * gamma_w * tau
        x1, x2 = plant_integration.rk4_advance(derivative, t, x1, x2, held_u, step, max_internal_step,
                                               plant_params)
    result = {"time": start + np.arange(steps + 1) * step}
    result.update({name: table[:, k] for k, name in enumerate(names)})
    return result
