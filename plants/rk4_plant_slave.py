"""Shared base of the plant FMUs: a model integrated by fixed-step RK4 inside doStep.

A plant FMU declares its variable table (with ``x1_start``, ``x2_start``,
..., ``max_internal_step`` and the input ``u``), its pure derivative and
``model_params()`` (the constants tuple of that function), and sets its
outputs in ``compute_outputs``.  Two states (the default ``STATE_ATTRIBUTES``
``("x1", "x2")``): ``derivative(t, x1, x2, u, params) -> (dx1, dx2)``, the
lean path of ``plant_integration.rk4_advance``; more states (a subclass sets
``STATE_ATTRIBUTES = ("x1", "x2", "x3", ...)``): ``derivative(t, x, u,
params) -> dx`` on tuples, ``plant_integration.rk4_advance_states``.  This class holds the state,
advances it over each communication step with u held, and fails the step
with a clear message when the state leaves the finite numbers.
Standard library and pythonfmu only: it travels inside each plant FMU.
"""
import math

from fmu_src.afc_slave_base import TableSlave
from plants import plant_integration


class RK4PlantSlave(TableSlave):
    STATE_ATTRIBUTES = ("x1", "x2")

    @staticmethod
    def derivative(t, x1, x2, u, params):
        """(dx1, dx2) of the model; overridden by each plant."""
        raise NotImplementedError

    def model_params(self) -> tuple:
        """The constants tuple of ``derivative`` from the current parameters."""
        raise NotImplementedError

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.initialize(self.start_time)

    def initialize(self, start_time):
        for name in self.STATE_ATTRIBUTES:
            setattr(self, name, float(getattr(self, f"{name}_start")))
        self._update_params()

    def _update_params(self):
        try:
            self._params = self.model_params()
        except ZeroDivisionError:  # invalid parameters, rejected when initialisation ends
            self._params = None

    def _set_fmu_state(self, state):
        super()._set_fmu_state(state)
        self._update_params()  # the derived constants follow the restored parameters

    def step(self, current_time, step_size):
        if len(self.STATE_ATTRIBUTES) != 2:
            return self._step_states(current_time, step_size)
        try:
            x1, x2 = plant_integration.rk4_advance(
                self.derivative, current_time, self.x1, self.x2, self.u,
                step_size, self.max_internal_step, self._params)
        except (ArithmeticError, ValueError) as error:  # overflow, math domain error
            x1 = x2 = math.nan
            reason = f" ({error})"
        else:
            reason = ""
        if x1 - x1 != 0.0 or x2 - x2 != 0.0:  # NaN or inf
            self.fail(f"state diverged in doStep(t={current_time!r}, h={step_size!r}) "
                      f"from x1={self.x1!r}, x2={self.x2!r} with u={self.u!r}{reason}; "
                      "the closed loop is unstable at this step size")
        self.x1 = x1
        self.x2 = x2
        return True

    def _step_states(self, current_time, step_size):
        names = self.STATE_ATTRIBUTES
        x = tuple(getattr(self, name) for name in names)
        try:
            new = plant_integration.rk4_advance_states(self.derivative, current_time, x, self.u,
                                                       step_size, self.max_internal_step, self._params)
        except (ArithmeticError, ValueError) as error:  # overflow, math domain error
            new, reason = (math.nan,) * len(x), f" ({error})"
        else:
            reason = ""
        if any(value - value != 0.0 for value in new):  # NaN or inf
            start = ", ".join(f"{name}={value!r}" for name, value in zip(names, x))
            self.fail(f"state diverged in doStep(t={current_time!r}, h={step_size!r}) "
                      f"from {start} with u={self.u!r}{reason}; "
                      "the closed loop is unstable at this step size")
        self.__dict__.update(zip(names, new))
        return True
