"""One shared base for every pythonfmu slave of the project.

Each FMU declares its variables once, in a table of :class:`Variable` rows
(name, causality, start, valid range, unit, meaning, direct dependencies).
From that table this module derives

* the pythonfmu registration (value references in table order),
* the modelDescription.xml details pythonfmu 0.7 does not write: units,
  the ``dependencies`` of each output and the ``InitialUnknowns``,
* the validation of parameters when initialisation ends
  (build_fmu.py renders the same rows as the variable tables of docs/model.md).

The per-step path (``set_real``, ``get_real``, ``do_step``) is written for
speed: value references index plain lists, values live in the instance
``__dict__`` and outputs are recomputed lazily, once after their inputs or
the state changed.

FMI's rules of the calling sequence are kept (as the Modelica Reference-FMUs
keep them), each refusal logged with the call, the variable or time and the rule:

* every parameter has variability ``fixed``: it can be set after instantiation
  and in initialisation mode only; in step mode only inputs can be set, and after
  fmi2Terminate nothing (``fmi2SetReal``/``fmi2SetInteger`` fail);
* ``fmi2DoStep`` only between fmi2ExitInitializationMode and fmi2Terminate, with
  ``currentCommunicationPoint`` equal to the FMU's own time (where the last step
  ended, or the time of a state restored by fmi2SetFMUstate) and a step >= 0.

Statuses: pythonfmu 0.7 reports every Python exception as ``fmi2Fatal`` (never
``fmi2Error``), so a refused write is ``fmi2Fatal`` (see
:func:`_outlive_pythonfmu_cleanup`: the host can still free the instance); a
refused doStep returns False, which pythonfmu reports as ``fmi2Discard``: the
FMU's state and time are unchanged and the host may go on correctly.  A model subclass implements only

* ``initialize(start_time)``   state at the end of initialisation,
* ``compute_outputs()``        outputs from state and inputs, no side effect
  on the state (FMI: reading an output has no side effect),
* ``step(time, step_size)``    advance the state over one communication step.

This file travels inside every FMU as a project file and so imports only
the standard library and pythonfmu.
"""
from __future__ import annotations

import atexit
import ctypes
import glob
import json
import math
import os
import sys
import threading
from abc import ABCMeta
from dataclasses import dataclass
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Fmi2Slave
from pythonfmu.enums import Fmi2Causality, Fmi2Initial, Fmi2Status, Fmi2Variability
from pythonfmu.variables import Integer, Real

PARAMETER = "parameter"
INPUT = "input"
OUTPUT = "output"


TUNING_SCALES = ("linear", "log", "log1m", "hurwitz")


@dataclass(frozen=True)
class Tuning:
    """Where ``python -m harness tune`` searches a parameter (docs/tuning.md): declaration only.

    Nothing of it reaches modelDescription.xml or the native edition's C tables (FMI has no
    attribute for a search range); it lives in the table so that the valid range and the search
    range are declared side by side, once.  ``scale``:

    * ``linear``: uniform over [low, high];
    * ``log``: uniform in log(value) (ranges spanning a decade or more);
    * ``log1m``: uniform in log(1 - value) over [1 - high, 1 - low] (a parameter in (0, 1)
      whose effect is set by its distance to 1, as lambda_ce: alpha(0) = 1 - lambda_ce (23));
    * ``hurwitz``: the value is a fraction f of the largest value keeping the polynomial
      s^n + k1 s^(n-1) + ... + kn Hurwitz given k1..k(i-1) (the Routh conditions), f searched
      on a log scale over [low, high] inside (0, 1): every sample is Hurwitz (P of (30) positive
      definite) and every Hurwitz k with the earlier gains in range can be reached.

    ``variants``: the values of the FMU's ``variant`` parameter in which the parameter acts
    (empty: every variant); ``order``: the smallest value of the FMU's ``order`` parameter at
    which it acts.
    """

    low: float
    high: float
    scale: str = "log"
    variants: tuple[int, ...] = ()
    order: int = 1

    def problem(self) -> str | None:
        """None for a usable range, else what is wrong with it."""
        if self.scale not in TUNING_SCALES:
            return f"scale {self.scale!r} is unknown; valid: {', '.join(TUNING_SCALES)}"
        if not (math.isfinite(self.low) and math.isfinite(self.high)):
            return f"range [{self.low!r}, {self.high!r}] is not finite"
        if not self.low < self.high:
            return (f"range [{self.low:g}, {self.high:g}] is "
                    + ("empty" if self.low == self.high else "inverted") + "; give low < high")
        if self.scale in ("log", "hurwitz") and not self.low > 0:
            return f"a {self.scale} range needs low > 0 (low = {self.low:g})"
        if self.scale in ("log1m", "hurwitz") and not self.high < 1:
            return f"a {self.scale} range needs high < 1 (high = {self.high:g})"
        return None


# The types a signal whose unit is another FMU's declares (FMI's declaredType: a SimpleType naming the
# quantity): the controller serves any plant, so its signals carry the plant's units
DECLARED_TYPES = {
    "PlantOutput": "in the unit of the plant's output y (rad for the project's plants)",
    "PlantOutputRate": "in the unit of y per second (rad/s for the project's plants)",
    "PlantOutputAcceleration": "in the unit of y per second squared (rad/s2 for the project's plants)",
    "PlantOutputJerk": "in the unit of y per second cubed (rad/s3 for the project's plants)",
    "PlantInput": "in the unit of the plant's input u (N, N.m or V for the project's plants)",
}


@dataclass(frozen=True)
class Variable:
    """One row of an FMU's variable table."""

    name: str
    causality: str  # PARAMETER, INPUT or OUTPUT
    start: float
    unit: str = ""
    description: str = ""
    kind: str = "Real"  # "Real" or "Integer"
    minimum: float | None = None  # lower bound of the valid range (parameters)
    maximum: float | None = None  # upper bound of the valid range (parameters)
    exclusive_minimum: bool = False  # True: the value must be > minimum
    exclusive_maximum: bool = False  # True: the value must be < maximum
    depends_on: tuple[str, ...] = ()  # outputs: inputs with direct feedthrough
    # outputs: the dependenciesKind of each entry of depends_on ("constant": a constant factor,
    # "dependent": no particular structure, ...); () leaves it undeclared (FMI: dependent)
    dependency_kinds: tuple[str, ...] = ()
    # outputs: what the output's value in initialization mode depends on (parameters and inputs:
    # the knowns of FMI's InitialUnknowns); None: every parameter and depends_on (conservative)
    initial_depends_on: tuple[str, ...] | None = None
    tuning: Tuning | None = None  # parameters: where `harness tune` searches it (None: not tuned)
    # a signal whose unit is another FMU's (the controller's e: the plant output's): a key of
    # DECLARED_TYPES, written as FMI's declaredType
    declared_type: str = ""

    def valid_range(self) -> str:
        """The valid range as text, e.g. ``(0, 1)``, ``> 0``, ``{1, 2, 3}``."""
        if self.kind == "Integer" and self.minimum is not None and self.maximum is not None:
            return "{" + ", ".join(str(i) for i in range(int(self.minimum), int(self.maximum) + 1)) + "}"
        low, high = self.minimum, self.maximum
        if low is not None and high is not None:
            return (("(" if self.exclusive_minimum else "[") + f"{low:g}, {high:g}"
                    + (")" if self.exclusive_maximum else "]"))
        if low is not None:
            return (">" if self.exclusive_minimum else ">=") + f" {low:g}"
        if high is not None:
            return ("<" if self.exclusive_maximum else "<=") + f" {high:g}"
        return "finite"

    def check(self, value) -> str | None:
        """None if ``value`` is valid, else an error message naming it."""
        bad = not math.isfinite(value)
        if not bad and self.kind == "Integer" and value != int(value):
            bad = True
        if not bad and self.minimum is not None:
            bad = value <= self.minimum if self.exclusive_minimum else value < self.minimum
        if not bad and self.maximum is not None:
            bad = value >= self.maximum if self.exclusive_maximum else value > self.maximum
        if bad:
            return f"parameter {self.name} = {value!r} is invalid; valid range: {self.valid_range()}"
        return None


def positive(name, start, unit="", description="", tuning=None):
    """A Real parameter that must be > 0."""
    return Variable(name, PARAMETER, start, unit, description, minimum=0.0, exclusive_minimum=True, tuning=tuning)


def non_negative(name, start, unit="", description="", tuning=None):
    """A Real parameter that must be >= 0."""
    return Variable(name, PARAMETER, start, unit, description, minimum=0.0, tuning=tuning)


def finite(name, start, unit="", description="", tuning=None):
    """A Real parameter that may take any finite value."""
    return Variable(name, PARAMETER, start, unit, description, tuning=tuning)


def initial_dependencies(variables, variable: Variable) -> tuple:
    """The knowns (parameters, inputs) of ``variable``'s value in initialization mode, in table order:
    its ``initial_depends_on``, or every parameter and its ``depends_on`` when that is None."""
    if variable.initial_depends_on is not None:
        names = set(variable.initial_depends_on)
    else:
        names = {v.name for v in variables if v.causality == PARAMETER} | set(variable.depends_on)
    known = {v.name for v in variables if v.causality in (PARAMETER, INPUT)}
    if not names <= known:
        raise ValueError(f"{variable.name}: initial dependencies {sorted(names - known)} are not parameters or inputs")
    return tuple(v.name for v in variables if v.name in names)


def _unknown(parent, index: int, dependencies, kinds=()) -> Element:
    """An FMI 2.0 <Unknown> with its dependencies ordered by index (as FMI 2.0 requires), and
    their dependenciesKind when declared."""
    if kinds and len(kinds) != len(dependencies):
        raise ValueError(f"Unknown {index}: {len(kinds)} dependency kinds for {len(dependencies)} dependencies")
    order = sorted(range(len(dependencies)), key=lambda i: dependencies[i])
    element = SubElement(parent, "Unknown", index=str(index),
                         dependencies=" ".join(str(dependencies[i]) for i in order))
    if kinds:
        element.set("dependenciesKind", " ".join(kinds[i] for i in order))
    return element


class FmuModelError(RuntimeError):
    """Raised inside an FMU call; the pythonfmu wrapper reports it to the host."""


_py_incref = ctypes.pythonapi.Py_IncRef
_py_incref.argtypes = [ctypes.py_object]
_py_incref.restype = None


def _outlive_pythonfmu_cleanup(slave) -> None:
    """Keep the instance alive through pythonfmu 0.7's error path.

    On any Python exception, pythonfmu 0.7's C wrapper (``handle_py_exception``
    -> ``cleanPyObject``) releases its references to the instance, its class
    and its log queue, and releases them once more when the host frees the
    instance: a double release that crashes the host process a few calls
    later.  Taking one extra reference to each before the exception leaves
    the wrapper balanced, so the host can free the instance and go on.
    """
    for owned in (slave, type(slave), slave.log_queue):
        _py_incref(owned)


def _hide_imported_classes(script_locals, module_globals) -> None:
    """Leave pythonfmu 0.7's class search one class to list: the slave class, defined last.

    After re-running the FMU script in a fresh locals dict, ``findClass`` takes a list of
    the MRO of every class in that dict, and the repr and UTF-8 bytes of each MRO entry,
    and releases none of them: per fmi2Instantiate about 0.2 KiB per MRO entry.  The
    classes a script imports (the base under the name ``Fmi2Slave``, ``Variable``,
    ``DefaultExperiment``, ``itemgetter`` ...) added 1.2 to 1.6 KiB per instantiate to
    the slave class's own 0.9 KiB.  Each of them is the very object the module globals
    hold under the same name, so removing it from the locals dict changes nothing for
    the rest of the script (a name missing from the locals is looked up in the globals)
    and hides it from the search.
    """
    for name, value in list(script_locals.items()):
        if isinstance(value, type) and module_globals.get(name) is value:
            del script_locals[name]


class _SlaveMeta(ABCMeta):
    """Make pythonfmu 0.7's re-execution of the FMU script at every instantiate cheap.

    At every fmi2Instantiate, pythonfmu 0.7's C wrapper (``findClass``) runs the FMU
    script once more, with the module's globals and a fresh locals dict, to find the
    slave class; it keeps a reference to a list of each class's MRO, so every class
    created there leaks with all its functions (a bare pythonfmu FMU grows by about
    7 KiB per instantiate, measured in tests/test_memory_cycles.py), and it releases
    the (borrowed) module globals once.  On such a re-execution this metaclass hands
    back the class already defined in the module instead of building a new one, takes
    the one reference to the module globals that the wrapper is about to release (until
    now the leaked functions held it), and hides the script's imported classes from the
    search (:func:`_hide_imported_classes`).  A normal import or ``importlib.reload``
    (locals is globals) builds the class as usual.  The slave class statement must be
    the last top-level statement of the script that binds a class: a class bound after
    it would be listed at every instantiate again.
    """

    def __new__(mcls, name, bases, namespace, **kwargs):
        caller = sys._getframe(1)  # the frame running the class statement
        module_globals = caller.f_globals
        existing = module_globals.get(name)
        if (caller.f_locals is not module_globals and isinstance(existing, mcls)
                and existing.__module__ == namespace.get("__module__")
                and existing.__qualname__ == namespace.get("__qualname__")):
            cell = namespace.get("__classcell__")  # set when the class body uses super()
            if cell is not None:
                cell.cell_contents = existing
            _py_incref(module_globals)
            _hide_imported_classes(caller.f_locals, module_globals)
            return existing
        return super().__new__(mcls, name, bases, namespace, **kwargs)

    def __repr__(cls):
        # findClass keeps the repr of every class in the slave's MRO at every instantiate:
        # interned, it is one string per class for the process instead of one per instantiate
        return sys.intern(super().__repr__())


def _drop_duplicate_path(resources) -> None:
    """Keep one sys.path entry for this FMU's resources folder.

    pythonfmu 0.7 inserts the resources folder at the front of sys.path at every
    fmi2Instantiate: a host that instantiates thousands of times would grow sys.path,
    and slow every later import, without bound.
    """
    path = sys.path
    if resources and path.count(resources) > 1:
        first = path.index(resources)
        path[first + 1:] = [entry for entry in path[first + 1:] if entry != resources]


_pythonfmu_finalizers: dict = {}  # handle of a loaded copy of the FMU's library -> its finalizePythonInterpreter
_resources_seen: set = set()


def _release_pythonfmu_state_at_exit() -> None:
    """Run each loaded pythonfmu library's ``finalizePythonInterpreter`` once, before the C exit handlers.

    Only when the host's main thread finalizes Python (a Python host: its statics are alive).  In
    a host that is not Python, pythonfmu's own thread finalizes the interpreter from inside the
    C++ exit handlers, after other copies' statics were destroyed: nothing is released then.
    """
    if threading.get_native_id() != os.getpid():
        return
    while _pythonfmu_finalizers:
        _, finalize = _pythonfmu_finalizers.popitem()
        finalize()


def _disarm_pythonfmu_exit_use_after_free(resources) -> None:
    """Keep pythonfmu 0.7's library from corrupting the heap when the host process exits (Linux).

    The library holds its interpreter helper in a static ``std::shared_ptr`` (``pyState``).  At
    process exit the C++ runtime destroys that static (freeing its 128-byte block), and then the
    library's ELF destructor (``onLibraryUnload`` -> ``finalizePythonInterpreter``: ``pyState =
    nullptr``) releases the destroyed pointer once more: it decrements a count inside the freed
    block, which glibc may be using as a free-list pointer by then, and a later free aborts with
    "corrupted double-linked list" (valgrind: invalid read in finalizePythonInterpreter of a block
    freed by __run_exit_handlers).  Every loaded copy of the library (one per extraction) does it.
    Calling ``finalizePythonInterpreter`` from a Python atexit handler, while the static is still
    alive, releases it properly and leaves null pointers for both exit paths.  The library is
    looked up only if already loaded (RTLD_NOLOAD), next to this FMU's resources folder.
    """
    if not resources or not sys.platform.startswith("linux") or resources in _resources_seen:
        return
    _resources_seen.add(resources)
    for binary in glob.glob(os.path.join(os.path.dirname(os.path.normpath(resources)), "binaries", "*", "*.so")):
        try:
            library = ctypes.CDLL(binary, mode=os.RTLD_NOLOAD)
            finalize = library.finalizePythonInterpreter
        except (OSError, AttributeError):  # not loaded in this process, or not a pythonfmu library
            continue
        finalize.restype, finalize.argtypes = None, []
        if not _pythonfmu_finalizers:
            atexit.register(_release_pythonfmu_state_at_exit)  # again after a run, if a new copy loads
        _pythonfmu_finalizers.setdefault(library._handle, finalize)


def _fmi_entry(method):
    """Guard an FMI entry point that is not on the per-step path (see above)."""
    def guarded(self, *args):
        try:
            return method(self, *args)
        except BaseException as error:
            if not isinstance(error, FmuModelError):
                self.log(f"{self.instance_name}: {type(error).__name__} in {method.__name__}: {error}",
                         Fmi2Status.error)
            _outlive_pythonfmu_cleanup(self)
            raise
    guarded.__name__ = method.__name__
    guarded.__doc__ = method.__doc__
    return guarded


class TableSlave(Fmi2Slave, metaclass=_SlaveMeta):
    """Base of the project's slaves: registration, validation, fast I/O, state."""

    VARIABLES: tuple[Variable, ...] = ()
    #: attribute names of internal state that is not a registered variable
    STATE_ATTRIBUTES: tuple[str, ...] = ()
    MODEL_DESCRIPTION = ""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        _drop_duplicate_path(self.resources)
        _disarm_pythonfmu_exit_use_after_free(self.resources)
        self.description = self.MODEL_DESCRIPTION
        self.author = "afc-fmi project"
        self.version = "0.1.0"
        self.start_time = 0.0
        self.time = 0.0
        self.initialized = False
        self.terminated = False
        self.stepping = False  # between fmi2ExitInitializationMode and fmi2Terminate
        self.outputs_stale = True
        # Setting an input makes the outputs stale only where some output depends on an
        # input directly (and always before initialisation, when parameters are set).
        self._feedthrough = any(v.depends_on for v in self.VARIABLES if v.causality == OUTPUT)
        self.stale_on_set = True
        names = [v.name for v in self.VARIABLES]
        if len(set(names)) != len(names):
            raise ValueError(f"{type(self).__name__}: duplicate variable names in table")
        # value reference -> attribute name, for the lean set/get path
        self._names_by_vr = names
        # what fmi2SetReal/fmi2SetInteger accept now: parameters and inputs until
        # initialisation ends, then inputs only (every parameter is fixed), then nothing
        self._settable_before_step = [v.causality != OUTPUT for v in self.VARIABLES]
        self._inputs = [v.causality == INPUT for v in self.VARIABLES]
        self._nothing_settable = [False] * len(self.VARIABLES)
        self._settable = self._settable_before_step
        for v in self.VARIABLES:
            setattr(self, v.name, int(v.start) if v.kind == "Integer" else float(v.start))
            self._register(v)

    def _register(self, v: Variable):
        if v.causality == PARAMETER:
            options = dict(causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed)
        elif v.causality == INPUT:
            options = dict(causality=Fmi2Causality.input, variability=Fmi2Variability.continuous)
        else:
            options = dict(causality=Fmi2Causality.output, initial=Fmi2Initial.calculated,
                           variability=Fmi2Variability.continuous)
        cls = Integer if v.kind == "Integer" else Real
        if cls is Integer and v.causality == OUTPUT:
            options["variability"] = Fmi2Variability.discrete
        self.register_variable(cls(v.name, description=v.description or None, **options))

    # ---------------------------------------------------------------- XML
    def to_xml(self, model_options=dict()):
        """pythonfmu's description plus units, dependencies and InitialUnknowns."""
        root = super().to_xml(model_options)
        index = {v.name: i + 1 for i, v in enumerate(self.VARIABLES)}
        units = sorted({v.unit for v in self.VARIABLES if v.unit})
        used = {v.declared_type for v in self.VARIABLES if v.declared_type}
        declared_types = {name: meaning for name, meaning in DECLARED_TYPES.items() if name in used}
        for element, v in zip(root.find("ModelVariables"), self.VARIABLES):
            typed = element[0]
            if v.unit:
                typed.set("unit", v.unit)
            if v.declared_type:
                if v.declared_type not in DECLARED_TYPES:
                    raise ValueError(f"{v.name}: declared_type {v.declared_type!r} is invalid; valid: "
                                     f"one of {sorted(DECLARED_TYPES)}")
                typed.set("declaredType", v.declared_type)
            if v.causality == PARAMETER and v.minimum is not None and not v.exclusive_minimum:
                typed.set("min", str(int(v.minimum)) if v.kind == "Integer" else f"{v.minimum:.16g}")
            if v.causality == PARAMETER and v.maximum is not None and not v.exclusive_maximum:
                typed.set("max", str(int(v.maximum)) if v.kind == "Integer" else f"{v.maximum:.16g}")
        if units:
            unit_definitions = Element("UnitDefinitions")
            for unit in units:
                SubElement(unit_definitions, "Unit", name=unit)
            position = list(root).index(root.find("CoSimulation")) + 1
            root.insert(position, unit_definitions)
        if declared_types:  # FMI 2.0: TypeDefinitions after UnitDefinitions, before LogCategories
            type_definitions = Element("TypeDefinitions")
            for name, meaning in declared_types.items():
                simple = SubElement(type_definitions, "SimpleType", name=name, description=meaning)
                SubElement(simple, "Real", quantity=name)
            anchor = root.find("UnitDefinitions")
            if anchor is None:
                anchor = root.find("CoSimulation")
            root.insert(list(root).index(anchor) + 1, type_definitions)
        structure = root.find("ModelStructure")
        for child in list(structure):
            structure.remove(child)
        outputs = [v for v in self.VARIABLES if v.causality == OUTPUT]
        if outputs:
            outputs_node = SubElement(structure, "Outputs")
            for v in outputs:
                unknown_dependencies = [n for n in v.depends_on if n not in index]
                if unknown_dependencies:
                    raise ValueError(f"{v.name} depends on unknown {unknown_dependencies}")
                _unknown(outputs_node, index[v.name], [index[n] for n in v.depends_on], v.dependency_kinds)
            # InitialUnknowns: the outputs' values in initialization mode and what they depend on
            # (parameters, inputs): a plant's y(0) depends on x1_start, not on u
            initial_node = SubElement(structure, "InitialUnknowns")
            for v in outputs:
                _unknown(initial_node, index[v.name], [index[n] for n in initial_dependencies(self.VARIABLES, v)])
        return root

    # ---------------------------------------------------------- life cycle
    @_fmi_entry
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self.start_time = float(start_time)
        self.time = float(start_time)

    @_fmi_entry
    def exit_initialization_mode(self):
        errors = self._parameter_errors()
        if errors:
            self.fail("; ".join(errors))
        self.time = self.start_time
        self.initialize(self.start_time)
        self.initialized = True
        self._enter_mode()
        self.outputs_stale = True

    def _enter_mode(self):
        """Set what may be set and whether doStep may run, from ``initialized`` and ``terminated``."""
        self.stepping = self.initialized and not self.terminated
        self._settable = (self._nothing_settable if self.terminated else
                          self._inputs if self.initialized else self._settable_before_step)
        self.stale_on_set = self._feedthrough or not self.initialized

    @_fmi_entry
    def enter_initialization_mode(self):
        pass

    @_fmi_entry
    def terminate(self):
        self.terminated = True
        self._enter_mode()

    def fail(self, message: str):
        """Log ``message`` as an error for the host and abort the FMI call."""
        self.log(f"{self.instance_name}: {message}", Fmi2Status.error)
        raise FmuModelError(message)

    def warn(self, message: str):
        """Log ``message`` with status Warning for the host (reaches it only with logging on)."""
        self.log(f"{self.instance_name}: {message}", Fmi2Status.warning)

    def _crashed(self, where: str, error: BaseException):
        """The error path of the per-step entry points (kept out of their bodies)."""
        if not isinstance(error, FmuModelError):
            self.log(f"{self.instance_name}: {type(error).__name__} in {where} at t = {self.time!r}: {error}",
                     Fmi2Status.error)
        _outlive_pythonfmu_cleanup(self)

    def do_step(self, current_time, step_size):
        time = self.time  # a step starts at the FMU's time, give or take rounding (1e-9 relative)
        if not (self.stepping and step_size >= 0.0 and abs(current_time - time) <= 1e-9 * (abs(time) + step_size)):
            return self._refuse_step(current_time, step_size)
        try:
            if self.outputs_stale:
                self.compute_outputs()
            ok = self.step(current_time, step_size)
        except BaseException as error:
            self._crashed("do_step", error)
            raise
        self.time = current_time + step_size
        self.outputs_stale = True
        return ok is not False

    def _refuse_step(self, current_time, step_size) -> bool:
        """Log why this doStep breaks FMI's rules; False: pythonfmu returns fmi2Discard, nothing changed."""
        call = f"fmi2DoStep(currentCommunicationPoint = {current_time!r}, communicationStepSize = {step_size!r})"
        if self.terminated:
            rule = ("the FMU was terminated (fmi2Terminate); doStep is allowed only between "
                    "fmi2ExitInitializationMode and fmi2Terminate")
        elif not self.initialized:
            rule = ("the FMU is not initialised: call fmi2ExitInitializationMode first; doStep is allowed only "
                    "between fmi2ExitInitializationMode and fmi2Terminate")
        elif not step_size >= 0.0:
            rule = "the communication step must be >= 0"
        else:
            rule = (f"expected currentCommunicationPoint = {self.time!r}, the FMU's time (where the last step "
                    "ended, or the time of the state restored by fmi2SetFMUstate); a step must start there")
        self.log(f"{self.instance_name}: {call} refused: {rule}; state and time unchanged", Fmi2Status.error)
        return False

    def _parameter_errors(self) -> list:
        table = [v.check(getattr(self, v.name)) for v in self.VARIABLES if v.causality == PARAMETER]
        return [message for message in table if message] or self.cross_parameter_errors()

    # ------------------------------------------------------- model hooks
    def cross_parameter_errors(self) -> list:
        """Messages for invalid combinations of individually valid parameters."""
        return []

    def initialize(self, start_time: float) -> None:
        """Set the internal state once the parameters and start inputs are known."""

    def compute_outputs(self) -> None:
        """Set every output attribute from state and inputs."""
        self.outputs_stale = False

    def step(self, current_time: float, step_size: float):
        """Advance the state from current_time by step_size; False means discard."""
        raise NotImplementedError

    # ------------------------------------------------------ lean value I/O
    def set_real(self, vrs, values):
        attributes = self.__dict__
        names = self._names_by_vr
        settable = self._settable
        try:
            for vr, value in zip(vrs, values):
                if value - value != 0.0 or not settable[vr]:  # NaN, +-inf, or an output
                    self._reject(vr, value)
                attributes[names[vr]] = value
        except BaseException as error:
            self._crashed("set_real", error)
            raise
        if self.stale_on_set:
            self.outputs_stale = True

    def _initial_outputs(self):
        """Outputs in initialization mode (they are InitialUnknowns).

        They follow the parameters and inputs set so far, so that a master
        propagating initial values through the connections hands every FMU
        consistent values at the start time (the controller latches e(0),
        de(0) from them).  While a parameter is invalid the outputs keep their
        start values; exitInitializationMode then reports the parameter.
        """
        if self._parameter_errors():
            return
        self.initialize(self.start_time)
        self.compute_outputs()

    def _reject(self, vr, value, call="fmi2SetReal"):
        variable = self.VARIABLES[vr]
        if variable.causality == OUTPUT:
            self.fail(f"{variable.name} is an output and cannot be set")  # the C edition's words too
        if self.terminated:
            self.fail(f"{call}: {variable.name} = {value!r} refused: the FMU was terminated (fmi2Terminate); "
                      "no variable can be set after fmi2Terminate")
        if variable.causality == PARAMETER and self.initialized:
            self.fail(f"{call}: {variable.name} = {value!r} refused at t = {self.time!r}: {variable.name} is a "
                      "parameter of variability fixed, which can be set only before fmi2ExitInitializationMode "
                      f"(it keeps {getattr(self, variable.name)!r}); in step mode only inputs can be set")
        if variable.causality == PARAMETER:
            self.fail(variable.check(value))
        self.fail(f"input {variable.name} = {value!r} is not finite")

    def get_real(self, vrs):
        try:
            if self.outputs_stale:
                if self.initialized:
                    self.compute_outputs()
                else:
                    self._initial_outputs()
            attributes = self.__dict__
            names = self._names_by_vr
            return [attributes[names[vr]] for vr in vrs]
        except BaseException as error:
            self._crashed("get_real", error)
            raise

    @_fmi_entry
    def set_integer(self, vrs, values):
        for vr, value in zip(vrs, values):
            if not self._settable[vr]:
                self._reject(vr, value, "fmi2SetInteger")
            setattr(self, self._names_by_vr[vr], int(value))
        self.outputs_stale = True

    @_fmi_entry
    def get_integer(self, vrs):
        return [int(getattr(self, self._names_by_vr[vr])) for vr in vrs]

    # ---------------------------------------------------------- FMU state
    def _state_names(self):
        return (*self._names_by_vr, *self.STATE_ATTRIBUTES,
                "time", "start_time", "initialized")

    @_fmi_entry
    def _get_fmu_state(self):
        """The whole internal state, not only registered variables."""
        attributes = self.__dict__
        return {name: _copy(attributes[name]) for name in self._state_names()}

    @_fmi_entry
    def _set_fmu_state(self, state):
        attributes = self.__dict__
        for name in self._state_names():
            attributes[name] = _copy(state[name])
        self._enter_mode()
        self.outputs_stale = True

    @staticmethod
    def _fmu_state_to_bytes(state) -> bytes:
        # repr-based JSON floats round-trip exactly
        return json.dumps(state, allow_nan=True).encode("utf-8")

    @staticmethod
    def _fmu_state_from_bytes(state: bytes):
        return json.loads(state.decode("utf-8"))


def _copy(value):
    return list(value) if isinstance(value, (list, tuple)) else value
