"""Shared base of the sampled FMUs (Sensor, Actuator): the chain of plants/sampled_chain.py as a co-simulation slave.

docs/model.md section 13.  A subclass declares its variable table (with the parameters
``sample_period`` and ``delay_samples``), its channels ``CHANNELS`` (input, output), the processing
of one sample (``process``), what follows the chain (``set_outputs``: the sensor writes the held
values, the actuator saturates and rate-limits them) and, if it has a state between samples,
``advance`` over a stretch of time with the chain's output held.

``sample_period = 0``: no clock of its own; the chain is the identity at every communication point
(the subclass's ``process`` of the current input, sample index 0, no delay).

What a host gets wrong, and what the FMU does about it:

* no initial-value propagation: nothing is taken before the first doStep; sample 0 comes from the
  inputs the host set for the step at the start time;
* Jacobi (every link delayed one step), or any host that reads this FMU's outputs before it sets
  its inputs at a communication point: where an output depends on the current input, the host
  got values from the inputs of the previous point while the sample is taken from the new ones;
  the FMU logs one warning naming the time (every FMU that passes its input straight through adds
  one step of delay in such a host) and goes on.

Standard library and pythonfmu only: it travels inside each sampled FMU.
"""
from fmu_src.afc_slave_base import TableSlave
from plants import sampled_chain as chain


class SampledSlave(TableSlave):
    CHANNELS: tuple = ()  # ((input name, output name), ...)
    STATE_ATTRIBUTES = ("chain", "read_time", "read_inputs", "warned_read_before_set")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._inputs_of = tuple(name for name, _ in self.CHANNELS)
        self.initialize(self.start_time)

    # ------------------------------------------------------------ model hooks
    def process(self, k: int, channel: int, value: float, previous: float) -> float:
        """Sample k of ``channel`` from the input ``value`` (``previous``: the processed sample k - 1)."""
        return value

    def set_outputs(self, held: list) -> None:
        """Set the outputs from the chain's values that hold now (one per channel)."""
        raise NotImplementedError

    def advance(self, begin: float, end: float, held: list) -> None:
        """Advance a state over [begin, end] with the chain's values ``held`` (none by default)."""

    def feeds_through(self) -> bool:
        """Does an output depend on the current input (at a sample instant)?"""
        return True

    # ------------------------------------------------------------- the chain
    def initialize(self, start_time):
        self.chain = chain.new_state(len(self.CHANNELS))
        self.read_time = float("nan")  # the first output computation of the current communication point
        self.read_inputs = [0.0] * len(self.CHANNELS)
        self.warned_read_before_set = False
        self.configure()

    def configure(self) -> None:
        """Derived constants from the parameters (also after an FMU state is restored)."""

    def _set_fmu_state(self, state):
        super()._set_fmu_state(state)
        self.configure()

    def _raw(self) -> list:
        attributes = self.__dict__
        return [attributes[name] for name in self._inputs_of]

    def _processed(self, k: int, raw: list) -> list:
        """Sample k of every channel from ``raw``, each after the committed sample k - 1."""
        state, channels = self.chain, len(self.CHANNELS)
        previous = [state[chain.slot(channels, k - 1, c)] if k > 0 else 0.0 for c in range(channels)]
        return [self.process(k, c, raw[c], previous[c]) for c in range(channels)]

    def _value_of(self, j: int, k: int, pending) -> list:
        """The values of sample j as held at sample k (``pending``: sample k's values if not committed)."""
        if pending is not None and j == k:
            return pending
        base = chain.slot(len(self.CHANNELS), j, 0)
        return self.chain[base:base + len(self.CHANNELS)]

    def held(self, raw: list) -> list:
        """The chain's values at the FMU's time, the pending sample taken from ``raw``."""
        if self.sample_period == 0.0:
            return [self.process(0, c, raw[c], 0.0) for c in range(len(self.CHANNELS))]
        k, is_pending = chain.held_index(self.chain, self.time, self.start_time, self.sample_period)
        pending = self._processed(k, raw) if is_pending else None
        return self._value_of(chain.delayed_index(k, self.delay_samples), k, pending)

    def compute_outputs(self):
        raw = self._raw()
        if self.initialized and self.time != self.read_time:
            self.read_time = self.time  # what the host reads first at this communication point
            self.read_inputs = raw
        self.set_outputs(self.held(raw))
        self.outputs_stale = False

    def _depends_on_input_now(self, t: float) -> bool:
        if not self.feeds_through():
            return False
        if self.sample_period == 0.0:
            return True
        return self.delay_samples == 0 and chain.at_instant(t, self.start_time, self.sample_period,
                                                            chain.committed(self.chain))

    def _check_read_before_set(self, t: float, raw: list) -> None:
        if (not self.warned_read_before_set and self.read_time == t and self.read_inputs != raw
                and self._depends_on_input_now(t)):
            self.warned_read_before_set = True
            inputs = ", ".join(name for name, _ in self.CHANNELS)
            outputs = ", ".join(name for _, name in self.CHANNELS)
            self.warn(f"the host read {outputs} at t = {t!r} before it set {inputs} there (a host that delays "
                      "every link one communication step, Jacobi, or one that reads this FMU before it sets it): "
                      "it got values from the inputs of its previous communication point, while this FMU takes "
                      "its sample from the inputs set for doStep, so every FMU that passes its input straight "
                      "through adds one step of delay to the loop in such a host. Set this FMU's inputs before "
                      "reading its outputs (a master that respects direct feedthrough)")

    def step(self, current_time, step_size):
        raw = self._raw()
        self._check_read_before_set(current_time, raw)
        end = current_time + step_size
        if self.sample_period == 0.0:
            self.advance(current_time, end, self.held(raw))
            return True
        start, period, channels = self.start_time, self.sample_period, len(self.CHANNELS)
        values = self.held(raw)
        begin = current_time
        for _ in range(chain.samples_before(self.chain, end, start, period)):
            k = chain.committed(self.chain)
            instant = chain.sample_time(start, period, k)
            if instant > begin:
                self.advance(begin, instant, values)
                begin = instant
            chain.commit(self.chain, channels, self._processed(k, raw))
            values = self._value_of(chain.delayed_index(k, self.delay_samples), k + 1, None)
        self.advance(begin, end, values)
        return True
