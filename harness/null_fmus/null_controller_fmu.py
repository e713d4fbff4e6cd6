"""Benchmark floor: an FMU with the variables of AdaptiveFuzzyController whose doStep does no work."""
from adaptive_fuzzy_controller_fmu import VARIABLES
# pythonfmu's C loader needs the literal "class X(Fmi2Slave):"
from afc_slave_base import TableSlave as Fmi2Slave


class NullController(Fmi2Slave):
    VARIABLES = VARIABLES
    MODEL_DESCRIPTION = "Benchmark floor: the variables of AdaptiveFuzzyController, no computation"

    def compute_outputs(self):
        self.outputs_stale = False

    def step(self, current_time, step_size):
        return True
