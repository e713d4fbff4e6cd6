"""The validated plan of a Monte Carlo study (:func:`plan_study`): the scenario, the controllers, the
distributions checked against the FMUs' valid ranges at the ends of what can be drawn, the design
(sampler, seed, samples), the noise seed's parameter, and the settings a resume must agree with.

Everything is checked before any run: an unknown parameter, an Integer parameter, a distribution
that can draw outside a parameter's valid range (a normal over a positive mass: give a truncated
normal) is one line.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field

import numpy as np

from ... import cli_args
from ... import scenario as scenarios
from ...master import ALGORITHMS
from ...scenario import Scenario, ScenarioError
from ...scenario_checks import model_info, resolve_fmu
from ...scores import SCORE_KEYS
from ...variants import CONTROLLER_VARIANTS
from .distributions import Distribution
from .draws import SAMPLERS, noise_seeds, parameter_values, unit_design

SEED_PARAMETER = f"{scenarios.SENSOR}.seed"  # the noise's global seed, where [hardware] inserted a sensor


@dataclass
class StudyPlan:
    scenario: Scenario  # with --stop / --step applied
    controllers: tuple
    distributions: tuple
    sampler: str
    seed: int
    samples: int
    objective: str
    algorithm: str = "feedthrough"
    fmu_files: dict = field(default_factory=dict)  # instance -> absolute path of its FMU

    @property
    def names(self) -> tuple:
        return tuple(d.name for d in self.distributions)

    @property
    def seed_parameter(self) -> str:
        """``sensor.seed`` when the scenario has a sensor (its noise drawn per sample), else ''."""
        return SEED_PARAMETER if scenarios.SENSOR in self.scenario.components else ""

    def settings(self) -> dict:
        """What a resume must agree with (the number of samples of a Sobol' design may grow)."""
        scenario = self.scenario
        parameters = {name: {k: v for k, v in spec.parameters.items()
                             if not (name == scenario.controller_instance and k == "variant")}
                      for name, spec in scenario.components.items()}
        settings = {"scenario": scenario.name, "start": scenario.start, "stop": scenario.stop, "step": scenario.step,
                    "algorithm": self.algorithm, "parameters": parameters,
                    "distributions": {d.name: d.settings() for d in self.distributions},
                    "sampler": self.sampler, "seed": self.seed, "noise_seed": self.seed_parameter}
        if self.sampler == "lhs":  # its strata depend on the number of samples
            settings["samples"] = self.samples
        return settings

    def fingerprint(self) -> str:
        text = json.dumps(self.settings(), sort_keys=True, default=repr)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def draws(self) -> tuple:
        """(values: samples x parameters, noise seeds or None) of the design."""
        design = unit_design(self.sampler, len(self.distributions), self.samples, self.seed)
        values = parameter_values(self.distributions, design)
        return values, (noise_seeds(self.seed, self.samples) if self.seed_parameter else None)

    def items(self):
        """((sample, controller), (controller, values)) for every sample, controllers innermost: the same
        values (parameters, then the noise seed) for every controller."""
        values, seeds = self.draws()
        for index in range(self.samples):
            drawn = tuple(float(v) for v in values[index])
            if seeds is not None:
                drawn += (int(seeds[index]),)
            for controller in self.controllers:
                yield (index, controller), (controller, drawn)


def plan_study(scenario_name, controllers, distributions, samples: int, sampler: str = "sobol", seed: int = 0,
               objective: str = "ITAE", stop=None, step=None, algorithm: str = "feedthrough",
               fmu_paths: dict | None = None) -> StudyPlan:
    """Validate the study against the scenario and the FMUs before any run."""
    scenario = scenarios.configure(scenario_name, step=step, stop=stop)
    controllers = tuple(dict.fromkeys(controllers))
    for controller in controllers:
        if controller not in CONTROLLER_VARIANTS:
            raise ScenarioError(f"unknown controller {controller!r}; valid: {', '.join(CONTROLLER_VARIANTS)}, all")
    if objective not in SCORE_KEYS:
        raise ScenarioError(f"unknown objective {objective!r}; valid: {', '.join(SCORE_KEYS)}")
    if sampler not in SAMPLERS:
        raise ScenarioError(f"unknown sampler {sampler!r}; valid: {', '.join(SAMPLERS)}")
    if algorithm not in ALGORITHMS:
        raise ScenarioError(f"unknown algorithm {algorithm!r}; valid: {', '.join(ALGORITHMS)}")
    if not isinstance(samples, int) or samples < 2:
        raise ScenarioError(f"--samples {samples}: need at least 2")
    if not 0 <= seed <= 2 ** 32 - 1:
        raise ScenarioError(f"--seed {seed}: valid 0 .. {2 ** 32 - 1}")
    plan = StudyPlan(scenario, controllers, tuple(distributions), sampler, seed, samples, objective, algorithm)
    if plan.seed_parameter and plan.seed_parameter in plan.names:
        raise ScenarioError(f"{plan.seed_parameter} is drawn per sample by the study (the noise seed): "
                            "do not give it a distribution")
    for distribution in plan.distributions:
        check_distribution(plan, distribution, fmu_paths)
    plan.fmu_files = {name: resolve_fmu(spec.fmu, scenario, fmu_paths).resolve()
                      for name, spec in scenario.components.items()}
    return plan


def check_distribution(plan: StudyPlan, distribution: Distribution, fmu_paths) -> None:
    """The parameter exists, is a Real parameter, and both ends of what can be drawn are valid."""
    scenario = plan.scenario
    instance, _, parameter = distribution.name.partition(".")
    option = f"--param {distribution.text()}"
    if distribution.name == f"{scenario.controller_instance}.variant":
        raise ScenarioError(f"{option}: the controller variant is chosen with --controller, not drawn")
    if instance in scenario.components:
        variable = model_info(scenario, instance, fmu_paths).variables.get(parameter)
        if variable is not None and variable.causality == "parameter" and variable.type != "Real":
            raise ScenarioError(f"{option}: {distribution.name} is an {variable.type}; a distribution draws Real values")
    low, high = distribution.support()
    ends = [(distribution.name, low), (distribution.name, high)]
    for end in ends:
        if not np.isfinite(end[1]):
            raise ScenarioError(f"{option}: its draws are not finite")
    try:
        cli_args.check_assignments(scenario, ends[:1], fmu_paths, option=option)
        cli_args.check_assignments(scenario, ends[1:], fmu_paths, option=option)
    except cli_args.UsageError as error:
        raise ScenarioError(f"{error} (the draws span {low:.6g} .. {high:.6g}"
                            + ("; a truncnormal bounds them" if distribution.kind == "normal" else "") + ")") from None


__all__ = ["StudyPlan", "plan_study", "SEED_PARAMETER"]
