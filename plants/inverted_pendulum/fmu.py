"""InvertedPendulum: the inverted pendulum on a cart (37) as a co-simulation FMU.

docs/model.md section 7 (the plants) and section 11 (co-simulation semantics).  The model
equations are in ``plants.inverted_pendulum.model``, the integrator in ``plant_integration``; this
class only adapts them to FMI.

Co-simulation semantics:
* y, dy are the states x1, x2 and d the disturbance d(t), all at the
  current communication time; no output depends directly on u, so a
  closed loop through this FMU has no algebraic loop.
* In initialization mode the outputs already follow x1_start, x2_start (and d
  the start time), so a master can propagate initial values before the
  controller latches e(0), de(0) at the end of initialisation.
* doStep(t, h) holds u over [t, t + h] and integrates with classical RK4 in
  ceil(h / max_internal_step) equal internal steps.
"""
import math

from pythonfmu import DefaultExperiment

from fmu_src.afc_declaration import Derivative, ModelExchange, TestDrive
from fmu_src.afc_slave_base import INPUT, OUTPUT, Variable, finite, positive
# pythonfmu's C loader finds the model class by the pattern "class X(Fmi2Slave):",
# so the plants' shared base class is imported under that name.
from plants.rk4_plant_slave import RK4PlantSlave as Fmi2Slave
from plants.inverted_pendulum import model

KIND = "plant"  # plants/registry.py: the shared RK4 files this FMU carries
VARIABLES = (
    positive("gv", 9.8, "m/s2", "gravitational acceleration"),
    positive("mc", 1.0, "kg", "cart mass"),
    positive("mp", 0.1, "kg", "pole mass (case 3: 1)"),
    positive("lp", 0.5, "m", "pole half-length"),
    finite("x1_start", math.pi / 12, "rad", "initial pole angle x1(0)"),
    finite("x2_start", 0.0, "rad/s", "initial pole rate x2(0)"),
    finite("dist_gain", 0.0, "", "gain of d(t) = 3 cos 2t + 2 sin((0.09 t + 1) t): "
                                 "0 case 1, 1 cases 2 and 3"),
    positive("max_internal_step", 1e-4, "s", "largest internal RK4 step"),
    Variable("u", INPUT, 0.0, "N", "force on the cart (held over each communication step)"),
    Variable("y", OUTPUT, math.pi / 12, "rad", "pole angle x1 (from the vertical)", initial_depends_on=("x1_start",)),
    Variable("dy", OUTPUT, 0.0, "rad/s", "pole rate x2", initial_depends_on=("x2_start",)),
    Variable("d", OUTPUT, 0.0, "rad/s2", "disturbance d(t) added to dx2", initial_depends_on=("dist_gain",)),
)


# beside the table (fmu_src/afc_declaration.py), built when asked: pythonfmu runs this script again at
# every instantiate
def model_exchange() -> ModelExchange:
    """The Model Exchange interface of the native edition (docs/model_exchange.md)."""
    return ModelExchange(
        derivatives=(Derivative("y", (("dy", "constant"),), (), "dx1 = x2 (37)"),
                     Derivative("dy", (("y", "dependent"), ("dy", "dependent"), ("u", "dependent")),
                                ("gv", "mc", "mp", "lp", "dist_gain"), "dx2 of (37) with d(t)")))


def test_drive() -> TestDrive:
    """How the tests drive this FMU."""
    return TestDrive(dict(dist_gain=1.0), lambda t: {"u": math.sin(3 * t)}, 1e-3)


class InvertedPendulum(Fmi2Slave):
    # The relative tolerance a Model Exchange host's solver needs for y, dy within 0.1 % of the
    # converged co-simulation (docs/model_exchange.md); co-simulation ignores it
    default_experiment = DefaultExperiment(tolerance=1e-8)
    VARIABLES = VARIABLES
    MODEL_DESCRIPTION = ("Inverted pendulum on a cart, eq. (37) of Pan, Er, Huang, Wang "
                         "(IEEE TFS 2011), with additive disturbance d(t), fixed-step RK4")
    derivative = staticmethod(model.pendulum_derivative)

    def model_params(self):
        return model.pendulum_params(self.gv, self.mc, self.mp, self.lp, self.dist_gain)

    def compute_outputs(self):
        self.y = self.x1
        self.dy = self.x2
        self.d = model.pendulum_disturbance(self.time, self.dist_gain)
        self.outputs_stale = False
