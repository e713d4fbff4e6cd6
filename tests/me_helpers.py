"""Driving the native FMUs' Model Exchange interface from tests, and the Python references.

``MeInstance`` wraps fmpy's FMU2Model / FMU3Model (FMI 2.0 / 3.0) with name-based access,
captured log messages and numpy arrays for states, derivatives and event indicators.  The
``*_reference`` functions integrate the pure Python model functions (plants/*/model.py,
fmu_src/afc_math.py) with scipy's solve_ivp, through the same piecewise-constant inputs and,
for the manipulator, through the same friction modes and events (docs/model_exchange.md).
"""
from __future__ import annotations

import math
import shutil
from ctypes import POINTER, c_double

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Model, defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
from fmpy.fmi3 import FMU3Model

from fmu_src import afc_math
from plants.dc_motor_arm import model as dc_motor_arm_model
from plants.inverted_pendulum import model as inverted_pendulum_model
from plants.manipulator import model as manipulator_model


def _pointer(array: np.ndarray):
    return array.ctypes.data_as(POINTER(c_double))


class MeInstance:
    """One Model Exchange instance of a native FMU (FMI ``version`` 2 or 3)."""

    def __init__(self, path, version: int, instance_name: str = "me"):
        self.version = version
        self.md = read_model_description(str(path))
        self.unzip_dir = extract(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.types = {v.name: v.type for v in self.md.modelVariables}
        self.nx = self.md.numberOfContinuousStates
        self.nz = self.md.numberOfEventIndicators
        self.next_event_time = None  # the time event the FMU announced at its last event update
        self.messages = []
        identifier = self.md.modelExchange.modelIdentifier
        if version == 2:
            self.fmu = FMU2Model(guid=self.md.guid, unzipDirectory=self.unzip_dir, modelIdentifier=identifier,
                                 instanceName=instance_name)
            callbacks = fmi2CallbackFunctions()
            callbacks.logger = fmi2CallbackLoggerTYPE(self._log2)
            callbacks.allocateMemory = defaultCallbacks.allocateMemory
            callbacks.freeMemory = defaultCallbacks.freeMemory
            self._callbacks = callbacks
            self.fmu.instantiate(callbacks=callbacks, loggingOn=True)
        else:
            self.fmu = FMU3Model(guid=self.md.guid, unzipDirectory=self.unzip_dir, modelIdentifier=identifier,
                                 instanceName=instance_name)
            self.fmu.instantiate(loggingOn=True, logMessage=self._log3)

    def _log2(self, env, instance, status, category, message):
        self.messages.append((status, message.decode("utf-8", "replace")))

    def _log3(self, env, status, category, message):
        self.messages.append((status, message.decode("utf-8", "replace")))

    # ------------------------------------------------------------ life cycle
    def enter(self, start_time: float = 0.0, **values):
        if self.version == 2:
            self.fmu.setupExperiment(startTime=start_time)
            self.fmu.enterInitializationMode()
        else:
            self.fmu.enterInitializationMode(startTime=start_time)
        self.set(**values)
        return self

    def update(self) -> tuple:
        """newDiscreteStates / updateDiscreteStates: (needs another update, values of states changed); the next
        time event it announces is kept in ``next_event_time`` (None: none)."""
        result = self.fmu.newDiscreteStates() if self.version == 2 else self.fmu.updateDiscreteStates()
        self.next_event_time = float(result[5]) if result[4] else None
        return bool(result[0]), bool(result[3])

    def exit(self) -> bool:
        """exitInitializationMode and the initial event iteration; True if it set continuous states."""
        self.fmu.exitInitializationMode()
        return self._iterate()

    def _iterate(self) -> bool:
        changed, again = False, True
        while again:
            again, values_changed = self.update()
            changed = changed or values_changed
        return changed

    def initialize(self, start_time: float = 0.0, **values):
        """Up to continuous-time mode at ``start_time`` with ``values`` set in initialization mode."""
        self.enter(start_time, **values)
        self.exit()
        self.fmu.enterContinuousTimeMode()
        return self

    def event(self) -> bool:
        """An event at the current time (enterEventMode, the event iteration, continuous-time mode)."""
        self.fmu.enterEventMode()
        changed = self._iterate()
        self.fmu.enterContinuousTimeMode()
        return changed

    def free(self):
        try:
            self.fmu.terminate()
        except Exception:
            pass
        self.fmu.freeInstance()
        shutil.rmtree(self.unzip_dir, ignore_errors=True)

    # ------------------------------------------------------------------ values
    def set(self, **values):
        for name, value in values.items():
            integer = self.types[name] in ("Integer", "Int32")
            if self.version == 2:
                if integer:
                    self.fmu.setInteger([self.vr[name]], [int(value)])
                else:
                    self.fmu.setReal([self.vr[name]], [float(value)])
            elif integer:
                self.fmu.setInt32([self.vr[name]], [int(value)])
            else:
                self.fmu.setFloat64([self.vr[name]], [float(value)])

    def get(self, *names):
        references = [self.vr[n] for n in names]
        values = self.fmu.getReal(references) if self.version == 2 else self.fmu.getFloat64(references)
        return values[0] if len(names) == 1 else list(values)

    def set_time(self, t: float):
        self.fmu.setTime(t)

    def states(self) -> np.ndarray:
        x = np.zeros(self.nx)
        self.fmu.getContinuousStates(_pointer(x), self.nx)
        return x

    def set_states(self, x):
        x = np.ascontiguousarray(x, dtype=float)
        self.fmu.setContinuousStates(_pointer(x), self.nx)

    def derivatives(self) -> np.ndarray:
        dx = np.zeros(self.nx)
        if self.version == 2:
            self.fmu.getDerivatives(_pointer(dx), self.nx)
        else:
            self.fmu.getContinuousStateDerivatives(_pointer(dx), self.nx)
        return dx

    def indicators(self) -> np.ndarray:
        z = np.zeros(self.nz)
        self.fmu.getEventIndicators(_pointer(z), self.nz)
        return z

    def nominals(self) -> np.ndarray:
        nominal = np.zeros(self.nx)
        self.fmu.getNominalsOfContinuousStates(_pointer(nominal), self.nx)
        return nominal

    # --------------------------------------------------------------- FMU state
    def get_state(self):
        return self.fmu.getFMUstate() if self.version == 2 else self.fmu.getFMUState()

    def set_state(self, state):
        if self.version == 2:
            self.fmu.setFMUstate(state)
        else:
            self.fmu.setFMUState(state)

    def serialize(self, state) -> bytes:
        return self.fmu.serializeFMUstate(state) if self.version == 2 else self.fmu.serializeFMUState(state)

    def deserialize(self, blob: bytes):
        return self.fmu.deSerializeFMUstate(blob) if self.version == 2 else self.fmu.deserializeFMUState(blob)


# ----------------------------------------------------------- Python references
def table_values(model_class, **overrides) -> dict:
    """The parameter values of an FMU's table (start values), with ``overrides``."""
    values = {v.name: (int(v.start) if v.kind == "Integer" else float(v.start))
              for v in model_class.VARIABLES if v.causality == "parameter"}
    values.update(overrides)
    return values


def pendulum_params(values: dict) -> tuple:
    return inverted_pendulum_model.pendulum_params(values["gv"], values["mc"], values["mp"], values["lp"],
                                                   values["dist_gain"])


def manipulator_params(values: dict) -> tuple:
    return manipulator_model.manipulator_params(values["gv"], values["lr"], values["dr"], values["cr"], values["vr"],
                                                values["mr0"], values["mr1"])


def motor_arm_params(values: dict) -> tuple:
    return dc_motor_arm_model.motor_arm_params(values["J"], values["b"], values["m"], values["lc"], values["gv"],
                                               values["Kt"], values["Ke"], values["R"], values["L"])


def pieces(times, values, stop):
    """[(t0, t1, value), ...] of a piecewise-constant signal that takes values[i] from times[i]."""
    bounds = list(times) + [stop]
    return [(bounds[i], bounds[i + 1], values[i]) for i in range(len(values)) if bounds[i + 1] > bounds[i]]


def input_csv(path, names, times, rows, stop):
    """An fmpy input CSV of piecewise-constant signals: rows[i] from times[i] (a jump repeats the time)."""
    lines = ["time," + ",".join(names)]
    bounds = list(times) + [stop]
    for i, row in enumerate(rows):
        for t in (bounds[i], bounds[i + 1]):
            lines.append(",".join(repr(float(v)) for v in (t, *row)))
    path.write_text("\n".join(lines) + "\n")
    return path


def smooth_reference(derivative, x0, segments, rtol=1e-12, atol=1e-12):
    """solve_ivp (DOP853) of dx = derivative(t, x, u) through constant-input segments
    [(t0, t1, u), ...]; returns a list of (t0, t1, dense solution)."""
    from scipy.integrate import solve_ivp

    x = np.asarray(x0, dtype=float)
    solutions = []
    for t0, t1, u in segments:
        solution = solve_ivp(lambda t, state: derivative(t, state, u), (t0, t1), x, method="DOP853", rtol=rtol,
                             atol=atol, dense_output=True)
        assert solution.success, solution.message
        solutions.append((t0, t1, solution.sol))
        x = solution.y[:, -1]
    return solutions


def evaluate(solutions, t: float) -> np.ndarray:
    for t0, t1, dense in solutions:
        if t0 <= t <= t1:
            return dense(t)
    raise ValueError(f"t = {t} outside the reference")


def manipulator_reference(params, x0, segments, rtol=1e-12, atol=1e-12):
    """(38, 39) through the friction modes: solve_ivp between events, the events located by
    solve_ivp on the indicators of manipulator_event_indicators, the update of
    manipulator_event_update at every event and input jump (what the FMU does).

    Returns (solutions, events): events are (t, mode before, mode after, x1, x2 after)."""
    from scipy.integrate import solve_ivp

    model = manipulator_model
    t = segments[0][0]
    x = [float(x0[0]), float(x0[1])]
    mode = model.manipulator_friction_mode(t, x[0], x[1], segments[0][2], params, model.STICK)
    solutions, events = [], []
    for t0, t1, u in segments:
        if t0 > segments[0][0]:  # an input jump: the event update with the new input
            before = mode
            mode, x[1] = model.manipulator_event_update(t, x[0], x[1], u, params, mode)
            events.append((t, before, mode, x[0], x[1], "input"))
        while t < t1:
            def rhs(s, state, mode=mode, u=u):
                return model.manipulator_mode_derivative(s, state[0], state[1], u, params, mode)

            def slip(s, state, mode=mode, u=u):
                return model.manipulator_event_indicators(s, state[0], state[1], u, params, mode)[0]

            def stick(s, state, mode=mode, u=u):
                return model.manipulator_event_indicators(s, state[0], state[1], u, params, mode)[1]

            for function in (slip, stick):
                function.terminal, function.direction = True, -1
            solution = solve_ivp(rhs, (t, t1), x, method="DOP853", rtol=rtol, atol=atol, dense_output=True,
                                 events=[slip, stick])
            assert solution.success, solution.message
            solutions.append((t, solution.t[-1], solution.sol))
            t, x = float(solution.t[-1]), [float(v) for v in solution.y[:, -1]]
            if solution.status == 1:  # an indicator reached zero
                before, x2 = mode, x[1]
                mode, x[1] = model.manipulator_event_update(t, x[0], x[1], u, params, mode)
                assert (mode, x[1]) != (before, x2), f"an event at t = {t} that changes nothing (it would recur)"
                events.append((t, before, mode, x[0], x[1], "state"))
    return solutions, events


def controller_reference(values: dict, error0, segments, rtol=1e-12, atol=1e-12):
    """theta (M weights) and w_hat through constant-input segments [(t0, t1, (e, de, ym, dym)), ...]:
    the adaptive law [31] of afc_math (controller_output, adaptation_signal, adaptation_rates,
    estimate_rate) with e(t0), de(t0) latched at the start; returns the solve_ivp pieces."""
    p = afc_math.controller_parameters(values, error0, segments[0][0])
    rules, variant = p["rules"], p["variant"]

    def derivative(t, state, inputs):
        error, reference = inputs[:2], inputs[2:]
        theta, w_hat = list(state[:rules]), float(state[rules])
        _, modified, _, xi = afc_math.controller_output(error, reference, t, theta, w_hat, p)
        tau = afc_math.adaptation_signal(modified, p["p_b"])
        rates = afc_math.adaptation_rates(theta, tau, xi, values["gamma"], values["m_theta"], values["delta"])
        w_rate = afc_math.estimate_rate(tau, values["gamma_w"]) if variant == afc_math.VARIANT_FAE else 0.0
        return [*rates, w_rate]

    x0 = [float(values["theta0"])] * rules + [0.0]
    return smooth_reference(derivative, x0, segments, rtol, atol), p


def no_nan(values) -> bool:
    return all(math.isfinite(v) for v in values)
