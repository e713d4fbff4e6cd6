"""Actuator: the limits between the controller and a plant, as a co-simulation FMU.

docs/model.md section 13.  The command u is sampled on the actuator's own clock and delayed by
``delay_samples`` samples (plants/sampled_chain.py, (C1), (C2): a converter updated every Ts
that applies each command d samples late), saturated to |u| <= u_max (A1) and rate-limited as
Modelica's SlewRateLimiter (A2).  The pure functions are ``plants.actuator.model``; this class
only adapts them to FMI.

Co-simulation semantics:
* without a rate limit (``rate_limit = 0``) ``u_applied`` depends directly on ``u`` (the
  saturated command of this communication point, or the held sample); with one it is the rate
  limiter's state r, integrated exactly over each step (the command held between samples);
* with every parameter at its default (no clock, delay, saturation or rate limit) ``u_applied``
  is ``u``, bit for bit;
* the rate limiter starts at rest (Modelica's steady-state initialisation): r follows the
  saturated command until the first doStep, which starts it from the command the host set there.
"""
import math

from pythonfmu import DefaultExperiment

from fmu_src.afc_declaration import Derivative, ModelExchange, TestDrive
from fmu_src.afc_slave_base import INPUT, OUTPUT, PARAMETER, Variable, non_negative, positive
# pythonfmu's C loader finds the model class by the pattern "class X(Fmi2Slave):",
# so the sampled FMUs' shared base class is imported under that name.
from plants.sampled_slave import SampledSlave as Fmi2Slave
from plants import sampled_chain
from plants.actuator import model

KIND = "sampled"  # plants/registry.py: the shared files this FMU carries
LIMITS = ("sample_period", "delay_samples", "u_max")

VARIABLES = (
    non_negative("sample_period", 0.0, "s", "Ts, the actuator's own update period (C1); 0: no clock of its own, "
                                            "the command passes at every communication point"),
    Variable("delay_samples", PARAMETER, 0, "", "d, the delay of the command in samples (C2); needs "
                                                "sample_period > 0", kind="Integer", minimum=0,
             maximum=sampled_chain.MAX_DELAY_SAMPLES),
    Variable("u_max", PARAMETER, 0.0, declared_type="PlantInput", minimum=0.0,
             description="saturation |u_applied| <= u_max (A1); 0: none"),
    non_negative("rate_limit", 0.0, "", "R, the largest rate of u_applied (A2), in the unit of u per second; "
                                        "0: none"),
    positive("rate_time_constant", 1e-3, "s", "Td, the rate limiter's derivative time constant (A2) "
                                              "(Modelica's SlewRateLimiter default)"),
    Variable("u", INPUT, 0.0, declared_type="PlantInput", description="the controller's command u"),
    Variable("u_applied", OUTPUT, 0.0, declared_type="PlantInput", depends_on=("u",),
             initial_depends_on=(*LIMITS, "u"),
             description="the input the plant gets: u sampled, delayed, saturated and rate-limited"),
    Variable("slew_state", OUTPUT, 0.0, declared_type="PlantInput", initial_depends_on=(*LIMITS, "u"),
             description="the rate limiter's state r of (A2): u_applied when rate_limit > 0; with "
                         "rate_limit = 0 it keeps its initial value"),
)


def model_exchange() -> ModelExchange:
    """The Model Exchange interface of the native edition (docs/model_exchange.md): the rate
    limiter's state r (A2) and, with a clock, its samples as time events."""
    return ModelExchange(
        derivatives=(Derivative("slew_state", (("slew_state", "dependent"), ("u", "dependent")),
                                ("sample_period", "delay_samples", "u_max", "rate_limit", "rate_time_constant"),
                                "dr/dt of (A2), 0 with rate_limit = 0"),),
        output_states=(("u_applied", (("slew_state", "dependent"),)),),
        time_events=True)


def test_drive() -> TestDrive:
    """How the tests drive this FMU: every stage on, an update period of 2.5 host steps."""
    return TestDrive(dict(sample_period=2.5e-3, delay_samples=1, u_max=0.8, rate_limit=40.0, rate_time_constant=2e-3),
                     lambda t: {"u": 1.2 * math.sin(9.0 * t)}, 1e-3,
                     cross_parameter_violations=(("delay_samples", 1, {}),))


class Actuator(Fmi2Slave):
    # The relative tolerance a Model Exchange host's solver needs (the plants' one); co-simulation ignores it
    default_experiment = DefaultExperiment(tolerance=1e-8)
    VARIABLES = VARIABLES
    CHANNELS = (("u", "u_applied"),)
    STATE_ATTRIBUTES = (*Fmi2Slave.STATE_ATTRIBUTES, "slew", "slew_started")
    MODEL_DESCRIPTION = ("Actuator: the command sampled on its own clock and delayed by n samples, saturated "
                         "(|u| <= u_max) and rate-limited (Modelica SlewRateLimiter)")

    def cross_parameter_errors(self):
        if self.sample_period == 0.0 and self.delay_samples != 0:
            return [f"parameter delay_samples = {self.delay_samples!r} is invalid with sample_period = 0; valid "
                    "range: 0 (a delay in samples needs a clock of its own: give sample_period > 0)"]
        return []

    def initialize(self, start_time):
        super().initialize(start_time)
        self.slew = 0.0
        self.slew_started = False

    def feeds_through(self):
        return self.rate_limit == 0.0

    def set_outputs(self, held):
        target = model.saturate(held[0], self.u_max)  # (A1)
        if not self.slew_started:  # at rest until the first doStep: r = v
            self.slew = target
        self.slew_state = self.slew
        self.u_applied = self.slew if self.rate_limit != 0.0 else target

    def advance(self, begin, end, held):
        target = model.saturate(held[0], self.u_max)  # (A1)
        if not self.slew_started:
            self.slew = target
            self.slew_started = True
        if self.rate_limit != 0.0 and end > begin:
            self.slew = model.slew(self.slew, target, end - begin, self.rate_limit, self.rate_time_constant)  # (A2)
