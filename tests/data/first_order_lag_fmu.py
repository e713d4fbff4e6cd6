"""A user's own plant, which the project does not ship: a first-order lag T dy/dt = K u - y.

Written as a user would write a plant with plain pythonfmu (not the project's FMU base), for the
tests of ``regress`` on a user's scenario (tests/test_regression_ci.py) and the CI recipes of
docs/ci.md. Exact discretisation over a communication step with u held:
y(t + h) = K u + (y(t) - K u) exp(-h / T).

pythonfmu lists outputs without ``dependencies`` (FMI 2.0: "depends on every input"); y does not
depend on u directly, so the model structure says so (``dependencies=""``), as an FMU exported by a
modelling tool would: otherwise a master sees an algebraic loop with the controller.
"""
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class FirstOrderLag(Fmi2Slave):
    description = "First-order lag T dy/dt = K u - y (a test plant)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.T = 0.5
        self.K = 2.0
        self.y_start = 0.0
        self.u = 0.0
        self.y = 0.0
        self.register_variable(Real("T", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable,
                                    description="time constant (s)"))
        self.register_variable(Real("K", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable,
                                    description="static gain"))
        self.register_variable(Real("y_start", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.tunable, description="y at the start time"))
        self.register_variable(Real("u", causality=Fmi2Causality.input, description="input"))
        self.register_variable(Real("y", causality=Fmi2Causality.output, description="output"))

    def exit_initialization_mode(self):
        self.y = self.y_start

    def do_step(self, current_time, step_size):
        target = self.K * self.u
        self.y = target + (self.y - target) * math.exp(-step_size / self.T)
        return True

    def to_xml(self, model_options=dict()):
        root = super().to_xml(model_options)
        for unknown in root.find("ModelStructure").find("Outputs"):
            unknown.set("dependencies", "")  # y is a state: no direct feedthrough from u
        return root
