"""What an FMU declares beside its variable table: its Model Exchange interface and its test drive.

Each FMU script (``fmu_src/adaptive_fuzzy_controller_fmu.py``, ``plants/<name>/fmu.py``) defines
``model_exchange()`` (a :class:`ModelExchange`) and ``test_drive()`` (a :class:`TestDrive`) next to
its ``VARIABLES``: the native build writes the Model Exchange part of the description from the
first (docs/model_exchange.md), the tests drive every FMU with the second.  Functions, not
constants: pythonfmu runs the script again at every instantiate.
Standard library only: it travels inside each pythonfmu FMU with its script.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable


@dataclass(frozen=True)
class Derivative:
    """der(state): the right-hand side of one continuous state."""
    state: str  # the table variable that is the state
    depends_on: tuple  # ((known, dependenciesKind), ...): the states and inputs it depends on
    parameters: tuple = ()  # the parameters it depends on (its value in initialization mode)
    description: str = ""


@dataclass(frozen=True)
class EventIndicator:
    name: str
    description: str
    depends_on: tuple = ()  # ((known, dependenciesKind), ...): states and inputs


@dataclass(frozen=True)
class ModelExchange:
    """What a native FMU declares for Model Exchange beside its table (docs/model_exchange.md).

    The continuous states are table variables (the plants' y, dy, ...; the controller's theta_j
    and w_hat), in the order of ``derivatives``; the description adds der(<state>), the event
    indicators and the model's other ``locals`` (discrete) after the table, with the value
    references N + 1, ... (N, the table's length, is FMI 3.0's time).  ``output_states`` gives
    the states an output depends on (Model Exchange knowns beside the inputs); ``reinit`` the
    states an event may reset.  The C model file's hooks (fmi_layer.h) follow the same order.
    """
    derivatives: tuple = ()
    output_states: tuple = ()  # ((output, ((state, dependenciesKind), ...)), ...)
    event_indicators: tuple = ()
    locals: tuple = ()  # ((name, description), ...)
    reinit: tuple = ()
    # the model announces time events: its event update gives the next event time (a sampled FMU's
    # next sample instant); the C model file then defines model_next_event_time (fmi_layer.h)
    time_events: bool = False

    @property
    def states(self) -> tuple:
        return tuple(d.state for d in self.derivatives)

    def extra_names(self) -> list:
        """The names of the variables after the table, in value-reference order."""
        return ([f"der({d.state})" for d in self.derivatives] + [e.name for e in self.event_indicators]
                + [name for name, _ in self.locals])


@dataclass(frozen=True)
class TestDrive:
    """How the tests drive an FMU: parameters away from the defaults, the inputs as functions of
    time, a communication step; and the values its valid ranges alone do not reject (a cross-
    parameter rule: ``((parameter, value, {other parameter: value}), ...)``)."""
    __test__ = False  # not a pytest test class

    parameters: dict
    inputs: Callable  # t -> {input name: value}
    step: float
    cross_parameter_violations: tuple = field(default=())
