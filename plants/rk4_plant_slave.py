"""Shared base of the plant FMUs: a 2-state model integrated by fixed-step RK4 inside doStep.

A plant FMU declares its variable table (with ``x1_start``, ``x2_start``,
``max_internal_step`` and the input ``u``), its pure ``derivative(t, x1, x2,
u, params)`` and ``model_params()`` (the constants tuple of that function),
and sets its outputs in ``compute_outputs``.  This class holds the state,
advances it over each communication step with u held, and fails the step
with a clear message when the state leaves the finite numbers.
Standard library and pythonfmu only: it travels inside each plant FMU.
"""
import math

import plant_integration
from afc_slave_base import TableSlave


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
        self.x1 = float(self.x1_start)
        self.x2 = float(self.x2_start)
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
