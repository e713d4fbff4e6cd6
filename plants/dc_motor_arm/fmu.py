"""DcMotorArm: an arm driven by a DC motor with armature inductance, a third-order plant FMU.

Our own plant for the general-order controller (docs/general_order.md); the
equations are in ``plants.dc_motor_arm.model``, the integrator in
``plant_integration``; this class only adapts them to FMI.

Co-simulation semantics (as the other plants):
* y, dy, d2y are the angle, rate and acceleration and i the armature
  current, all at the current communication time; no output depends
  directly on u (the voltage acts through the inductance), so a closed loop
  through this FMU has no algebraic loop.
* In initialization mode the outputs already follow x1_start..x3_start.
* doStep(t, h) holds u over [t, t + h] and integrates with classical RK4 in
  ceil(h / max_internal_step) equal internal steps.
"""
import math

from pythonfmu import DefaultExperiment

from fmu_src.afc_declaration import Derivative, ModelExchange, TestDrive
from fmu_src.afc_slave_base import INPUT, OUTPUT, Variable, finite, non_negative, positive
# pythonfmu's C loader finds the model class by the pattern "class X(Fmi2Slave):",
# so the plants' shared base class is imported under that name.
from plants.rk4_plant_slave import RK4PlantSlave as Fmi2Slave
from plants.dc_motor_arm import model

KIND = "plant"  # plants/registry.py: the shared RK4 files this FMU carries
VARIABLES = (
    positive("J", 0.5, "kg.m2", "inertia at the motor shaft (motor and arm)"),
    non_negative("b", 0.2, "N.m.s/rad", "viscous friction"),
    non_negative("m", 2.0, "kg", "arm mass (gravity load m gv lc sin x1)"),
    non_negative("lc", 0.25, "m", "distance from the joint to the arm's mass centre"),
    positive("gv", 9.8, "m/s2", "gravitational acceleration"),
    positive("Kt", 0.5, "N.m/A", "motor torque constant"),
    non_negative("Ke", 0.5, "V.s/rad", "back-emf constant"),
    positive("R", 1.0, "Ohm", "armature resistance"),
    positive("L", 0.1, "H", "armature inductance (L / R = 0.1 s electrical time constant)"),
    finite("x1_start", 0.3, "rad", "initial angle x1(0) (0 = hanging down)"),
    finite("x2_start", 0.0, "rad/s", "initial rate x2(0)"),
    finite("x3_start", 0.0, "A", "initial armature current x3(0)"),
    positive("max_internal_step", 1e-4, "s", "largest internal RK4 step"),
    Variable("u", INPUT, 0.0, "V", "armature voltage (held over each communication step)"),
    Variable("y", OUTPUT, 0.3, "rad", "arm angle x1", initial_depends_on=("x1_start",)),
    Variable("dy", OUTPUT, 0.0, "rad/s", "arm rate x2", initial_depends_on=("x2_start",)),
    Variable("d2y", OUTPUT, 0.0, "rad/s2", "arm acceleration dx2 = (Kt x3 - b x2 - m gv lc sin x1) / J",
             initial_depends_on=("J", "b", "m", "lc", "gv", "Kt", "x1_start", "x2_start", "x3_start")),
    Variable("i", OUTPUT, 0.0, "A", "armature current x3", initial_depends_on=("x3_start",)),
)


# beside the table (fmu_src/afc_declaration.py), built when asked: pythonfmu runs this script again at
# every instantiate
def model_exchange() -> ModelExchange:
    """The Model Exchange interface of the native edition (docs/model_exchange.md)."""
    return ModelExchange(
        derivatives=(Derivative("y", (("dy", "constant"),), (), "dx1 = x2"),
                     Derivative("dy", (("y", "dependent"), ("dy", "fixed"), ("i", "fixed")),
                                ("J", "b", "m", "lc", "gv", "Kt"), "dx2 = (Kt x3 - b x2 - m gv lc sin x1) / J"),
                     Derivative("i", (("dy", "fixed"), ("i", "fixed"), ("u", "fixed")), ("Ke", "R", "L"),
                                "dx3 = (u - R x3 - Ke x2) / L")),
        output_states=(("d2y", (("y", "dependent"), ("dy", "fixed"), ("i", "fixed"))),))


def test_drive() -> TestDrive:
    """How the tests drive this FMU."""
    return TestDrive({}, lambda t: {"u": 5.0 * math.cos(t)}, 1e-3)


class DcMotorArm(Fmi2Slave):
    # The relative tolerance a Model Exchange host's solver needs for y, dy within 0.1 % of the
    # converged co-simulation (docs/model_exchange.md); co-simulation ignores it
    default_experiment = DefaultExperiment(tolerance=1e-8)
    VARIABLES = VARIABLES
    STATE_ATTRIBUTES = ("x1", "x2", "x3")
    MODEL_DESCRIPTION = ("Arm driven by a DC motor with armature inductance: a third-order plant "
                         "(angle, rate, current), fixed-step RK4")
    derivative = staticmethod(model.motor_arm_derivative)

    def model_params(self):
        return model.motor_arm_params(self.J, self.b, self.m, self.lc, self.gv, self.Kt, self.Ke,
                                      self.R, self.L)

    def compute_outputs(self):
        self.y = self.x1
        self.dy = self.x2
        self.d2y = model.motor_arm_acceleration(self.x1, self.x2, self.x3, self._params)
        self.i = self.x3
        self.outputs_stale = False
