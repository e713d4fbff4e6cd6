"""The ladders of runs that estimate a score's distance to the continuous-time value of the model.

A co-simulation's error depends on its communication step h and on the plant's internal RK4 step h_p
(plants/plant_integration.py: h split into ceil(h / max_internal_step) equal steps).  A case's ladder
refines both (harness/studies/claims.py turns it into value +- error, docs/verification.md):

* the communication axis: the case at h / 2, h / 4, ... with the plant's internal step halved with it
  (the same h_p / h: where the manipulator's link sticks, RK4 of sgn(x2) chatters by an amount set by
  h_p / h, so halving h alone shows no change of it);
* the plant axis, for a plant whose right-hand side switches (its Model Exchange interface declares event
  indicators: the manipulator's Coulomb friction; a plant of one's own FMU counts as switching): the case
  at h with twice the plant's internal step (half of it where h holds one).  A smooth plant needs no
  plant axis: RK4's error there is fourth order in h_p alone, and the communication axis, which halves
  h_p with h, takes 15/16 of that error away, so its change already counts it (tests/test_error_bars.py runs
  the left-out plant axis of the smooth plants: the RK4 error it shows is below a quarter of the printed error).

Model Exchange (``--algorithm me``) has no step: its ladder is the same case at tolerances
claims.TOLERANCE_FACTOR apart.  Every row of a ladder carries its plant step (``plant_step``) and
whether its case needs the plant axis (``plant_axis``).

Where the tables run the pythonfmu edition, a ladder's own runs (all but the tables' run at h, its first rung) run
on the native FMUs with the master's compiled loop when zig's compiler is installed (:func:`native_ladder_fmus`):
the same equations in C give the same scores (tests/test_tables.py) in a fraction of the time.
"""
from __future__ import annotations

from harness.fmu_build import builder as fmu_builder
from harness.fmu_build import catalog as fmu_catalog
from harness.fmu_build import native as native_build
from plants import plant_integration

from .. import master_loop
from ..cases import Case
from ..me_master import ALGORITHM as MODEL_EXCHANGE
from . import claims as claims_module

PLANT = "plant"  # the plant instance of the tables' scenarios
PLANT_STEP_LIMIT = "max_internal_step"  # the plant FMUs' largest internal RK4 step (plants/rk4_plant_slave.py)


def plant_step(scenario) -> float | None:
    """The plant's internal RK4 step in a run of ``scenario``: its step split into
    ceil(step / max_internal_step) equal steps (plants/plant_integration.py); None for a plant without one."""
    spec = scenario.components.get(PLANT)
    if spec is None:
        return None
    limit = spec.parameters.get(PLANT_STEP_LIMIT)
    if limit is None:
        try:
            declared = {v.name: v.start for v in fmu_catalog.model_class(spec.fmu).VARIABLES}
        except (KeyError, ImportError, AttributeError):  # an FMU of its own (a path): no declared table here
            return None
        limit = declared.get(PLANT_STEP_LIMIT)
    if limit is None:
        return None
    return scenario.step / plant_integration.internal_step_count(scenario.step, float(limit))


def switching_plant(scenario) -> bool:
    """Whether the plant's right-hand side switches: its declaration's Model Exchange interface has event
    indicators (the manipulator's stick and slip); True for a plant of its own FMU (nothing declared here)."""
    spec = scenario.components.get(PLANT)
    if spec is None:
        return False
    try:
        interface = fmu_catalog.declaration(spec.fmu).model_exchange()
    except (KeyError, ImportError, AttributeError):  # an FMU of its own (a path): assume the worst
        return True
    return bool(interface.event_indicators)


def needs_plant_axis(scenario) -> bool:
    """A co-simulation of ``scenario`` needs the plant axis: its plant has an internal RK4 step and a
    right-hand side that switches (see the module's doc)."""
    return plant_step(scenario) is not None and switching_plant(scenario)


def at_steps(case: Case, step: float, internal: float) -> Case:
    """The same case (no figure signals) at the communication step ``step`` with the plant's internal step
    ``internal`` (its max_internal_step set to it: ``step`` / ``internal`` whole steps)."""
    overrides = tuple((k, v) for k, v in case.overrides if k != f"{PLANT}.{PLANT_STEP_LIMIT}")
    return Case(case.scenario, case.controller, step=step, stop=case.stop,
                overrides=(*overrides, (f"{PLANT}.{PLANT_STEP_LIMIT}", internal)))


def half_step_case(case: Case) -> Case:
    """The communication axis of the claims' ladder: the same case at half its step with the plant's internal
    step halved with it (the same h_p / h); for Model Exchange the same case at a TOLERANCE_FACTOR looser rtol."""
    if case.algorithm == MODEL_EXCHANGE:
        return Case(case.scenario, case.controller, stop=case.stop, algorithm=MODEL_EXCHANGE,
                    rtol=case.rtol * claims_module.TOLERANCE_FACTOR)
    scenario = case.build()
    internal = plant_step(scenario)
    if internal is None:
        return Case(case.scenario, case.controller, step=scenario.step / 2, stop=case.stop)
    return at_steps(case, scenario.step / 2, internal / 2)


def plant_step_case(case: Case, smooth_too: bool = False) -> Case | None:
    """The plant axis of the claims' ladder: the same case at its step with twice the plant's internal step
    where the step holds two plant steps or more (the cheaper run), else half of it; None for Model Exchange
    (no fixed step), a plant without an internal step, or (unless ``smooth_too``) a smooth plant."""
    if case.algorithm == MODEL_EXCHANGE:
        return None
    scenario = case.build()
    internal = plant_step(scenario)
    if internal is None or not (smooth_too or switching_plant(scenario)):
        return None
    other = 2 * internal if scenario.step >= 2 * internal * (1 - 1e-9) else internal / 2
    return at_steps(case, scenario.step, other)


def ladder_cases(case: Case) -> list:
    """The runs the claims' error estimates of ``case`` need besides the case itself."""
    return [c for c in (half_step_case(case), plant_step_case(case)) if c is not None]


def ladder_row(case: Case, outcome: dict) -> dict:
    """A run's outcome as a row of its ladder: with the plant's internal step and whether the case needs the
    plant axis (None and False for Model Exchange)."""
    if case.algorithm == MODEL_EXCHANGE:
        return dict(outcome, plant_step=None, plant_axis=False)
    scenario = case.build()
    return dict(outcome, plant_step=plant_step(scenario), plant_axis=needs_plant_axis(scenario))


def case_cost(case: Case) -> int:
    return case.build().steps


def finer_case(name: str, controller: str, ladder: list, stop: float | None) -> Case:
    """The next rung of a case's ladder: half the finest step of its communication axis, the plant's internal
    step halved with it; or (Model Exchange) a tighter rtol."""
    if all(o.get("rtol") for o in ladder):
        return Case(name, controller, stop=stop, algorithm=MODEL_EXCHANGE,
                    rtol=min(o["rtol"] for o in ladder) / claims_module.TOLERANCE_FACTOR)
    finest = min(ladder, key=lambda o: (o["step"], -(o.get("plant_step") or 0.0)))
    if finest.get("plant_step"):
        return at_steps(Case(name, controller, stop=stop), finest["step"] / 2, finest["plant_step"] / 2)
    return Case(name, controller, step=finest["step"] / 2, stop=stop)


def native_ladder_fmus() -> dict | None:
    """The FMUs the ladders run on where the tables run the pythonfmu edition: the native ones (FMI 2.0, the same
    equations in C) with the master's compiled loop, a run in seconds; None where zig's C compiler is missing or
    the tables already run a native edition (the ladders then run on the tables' own FMUs)."""
    if fmu_catalog.selected_edition() != "python" or not native_build.compiler_available():
        return None
    if master_loop.library() is None:  # the compiled loop could not be built: say so once (compiled_loop.py)
        return None
    return fmu_builder.ensure_built(edition="native")

