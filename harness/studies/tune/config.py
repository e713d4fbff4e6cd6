"""The configuration of a study: its options (:class:`TuneConfig`), and every input checked before
the database is opened (:func:`prepare`: a TuneError names the culprit, nothing is written)."""
from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass
from pathlib import Path

from harness.fmu_build import builder as build_fmu

from ... import cli_args, variants
from ... import scenario as scenarios
from ...fmi import ModelInfo
from ...master import resolve_fmu
from ...scores import REFERENCE_PERIOD, undefined_reason
from .errors import TuneError
from .objective import parse_constraint, parse_vary, robust_grid, score_name
from .space import CONTROLLER_MODEL, declared_parameters, paper_conditions, search_space

DEFAULT_OUT = Path("results") / "tune"  # under the working directory, like the other studies
DEFAULT_TRIALS = 200
VERIFY_TOLERANCE = 0.01  # a best candidate whose objective moves more at half the step is an artefact
SAMPLERS = ("tpe", "cmaes")
# held-out scenarios for the tuned-vs-start comparison: the other pendulum cases (disturbance, heavy pole)
HELD_OUT = {"pendulum_case1": ("pendulum_case2", "pendulum_case3")}


@dataclass
class TuneConfig:
    scenario: object  # name or .toml path
    controller: str = "vud"
    objective: str = "ITAE"
    constraints: tuple = ()
    trials: int = DEFAULT_TRIALS
    seed: int = 0
    storage: str | None = None  # None: sqlite:///<out>/<scenario>.db
    study: str | None = None  # None: <scenario>-<controller>-<objective>[-robust]
    sampler: str = "tpe"
    jobs: int = 1
    scheduler: str | None = None  # a Dask scheduler's address: the trials run on its workers
    stop: float | None = None
    edition: str = "python"
    robust: bool = False
    vary: tuple = ()
    params: tuple = ()
    ranges: tuple = ()  # ((name, low, high), ...)
    out: Path = DEFAULT_OUT
    tolerance: float = VERIFY_TOLERANCE
    held_out: tuple | None = None  # None: HELD_OUT of the scenario
    quiet: bool = False
    fmu_paths: dict | None = None


@dataclass
class Prepared:
    """Everything checked before the database is opened."""

    config: TuneConfig
    scenario: object  # the configured Scenario (controller variant, stop)
    table: dict
    dimensions: list
    fixed: dict  # every controller parameter's value before tuning (table start values, then the scenario's)
    grid: list
    constraints: tuple
    fmu_paths: dict
    study_name: str
    storage_url: str  # as given: may hold a password, so never printed or written (storage_shown is)
    signature: dict
    held_out: tuple

    @property
    def storage_shown(self) -> str:
        """The database's URL as messages, logs and files show it: its password masked (***)."""
        return shown_url(self.storage_url)


def _parsed_url(url: str):
    from sqlalchemy.engine import make_url  # Optuna's dependency (the tune extra)

    return make_url(url)


def shown_url(url: str) -> str:
    """``url`` with its password, if any, masked as ``***`` (SQLAlchemy's own rendering)."""
    try:
        return _parsed_url(url).render_as_string(hide_password=True)
    except Exception:  # noqa: BLE001 - not a URL SQLAlchemy reads: mask whatever sits between ':' and '@'
        return re.sub(r"(//[^/:@]*):[^@/]*@", r"\1:***@", url)


def url_without_password(url: str) -> str:
    """``url`` without its password: libpq (PostgreSQL's client library) then takes it from
    PGPASSWORD or the password file (~/.pgpass, or PGPASSFILE), as optuna-dashboard does too."""
    try:
        from sqlalchemy.engine import URL

        parsed = _parsed_url(url)
        return URL.create(parsed.drivername, parsed.username, None, parsed.host, parsed.port, parsed.database,
                          parsed.query).render_as_string(hide_password=False)
    except Exception:  # noqa: BLE001 - as above
        return shown_url(url)


def has_password(url: str) -> bool:
    try:
        return _parsed_url(url).password is not None
    except Exception:  # noqa: BLE001 - as above
        return shown_url(url) != url


def _digest(scenario) -> str:
    data = {"start": scenario.start,  # stop and step are signature entries of their own
            "components": {n: [c.fmu, sorted(c.parameters.items())] for n, c in scenario.components.items()},
            "connections": [[c.source, c.target] for c in scenario.connections],
            "signals": sorted(scenario.signals.items()), "bounds": sorted(scenario.bounds.items()),
            "divergence_bound": scenario.divergence_bound}
    return hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode()).hexdigest()[:16]


def default_study_name(scenario: str, controller: str, objective: str, constraints, robust: bool, seed: int) -> str:
    """SCENARIO-CONTROLLER-OBJECTIVE[-CONSTRAINTS][-robust][-seedN]: every setting that changes the
    trials names the study (the seed when it is not 0, so that the names of the studies made before
    the seed joined them stay theirs); the rest of its settings are in its signature (storage.py)."""
    return "-".join([scenario, controller, objective]
                    + [f"{c.score}{'le' if c.operator == '<=' else 'ge'}{c.limit:g}" for c in constraints]
                    + (["robust"] if robust else []) + ([f"seed{seed}"] if seed else []))


def prepare(config: TuneConfig) -> Prepared:
    """Check every input (TuneError names the culprit); nothing is written and no database is opened."""

    if config.controller not in variants.NAMES:
        raise TuneError(f"unknown controller {config.controller!r}; valid: {', '.join(variants.NAMES)}")
    if config.sampler not in SAMPLERS:
        raise TuneError(f"unknown sampler {config.sampler!r}; valid: {', '.join(SAMPLERS)}")
    objective = score_name(config.objective)
    constraints = tuple(parse_constraint(c) if isinstance(c, str) else c for c in config.constraints)
    if config.trials < 1:
        raise TuneError(f"--trials {config.trials}: give a whole number >= 1")
    if not 0 < config.tolerance:
        raise TuneError(f"--verify-tolerance: give a number > 0 (percent), not {100 * config.tolerance:g}")
    scenario = scenarios.configure(config.scenario, config.controller, stop=config.stop)
    for score in dict.fromkeys((objective, *(c.score for c in constraints))):
        reason = undefined_reason(score, scenario.start, scenario.stop)
        if reason is not None:
            raise TuneError(f"{score} is not defined on this run: {reason}; give --stop of at least "
                            f"{scenario.start + REFERENCE_PERIOD:.4g} s or another score")
    fmu_paths = config.fmu_paths
    if fmu_paths is None:

        fmu_paths = build_fmu.ensure_built(edition=config.edition)
    infos = {name: ModelInfo.read(resolve_fmu(spec.fmu, scenario, fmu_paths))
             for name, spec in scenario.components.items()}
    controller = scenario.controller_instance
    if infos[controller].model_identifier != CONTROLLER_MODEL:
        raise TuneError(f"tune searches the parameters of {CONTROLLER_MODEL}; the scenario's controller_instance "
                        f"{controller!r} is {infos[controller].model_identifier}")
    table = declared_parameters()
    fixed = {name: v.start for name, v in table.items()}
    fixed.update(scenario.components[controller].parameters)
    variant, order = int(fixed["variant"]), int(fixed["order"])
    ranges = {}
    for name, low, high in config.ranges:
        ranges[name] = (low, high)
    dimensions = search_space(variant, order, table, only=config.params, ranges=ranges)
    if not dimensions:
        raise TuneError("nothing to search: no tunable parameter acts here")
    problem = paper_conditions(fixed, table)
    if problem:
        raise TuneError(f"the scenario's controller parameters: {problem}")
    grid = [()]
    if config.robust or config.vary:
        grid = robust_grid(scenario, [parse_vary(v) if isinstance(v, str) else v for v in config.vary], infos)
        for point in grid:  # values the FMUs reject (a mass < 0, ...) are usage errors, before anything runs
            cli_args.check_assignments(scenario, list(point), fmu_paths, option="--vary")
    held_out = tuple(config.held_out) if config.held_out is not None else HELD_OUT.get(scenario.name, ())
    for name in held_out:
        scenarios.load(name)
    study_name = config.study or default_study_name(scenario.name, config.controller, objective, constraints,
                                                    len(grid) > 1, config.seed)
    storage_url = config.storage or f"sqlite:///{Path(config.out) / scenario.name}.db"
    signature = {"scenario": scenario.name, "scenario_digest": _digest(scenario), "controller": config.controller,
                 "objective": objective, "constraints": sorted(c.text for c in constraints),
                 "grid": [[list(item) for item in point] for point in grid], "step": scenario.step,
                 "stop": scenario.stop, "edition": config.edition, "sampler": config.sampler,
                 "space": [[d.parameter, d.low, d.high, d.scale] for d in dimensions],
                 "tolerance": config.tolerance}
    config.objective = objective
    return Prepared(config, scenario, table, dimensions, fixed, grid, constraints, fmu_paths, study_name,
                    storage_url, signature, held_out)
