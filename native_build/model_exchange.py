"""What a native FMU declares for Model Exchange beside its variable table, and its XML
(docs/model_exchange.md)."""
from __future__ import annotations

from dataclasses import dataclass
from xml.etree import ElementTree as ET

from c_toolchain import NativeBuildError
from fmu_catalog import model_class
from fmu_src.afc_slave_base import INPUT, OUTPUT, PARAMETER, _unknown, initial_dependencies


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

    @property
    def states(self) -> tuple:
        return tuple(d.state for d in self.derivatives)

    def extra_names(self) -> list:
        """The names of the variables after the table, in value-reference order."""
        return ([f"der({d.state})" for d in self.derivatives] + [e.name for e in self.event_indicators]
                + [name for name, _ in self.locals])


MODEL_EXCHANGE = {
    "InvertedPendulum": ModelExchange(
        derivatives=(Derivative("y", (("dy", "constant"),), (), "dx1 = x2 (37)"),
                     Derivative("dy", (("y", "dependent"), ("dy", "dependent"), ("u", "dependent")),
                                ("gv", "mc", "mp", "lp", "dist_gain"), "dx2 of (37) with d(t)"))),
    "Manipulator": ModelExchange(
        derivatives=(Derivative("y", (("dy", "constant"),), (), "dx1 = x2 (38)"),
                     Derivative("dy", (("y", "dependent"), ("dy", "dependent"), ("u", "dependent")),
                                ("gv", "lr", "dr", "cr", "vr", "mr0", "mr1"),
                                "dx2 of (38, 39) in the friction mode (0 while stuck)")),
        output_states=(("d", (("dy", "dependent"),)),),
        event_indicators=(
            EventIndicator("z_slip", "slip indicator: friction_mode x2 + 1e-10 rad/s while slipping (zero when "
                                     "the link comes to rest), 1e-10 while stuck", (("dy", "discrete"),)),
            EventIndicator("z_stick", "stick indicator: cr while slipping; cr - |u - mr gv lr cos x1| while "
                                      "stuck (zero at break-away)", (("y", "dependent"), ("u", "dependent")))),
        locals=(("friction_mode", "Model Exchange friction mode: 1 slipping forwards, -1 backwards, 0 stuck "
                                  "(co-simulation: sgn(x2))"),),
        reinit=("dy",)),
    "DcMotorArm": ModelExchange(
        derivatives=(Derivative("y", (("dy", "constant"),), (), "dx1 = x2"),
                     Derivative("dy", (("y", "dependent"), ("dy", "fixed"), ("i", "fixed")),
                                ("J", "b", "m", "lc", "gv", "Kt"), "dx2 = (Kt x3 - b x2 - m gv lc sin x1) / J"),
                     Derivative("i", (("dy", "fixed"), ("i", "fixed"), ("u", "fixed")), ("Ke", "R", "L"),
                                "dx3 = (u - R x3 - Ke x2) / L")),
        output_states=(("d2y", (("y", "dependent"), ("dy", "fixed"), ("i", "fixed"))),)),
    "TrackingReference": ModelExchange(),
}


def _controller_model_exchange() -> ModelExchange:
    """theta1..thetaN (N = the table's rule weights) and w_hat: dtheta_j = gamma tau xi_j with the
    projection (31), dw_hat = gamma_w tau (variant 3; else 0); tau and xi depend on every input."""
    table = model_class("AdaptiveFuzzyController").VARIABLES
    inputs = tuple((v.name, "dependent") for v in table if v.causality == INPUT)
    parameters = tuple(v.name for v in table if v.causality == PARAMETER)
    thetas = [v.name for v in table if v.causality == OUTPUT and v.name.startswith("theta") and v.name[5:].isdigit()]
    derivatives = tuple(Derivative(name, ((name, "dependent"), *inputs), parameters,
                                   f"d{name} of the adaptive law with projection (31)") for name in thetas)
    derivatives += (Derivative("w_hat", inputs, parameters, "dw_hat = gamma_w tau (variant 3; else 0)"),)
    return ModelExchange(derivatives=derivatives,
                         output_states=(("u", (*((name, "dependent") for name in thetas), ("w_hat", "fixed"))),))


def model_exchange(model_identifier: str) -> ModelExchange:
    """The Model Exchange declaration of a native FMU."""
    if model_identifier == "AdaptiveFuzzyController":
        return _controller_model_exchange()
    if model_identifier not in MODEL_EXCHANGE:  # a plant row of plants/registry.py without its entry here
        raise NativeBuildError(f"native_build/model_exchange.py: MODEL_EXCHANGE has no entry for {model_identifier!r} (every FMU "
                               "of plants/registry.py needs one: its continuous states and their derivatives, "
                               "docs/model_exchange.md)")
    return MODEL_EXCHANGE[model_identifier]


def _derivative_unit(unit: str) -> str:
    """The unit of der(x) for x in ``unit``: rad -> rad/s, rad/s -> rad/s2, A -> A/s."""
    if not unit:
        return ""
    if unit.endswith("/s"):
        return unit + "2"
    if unit.endswith("/s2"):
        return unit[:-1] + "3"
    return unit + "/s"


def add_model_exchange(root: ET.Element, model_identifier: str) -> ET.Element:
    """Model Exchange beside Co-Simulation in the FMI 2.0 description ``root`` (in place).

    <ModelExchange>, numberOfEventIndicators, der(<state>) and the other variables after the table,
    reinit on the states an event may reset, and the ModelStructure: the outputs' dependencies on
    states, <Derivatives>, and the derivatives' <InitialUnknowns> (their knowns in initialization
    mode: the initial dependencies of the states they depend on, their inputs and parameters).
    """
    declaration = model_exchange(model_identifier)
    table = model_class(model_identifier).VARIABLES
    rows = {v.name: v for v in table}
    index = {v.name: i + 1 for i, v in enumerate(table)}
    cosim = root.find("CoSimulation")
    root.set("numberOfEventIndicators", str(len(declaration.event_indicators)))
    me = ET.Element("ModelExchange", modelIdentifier=cosim.get("modelIdentifier"), needsExecutionTool="false",
                    completedIntegratorStepNotNeeded="true", canBeInstantiatedOnlyOncePerProcess="false",
                    canNotUseMemoryManagementFunctions="true", canGetAndSetFMUstate="true",
                    canSerializeFMUstate="true")
    root.insert(list(root).index(cosim), me)
    variables = root.find("ModelVariables")
    for scalar in variables:
        if scalar.get("name") in declaration.reinit:
            scalar[0].set("reinit", "true")
    definitions = root.find("UnitDefinitions")
    units = {unit.get("name") for unit in definitions} if definitions is not None else set()
    first = len(table) + 1  # value reference N is FMI 3.0's time
    extras = declaration.extra_names()

    def add(name, description, variability, **real):
        vr = first + extras.index(name)
        index[name] = len(variables) + 1
        scalar = ET.SubElement(variables, "ScalarVariable", name=name, valueReference=str(vr),
                               description=description, causality="local", variability=variability,
                               initial="calculated")
        ET.SubElement(scalar, "Real", **{k: v for k, v in real.items() if v})

    for derivative in declaration.derivatives:
        add(f"der({derivative.state})", derivative.description or f"derivative of {derivative.state}", "continuous",
            derivative=str(index[derivative.state]), unit=_derivative_unit(rows[derivative.state].unit))
    for indicator in declaration.event_indicators:
        add(indicator.name, indicator.description, "continuous")
    for name, description in declaration.locals:
        add(name, description, "discrete")
    for name in sorted({_derivative_unit(rows[state].unit) for state in declaration.states} - units - {""}):
        ET.SubElement(definitions, "Unit", name=name)  # e.g. A/s for der(i)
    structure = root.find("ModelStructure")
    outputs = structure.find("Outputs")
    states = dict(declaration.output_states)
    for unknown in (outputs if outputs is not None else ()):
        name = table[int(unknown.get("index")) - 1].name
        if name not in states:
            continue
        known = [int(i) for i in unknown.get("dependencies", "").split()]
        kinds = (unknown.get("dependenciesKind") or " ".join(["dependent"] * len(known))).split()
        pairs = list(zip(known, kinds)) + [(index[state], kind) for state, kind in states[name]]
        pairs.sort()
        unknown.set("dependencies", " ".join(str(i) for i, _ in pairs))
        unknown.set("dependenciesKind", " ".join(kind for _, kind in pairs))
    if declaration.derivatives:
        derivatives = ET.Element("Derivatives")
        structure.insert(list(structure).index(structure.find("InitialUnknowns")), derivatives)
        initial = structure.find("InitialUnknowns")
        for derivative in declaration.derivatives:
            _unknown(derivatives, index[f"der({derivative.state})"], [index[n] for n, _ in derivative.depends_on],
                     [kind for _, kind in derivative.depends_on])
            knowns = set(derivative.parameters)
            for name, _ in derivative.depends_on:
                knowns |= set(initial_dependencies(table, rows[name])) if name in declaration.states else {name}
            _unknown(initial, index[f"der({derivative.state})"], sorted(index[n] for n in knowns))
    return root


def event_indicator_elements(fmi2_root: ET.Element) -> list:
    """The FMI 2.0 description's event indicator variables: the first numberOfEventIndicators
    locals that are not derivatives (add_model_exchange writes them after the derivatives)."""
    count = int(fmi2_root.get("numberOfEventIndicators") or 0)
    return [s for s in fmi2_root.find("ModelVariables")
            if s.get("causality") == "local" and s[0].get("derivative") is None][:count]

