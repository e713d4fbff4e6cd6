"""Manipulator: the single-link manipulator with friction (38, 39) as a co-simulation FMU.

docs/model.md section 7 (the plants) and section 11 (co-simulation semantics).  The model
equations are in ``plants.manipulator.model``, the integrator in ``plant_integration``; this class only
adapts them to FMI.

Co-simulation semantics:
* y, dy are the states x1, x2, d the friction term -(sgn(x2) cr + vr x2)/J
  and mr the payload mr(t), all at the current communication time; no
  output depends directly on u, so a closed loop through this FMU has no
  algebraic loop.
* In initialization mode the outputs already follow x1_start, x2_start (and
  the start time), so a master can propagate initial values before the
  controller latches e(0), de(0) at the end of initialisation.
* doStep(t, h) holds u over [t, t + h] and integrates with classical RK4 in
  ceil(h / max_internal_step) equal internal steps, with no event handling
  at x2 = 0 (see ``plants.manipulator.model``: first-order convergence where the
  Coulomb friction switches or the arm sticks).
"""
import math

from pythonfmu import DefaultExperiment

from fmu_src.afc_declaration import Derivative, EventIndicator, ModelExchange, TestDrive
from fmu_src.afc_slave_base import INPUT, OUTPUT, Variable, finite, non_negative, positive
# pythonfmu's C loader finds the model class by the pattern "class X(Fmi2Slave):",
# so the plants' shared base class is imported under that name.
from plants.rk4_plant_slave import RK4PlantSlave as Fmi2Slave
from plants.manipulator import model

KIND = "plant"  # plants/registry.py: the shared RK4 files this FMU carries
VARIABLES = (
    positive("gv", 9.8, "m/s2", "gravitational acceleration"),
    positive("lr", 0.25, "m", "link length"),
    non_negative("dr", 2.0, "N.m.s/rad", "joint damping coefficient"),
    non_negative("cr", 1.5, "N.m", "Coulomb friction torque"),
    non_negative("vr", 0.3, "N.m.s/rad", "viscous friction coefficient"),
    positive("mr0", 5.0, "kg", "mean payload mass: mr(t) = mr0 + mr1 sin t"),
    non_negative("mr1", 4.0, "kg", "payload variation amplitude, must be < mr0"),
    finite("x1_start", math.pi / 6, "rad", "initial link angle x1(0)"),
    finite("x2_start", 0.0, "rad/s", "initial link rate x2(0)"),
    positive("max_internal_step", 1e-4, "s", "largest internal RK4 step"),
    Variable("u", INPUT, 0.0, "N.m", "joint torque (held over each communication step)"),
    Variable("y", OUTPUT, math.pi / 6, "rad", "link angle x1", initial_depends_on=("x1_start",)),
    Variable("dy", OUTPUT, 0.0, "rad/s", "link rate x2", initial_depends_on=("x2_start",)),
    Variable("d", OUTPUT, 0.0, "rad/s2", "friction term d = -(sgn(x2) cr + vr x2)/J in dx2",
             initial_depends_on=("lr", "cr", "vr", "mr0", "mr1", "x2_start")),
    Variable("mr", OUTPUT, 5.0, "kg", "payload mass mr(t) = mr0 + mr1 sin t", initial_depends_on=("mr0", "mr1")),
)


# beside the table (fmu_src/afc_declaration.py), built when asked: pythonfmu runs this script again at
# every instantiate
def model_exchange() -> ModelExchange:
    """The Model Exchange interface of the native edition (docs/model_exchange.md)."""
    return ModelExchange(
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
        reinit=("dy",))


def test_drive() -> TestDrive:
    """How the tests drive this FMU."""
    # the arm slides, sticks at t ~ 2 ms and breaks away when u jumps at 7 ms; mr1 < mr0 is the rule
    # the valid ranges alone do not state
    return TestDrive(dict(mr0=0.2, mr1=0.0, x1_start=math.pi / 2, x2_start=0.2),
                     lambda t: {"u": 0.7 if t < 0.007 - 1e-12 else -2.0}, 1e-4,
                     cross_parameter_violations=(("mr1", 5.0, {}), ("mr1", 7.0, {}), ("mr1", 3.0, {"mr0": 3.0})))


class Manipulator(Fmi2Slave):
    # The relative tolerance a Model Exchange host's solver needs for y, dy within 0.1 % of the
    # converged co-simulation (docs/model_exchange.md); co-simulation ignores it
    default_experiment = DefaultExperiment(tolerance=1e-8)
    VARIABLES = VARIABLES
    MODEL_DESCRIPTION = ("Single-link manipulator with Coulomb and viscous friction and a varying "
                         "payload, eqs. (38, 39) of Pan, Er, Huang, Wang (IEEE TFS 2011), "
                         "fixed-step RK4")
    derivative = staticmethod(model.manipulator_derivative)

    def model_params(self):
        return model.manipulator_params(self.gv, self.lr, self.dr, self.cr, self.vr, self.mr0, self.mr1)

    def cross_parameter_errors(self):
        if not self.mr1 < self.mr0:
            return [f"parameter mr1 = {self.mr1!r} is invalid; valid range: 0 <= mr1 < mr0 "
                    f"= {self.mr0!r} (the payload mr(t) = mr0 + mr1 sin t must stay > 0)"]
        return []

    def compute_outputs(self):
        mr = model.manipulator_payload(self.time, self.mr0, self.mr1)
        self.y = self.x1
        self.dy = self.x2
        self.d = model.manipulator_friction(self.x2, model.manipulator_inertia(mr, self.lr), self.cr, self.vr)
        self.mr = mr
        self.outputs_stale = False
