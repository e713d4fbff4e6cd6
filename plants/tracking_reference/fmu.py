"""TrackingReference: the reference ym(t) = amplitude sin(omega t) and the
tracking errors e = ym - y, de = dym - dy (and d2e = ddym - d2y for a
third-order plant) as a co-simulation FMU.

docs/model.md section 1 (the problem), section 8 (scenarios) and section 11 (co-simulation
semantics); the scenarios' amplitude is pi/6 for the pendulum, 1 for the manipulator, and
omega = 1 rad/s in both.

Co-simulation semantics:
* ym, dym, ddym are functions of the current communication time only (no
  input dependency); e and de depend directly on the inputs y and dy at the
  same communication point (direct feedthrough): reading e after setting y
  gives e for that y, without a doStep.
* The outputs are available in initialization mode too (at the start
  time), so a master can propagate e(0), de(0) to the controller before it
  latches them at the end of initialisation.
* doStep only advances the time; the FMU has no other state.
"""
import math

# pythonfmu's C loader finds the model class by the pattern "class X(Fmi2Slave):",
# so the project's base class is imported under that name.
from pythonfmu import DefaultExperiment

from fmu_src.afc_declaration import ModelExchange, TestDrive
from fmu_src.afc_slave_base import INPUT, OUTPUT, Variable, finite, positive
from fmu_src.afc_slave_base import TableSlave as Fmi2Slave

KIND = "reference"  # plants/registry.py: no state, no shared files
_sin = math.sin
_cos = math.cos

REFERENCE_PARAMETERS = ("amplitude", "omega")  # ym, dym, ddym at the start time depend on these only
VARIABLES = (
    finite("amplitude", math.pi / 6, "rad", "reference amplitude A of ym = A sin(omega t) "
                                            "(pendulum pi/6, manipulator 1)"),
    positive("omega", 1.0, "rad/s", "reference angular frequency omega"),
    Variable("y", INPUT, 0.0, "rad", "plant output y"),
    Variable("dy", INPUT, 0.0, "rad/s", "plant output rate dy"),
    Variable("ym", OUTPUT, 0.0, "rad", "reference ym = A sin(omega t)", initial_depends_on=REFERENCE_PARAMETERS),
    Variable("dym", OUTPUT, 0.0, "rad/s", "reference rate dym = A omega cos(omega t)",
             initial_depends_on=REFERENCE_PARAMETERS),
    Variable("ddym", OUTPUT, 0.0, "rad/s2", "reference acceleration ddym = -A omega^2 sin(omega t)",
             initial_depends_on=REFERENCE_PARAMETERS),
    Variable("e", OUTPUT, 0.0, "rad", "tracking error e = ym - y", depends_on=("y",), dependency_kinds=("constant",),
             initial_depends_on=(*REFERENCE_PARAMETERS, "y")),
    Variable("de", OUTPUT, 0.0, "rad/s", "tracking error rate de = dym - dy", depends_on=("dy",),
             dependency_kinds=("constant",), initial_depends_on=(*REFERENCE_PARAMETERS, "dy")),
    # appended for third-order plants (value references above unchanged)
    Variable("d2y", INPUT, 0.0, "rad/s2", "plant output acceleration d2y (third-order plants)"),
    Variable("d2e", OUTPUT, 0.0, "rad/s2", "tracking error acceleration d2e = ddym - d2y",
             depends_on=("d2y",), dependency_kinds=("constant",), initial_depends_on=(*REFERENCE_PARAMETERS, "d2y")),
)


# beside the table (fmu_src/afc_declaration.py), built when asked: pythonfmu runs this script again at
# every instantiate
def model_exchange() -> ModelExchange:
    """The Model Exchange interface of the native edition (docs/model_exchange.md)."""
    # no continuous state: the outputs follow the host's time
    return ModelExchange()


def test_drive() -> TestDrive:
    """How the tests drive this FMU."""
    return TestDrive({}, lambda t: {"y": 0.1 * t, "dy": 0.1}, 1e-3)


class TrackingReference(Fmi2Slave):
    # No continuous state: the tolerance does not act; the plants' one, for a host integrating the loop
    default_experiment = DefaultExperiment(tolerance=1e-8)
    VARIABLES = VARIABLES
    MODEL_DESCRIPTION = ("Sinusoidal reference ym = A sin(omega t) with its derivatives and the "
                         "tracking errors e = ym - y, de = dym - dy")

    def compute_outputs(self):
        amplitude, omega = self.amplitude, self.omega
        phase = omega * self.time
        s = _sin(phase)
        ym = amplitude * s
        dym = amplitude * omega * _cos(phase)
        self.ym = ym
        self.dym = dym
        ddym = -amplitude * omega * omega * s
        self.ddym = ddym
        self.e = ym - self.y
        self.de = dym - self.dy
        self.d2e = ddym - self.d2y
        self.outputs_stale = False

    def step(self, current_time, step_size):
        return True
