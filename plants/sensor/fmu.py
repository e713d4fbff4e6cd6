"""Sensor: the measurement between a plant and the controller, as a co-simulation FMU.

docs/model.md section 13.  Per channel (y, dy, d2y, d3y: the plant's outputs up to order 4) it
takes samples on a clock of its own (``sample_period``), adds reproducible Gaussian noise (S1),
quantises (S2), filters (S3) and delays them by ``delay_samples`` samples (C2); the outputs hold
each sample until the next.  The pure functions are ``plants.sensor.model`` (the measurement) and
``plants.sampled_chain`` (the clock and the delay line); this class only adapts them to FMI.

Co-simulation semantics:
* at a communication point that is a sample instant, the sample is taken from the inputs set
  there: with ``delay_samples = 0`` the outputs depend directly on the inputs (as a plain wire
  does); between sample instants they hold;
* with every parameter at its default (no clock, noise, quantiser, filter or delay) each output is
  its input, bit for bit;
* in initialization mode the outputs follow the inputs set so far (sample 0, its noise included),
  so a master can propagate initial values through the sensor;
* the noise of sample k is a function of (seed, local_seed, channel, k) only: the same in any host
  and edition, however the host steps.
"""
from pythonfmu import DefaultExperiment

from fmu_src.afc_declaration import ModelExchange, TestDrive
from fmu_src.afc_slave_base import INPUT, OUTPUT, PARAMETER, Variable, non_negative
# pythonfmu's C loader finds the model class by the pattern "class X(Fmi2Slave):",
# so the sampled FMUs' shared base class is imported under that name.
from plants.sampled_slave import SampledSlave as Fmi2Slave
from plants import sampled_chain
from plants.sensor import model

KIND = "sampled"  # plants/registry.py: the shared files this FMU carries
#: the channels: (input, output, declared type of both, meaning)
CHANNELS = (("y", "y_measured", "PlantOutput", "plant output y"),
            ("dy", "dy_measured", "PlantOutputRate", "plant output rate dy"),
            ("d2y", "d2y_measured", "PlantOutputAcceleration", "plant output acceleration d2y (order >= 3)"),
            ("d3y", "d3y_measured", "PlantOutputJerk", "plant output jerk d3y (order 4)"))
CHAIN_PARAMETERS = ("sample_period", "delay_samples", "filter_time_constant", "seed", "local_seed")


def _channel_parameters():
    rows = []
    for kind, meaning in (("noise", "standard deviation of the additive Gaussian noise on {} (S1); 0: none"),
                          ("quantum", "quantisation step of {} (S2); 0: none")):
        for name, _, declared, what in CHANNELS:
            rows.append(Variable(f"{kind}_{name}", PARAMETER, 0.0, declared_type=declared, minimum=0.0,
                                 description=meaning.format(name)))
    return tuple(rows)


def _channel_signals():
    rows = []
    for name, _, declared, what in CHANNELS:
        rows.append(Variable(name, INPUT, 0.0, declared_type=declared, description=f"true {what}"))
    for name, measured, declared, what in CHANNELS:
        initial = (*CHAIN_PARAMETERS, f"noise_{name}", f"quantum_{name}", name)
        rows.append(Variable(measured, OUTPUT, 0.0, declared_type=declared, depends_on=(name,),
                             initial_depends_on=initial,
                             description=f"measured {what}: sampled, noisy, quantised, filtered, delayed"))
    return tuple(rows)


VARIABLES = (
    non_negative("sample_period", 0.0, "s", "Ts, the sensor's own sample period (C1); 0: no clock of its own, "
                                            "the outputs follow the inputs at every communication point"),
    Variable("delay_samples", PARAMETER, 0, "", "d, the delay in samples (C2); needs sample_period > 0",
             kind="Integer", minimum=0, maximum=sampled_chain.MAX_DELAY_SAMPLES),
    non_negative("filter_time_constant", 0.0, "s", "T of the first-order filter (S3); 0: none; needs "
                                                   "sample_period > 0"),
    Variable("seed", PARAMETER, 0, "", "global seed of the noise (S1), shared by the scenario's noise sources",
             kind="Integer", minimum=0),
    Variable("local_seed", PARAMETER, 1, "", "this instance's seed of the noise (S1): distinct sources draw "
                                             "independent noise from one global seed", kind="Integer", minimum=0),
    *_channel_parameters(),
    *_channel_signals(),
)


def model_exchange() -> ModelExchange:
    """The Model Exchange interface of the native edition (docs/model_exchange.md): no continuous
    state; the samples are time events at t_k (C1), announced as the next event time."""
    return ModelExchange(time_events=True)


def test_drive() -> TestDrive:
    """How the tests drive this FMU: every stage on, a sample period of 2.5 host steps (samples inside
    steps and at communication points)."""
    return TestDrive(dict(sample_period=2.5e-3, delay_samples=2, filter_time_constant=4e-3, seed=7, local_seed=3,
                          noise_y=1e-3, noise_dy=2e-2, noise_d2y=0.5, quantum_y=1e-3, quantum_dy=1e-2),
                     lambda t: {"y": 0.3 * t, "dy": 0.3, "d2y": -0.2 * t, "d3y": 0.0}, 1e-3,
                     cross_parameter_violations=(("noise_y", 1e-3, {}), ("delay_samples", 1, {}),
                                                 ("filter_time_constant", 1e-3, {})))


class Sensor(Fmi2Slave):
    # No continuous state: the tolerance does not act; the plants' one, for a host integrating the loop
    default_experiment = DefaultExperiment(tolerance=1e-8)
    VARIABLES = VARIABLES
    CHANNELS = tuple((name, measured) for name, measured, _, _ in CHANNELS)
    MODEL_DESCRIPTION = ("Sensor: per channel y, dy, d2y, d3y sampled on its own clock, reproducible Gaussian "
                         "noise (SplitMix64, Box-Muller), quantiser, first-order filter, delay of n samples")

    def configure(self):
        self._keys = tuple(model.stream_key(self.seed, self.local_seed, c) for c in range(len(CHANNELS)))
        self._sigma = tuple(getattr(self, f"noise_{name}") for name, _, _, _ in CHANNELS)
        self._quantum = tuple(getattr(self, f"quantum_{name}") for name, _, _, _ in CHANNELS)
        self._coefficient = model.filter_coefficient(self.sample_period, self.filter_time_constant)
        self._filtered = self.filter_time_constant != 0.0

    def cross_parameter_errors(self):
        if self.sample_period != 0.0:
            return []
        needs = "needs a sample period of its own: give sample_period > 0"
        errors = [f"parameter noise_{name} = {getattr(self, f'noise_{name}')!r} is invalid with sample_period = 0; "
                  f"valid range: 0 (the noise is drawn once per sample of the sensor's clock, so it {needs})"
                  for name, _, _, _ in CHANNELS if getattr(self, f"noise_{name}") != 0.0]
        if self.delay_samples != 0:
            errors.append(f"parameter delay_samples = {self.delay_samples!r} is invalid with sample_period = 0; "
                          f"valid range: 0 (a delay in samples {needs})")
        if self.filter_time_constant != 0.0:
            errors.append(f"parameter filter_time_constant = {self.filter_time_constant!r} is invalid with "
                          f"sample_period = 0; valid range: 0 (the filter runs at each sample, so it {needs})")
        return errors

    def process(self, k, channel, value, previous):
        return model.measure(self._keys[channel], k, value, previous, self._sigma[channel], self._quantum[channel],
                             self._coefficient, self._filtered)

    def set_outputs(self, held):
        self.y_measured, self.dy_measured, self.d2y_measured, self.d3y_measured = held
