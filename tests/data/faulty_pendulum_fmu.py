"""A test FMU: the inverted pendulum, raising inside doStep from t = fault_time on."""
from afc_slave_base import Variable, PARAMETER
from inverted_pendulum_fmu import VARIABLES as PENDULUM_VARIABLES
# pythonfmu's C loader needs the literal "class X(Fmi2Slave):"
from inverted_pendulum_fmu import InvertedPendulum as Fmi2Slave


class FaultyPendulum(Fmi2Slave):
    VARIABLES = PENDULUM_VARIABLES + (
        Variable("fault_time", PARAMETER, 0.5, "s", "doStep raises from this time on"),)

    def step(self, current_time, step_size):
        if current_time >= self.fault_time - 1e-12:
            raise RuntimeError(f"injected fault at t = {current_time}")
        return super().step(current_time, step_size)
