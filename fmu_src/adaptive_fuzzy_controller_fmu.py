"""AdaptiveFuzzyController: the variable-universe direct adaptive fuzzy controller as an FMU.

Pan, Er, Huang, Wang, IEEE Trans. Fuzzy Systems 19(5), 2011; docs/model.md sections 1-6 (the controller)
and section 11 (co-simulation semantics).
The math is in ``afc_math``; this class only adapts it to FMI.

Co-simulation semantics:
* u (and E, dE, alpha1, alpha2) depend directly on the inputs at the same
  communication point: after the master sets e, de, ym, dym, reading u
  gives u for those inputs (computed on demand, no one-step delay).
* doStep(t, h) advances theta (and w_hat for variant 3) over the step with
  the inputs held at their values at t: the sampled-data update
  ``theta += h * dtheta(t)`` (explicit Euler) that an embedded target runs.
* e(0), de(0), ..., e^(n-1)(0) of the modified error (Remark 3, (36)) and
  its time origin come from the inputs, robust to hosts that hand
  placeholders at initialisation (``initial_error_latch``,
  docs/host_robustness.md), or from parameters.
* The controller watches its own u for chatter (``chatter_monitor``) and
  warns once, naming the step and the remedies.
* The robust cures (docs/model.md section 14 (robust cures)), each off at 0: a floor
  alpha_min on alpha (in ``afc_math.controller_output``), a dead zone and sigma-modification
  in the adaptive law (``step``), a first-order filter on the error inputs
  (``compute_outputs``, committed in ``step``).
* order n and sets m (Integer parameters, appended to the table) make it the
  controller of an nth-order plant with m fuzzy sets per input: wire e, de,
  ..., e^(n-1) (and ym, ..., ym^(n-1) for fls_input = 2); M = m^n rule
  weights theta1..thetaM; docs/general_order.md.
"""
import math
from operator import itemgetter

from fmu_src import afc_math, chatter_monitor
from fmu_src import initial_error_latch as latch_rule
from pythonfmu import DefaultExperiment
# pythonfmu's C loader finds the model class by the pattern "class X(Fmi2Slave):",
# so the project's base class is imported under that name.
from fmu_src.afc_declaration import Derivative, ModelExchange, TestDrive
from fmu_src.afc_slave_base import INPUT, OUTPUT, PARAMETER, Tuning, Variable, finite, non_negative, positive
from fmu_src.afc_slave_base import TableSlave as Fmi2Slave

_INF = math.inf
# u depends on every error and reference input: n is a parameter (ym.. with fls_input = 2)
FEEDTHROUGH = ("e", "de", "ym", "dym", "d2e", "d3e", "d2ym", "d3ym")
INITIAL_ERROR_PARAMETERS = ("e0", "de0", "d2e0", "d3e0")  # pinned x(0), first n used
THETA_INITIAL = ("theta0", "order", "sets")  # theta_j(0) = theta0 for j <= sets^order, else 0
INITIAL_ERROR_FROM_INPUTS = 1
INITIAL_ERROR_PINNED = 2

# Search ranges of `python -m harness tune` (docs/tuning.md): wide enough to hold the paper's values
# for the pendulum and the manipulator and the motor arm's, log-scaled where they span decades.
# Declaration only: nothing of them reaches modelDescription.xml or the C tables.
VUD_ONLY = (1,)  # alpha_i = 1 in variants 2 and 3: lambda_ce and kappa_i act in vud only
FAE_ONLY = (3,)  # w_hat exists in variant 3 only
K_RANGE = dict(low=0.05, high=50.0)  # k1, k2: > 0 is Hurwitz for n = 2
HURWITZ_FRACTION = dict(low=0.01, high=0.99, scale="hurwitz")  # k3, k4: a fraction of the Routh bound
Q_RANGE = dict(low=0.1, high=1000.0)
KAPPA_RANGE = dict(low=0.1, high=1000.0, variants=VUD_ONLY)
UNIVERSE_RANGE = dict(low=0.05, high=20.0)

VARIABLES = (
    Variable("variant", PARAMETER, 1, kind="Integer", minimum=1, maximum=3,
             description="1 = vud (variable universes, proposed), 2 = fixed universes, "
                         "3 = fixed universes + approximation-error estimator"),
    Variable("fls_input", PARAMETER, 1, kind="Integer", minimum=1, maximum=2,
             description="FLS input: 1 = modified error [E, dE], 2 = state [ym - e, dym - de]"),
    positive("k1", 2.0, description="Hurwitz gain k1 of s^2 + k1 s + k2", tuning=Tuning(**K_RANGE)),
    positive("k2", 1.0, description="Hurwitz gain k2 of s^2 + k1 s + k2", tuning=Tuning(**K_RANGE)),
    positive("q1", 10.0, description="Q = diag(q1, q2) of the Lyapunov equation (30)", tuning=Tuning(**Q_RANGE)),
    positive("q2", 10.0, description="Q = diag(q1, q2) of the Lyapunov equation (30)", tuning=Tuning(**Q_RANGE)),
    positive("gamma", 300.0, description="learning rate gamma of the adaptive law (31)", tuning=Tuning(1.0, 1e4)),
    positive("gamma_w", 300.0, description="learning rate of w_hat (variant 3)",
             tuning=Tuning(1.0, 1e4, variants=FAE_ONLY)),
    positive("m_theta", 200.0, description="projection bound M_theta (31)", tuning=Tuning(1.0, 1e4)),
    positive("delta", 5.0, description="projection boundary layer delta (31)", tuning=Tuning(0.01, 100.0)),
    non_negative("lambda_e", 5.0, "1/s", "decay rate of the modified error (Remark 3); 0 = off",
                 tuning=Tuning(0.1, 100.0)),
    Variable("lambda_ce", PARAMETER, 0.99, description="contraction-expansion depth lambda (23)",
             minimum=0.0, maximum=1.0, exclusive_minimum=True, exclusive_maximum=True,
             tuning=Tuning(0.5, 0.9999, "log1m", variants=VUD_ONLY)),
    positive("kappa1", 10.0, description="contraction-expansion width kappa_1 (23)", tuning=Tuning(**KAPPA_RANGE)),
    positive("kappa2", 10.0, description="contraction-expansion width kappa_2 (23)", tuning=Tuning(**KAPPA_RANGE)),
    positive("mf_slope", 7.0, description="slope s of the sigmoid membership functions", tuning=Tuning(0.5, 50.0)),
    positive("E1", math.pi / 3, description="universe [-E1, E1] of FLS input 1", tuning=Tuning(**UNIVERSE_RANGE)),
    positive("E2", math.pi / 3, description="universe [-E2, E2] of FLS input 2", tuning=Tuning(**UNIVERSE_RANGE)),
    finite("theta0", 0.0, description="initial value of every theta_j"),
    Variable("e", INPUT, 0.0, declared_type="PlantOutput", description="tracking error e = ym - y"),
    Variable("de", INPUT, 0.0, declared_type="PlantOutputRate", description="tracking error rate de = dym - dy"),
    Variable("ym", INPUT, 0.0, declared_type="PlantOutput", description="reference ym (used with fls_input = 2)"),
    Variable("dym", INPUT, 0.0, declared_type="PlantOutputRate", description="reference rate dym (used with fls_input = 2)"),
    Variable("u", OUTPUT, 0.0, declared_type="PlantInput", description="control input u = theta^T xi (+ w_hat) (9)",
             depends_on=FEEDTHROUGH),
    Variable("E", OUTPUT, 0.0, declared_type="PlantOutput", description="modified tracking error E (Remark 3)", depends_on=("e", "de")),
    Variable("dE", OUTPUT, 0.0, declared_type="PlantOutputRate", description="its time derivative dE", depends_on=("e", "de")),
    Variable("alpha1", OUTPUT, 1.0, description="contraction-expansion factor of input 1 (23)",
             depends_on=("e", "de", "ym", "dym")),
    Variable("alpha2", OUTPUT, 1.0, description="contraction-expansion factor of input 2 (23)",
             depends_on=("e", "de", "ym", "dym")),
    Variable("theta1", OUTPUT, 0.0, description="rule weight theta_1 (rule (1,1))", initial_depends_on=THETA_INITIAL),
    Variable("theta2", OUTPUT, 0.0, description="rule weight theta_2 (rule (1,2))", initial_depends_on=THETA_INITIAL),
    Variable("theta3", OUTPUT, 0.0, description="rule weight theta_3 (rule (2,1))", initial_depends_on=THETA_INITIAL),
    Variable("theta4", OUTPUT, 0.0, description="rule weight theta_4 (rule (2,2))", initial_depends_on=THETA_INITIAL),
    Variable("w_hat", OUTPUT, 0.0, declared_type="PlantInput", description="approximation-error estimate (variant 3; else 0)",
             initial_depends_on=()),  # w_hat(0) = 0
    # appended rows (value references are table order: never reorder)
    Variable("initial_error", PARAMETER, INITIAL_ERROR_FROM_INPUTS, kind="Integer", minimum=1, maximum=2,
             description="e(0), de(0) of the modified error: 1 = from the inputs, checked over the first "
                         "doSteps (host-robust, docs/host_robustness.md); 2 = pinned by e0, de0, ..."),
    finite("e0", 0.0, description="pinned e(0) (initial_error = 2)"),
    finite("de0", 0.0, description="pinned de(0) (initial_error = 2)"),
    finite("d2e0", 0.0, description="pinned d2e(0) (initial_error = 2, plant order n >= 3)"),
    finite("d3e0", 0.0, description="pinned d3e(0) (initial_error = 2, plant order n = 4)"),
    # ---- the general controller (order n, m sets per input): appended rows, so the value
    # references above keep their numbers; entries beyond n are unused but validated
    Variable("order", PARAMETER, 2, kind="Integer", minimum=1, maximum=afc_math.ORDER_MAX,
             description="plant order n: FLS inputs [E, dE, ..., E^(n-1)], M = sets^order rules"),
    Variable("sets", PARAMETER, 2, kind="Integer", minimum=2, maximum=afc_math.SETS_MAX,
             description=f"fuzzy sets m per FLS input (sets^order <= {afc_math.RULES_MAX})"),
    positive("k3", 0.5, description="Hurwitz gain k3 of s^n + k1 s^(n-1) + ... + kn (n >= 3); "
                                    "0.5 keeps s^3 + 2 s^2 + s + 0.5 Hurwitz with the default k1, k2",
             tuning=Tuning(**HURWITZ_FRACTION, order=3)),
    positive("k4", 0.1, description="Hurwitz gain k4 (n = 4); 0.1 keeps s^4 + 2 s^3 + s^2 + 0.5 s + 0.1 "
                                    "Hurwitz with the default k1..k3",
             tuning=Tuning(**HURWITZ_FRACTION, order=4)),
    positive("q3", 10.0, description="Q = diag(q1, ..., qn) of (30) (n >= 3); 10 as q1, q2",
             tuning=Tuning(**Q_RANGE, order=3)),
    positive("q4", 10.0, description="Q = diag(q1, ..., qn) of (30) (n = 4); 10 as q1, q2",
             tuning=Tuning(**Q_RANGE, order=4)),
    positive("kappa3", 10.0, description="contraction-expansion width kappa_3 (23) (n >= 3); 10 as kappa1, 2",
             tuning=Tuning(**KAPPA_RANGE, order=3)),
    positive("kappa4", 10.0, description="contraction-expansion width kappa_4 (23) (n = 4); 10 as kappa1, 2",
             tuning=Tuning(**KAPPA_RANGE, order=4)),
    positive("E3", math.pi / 3, description="universe [-E3, E3] of FLS input 3 (n >= 3); as E1, E2",
             tuning=Tuning(**UNIVERSE_RANGE, order=3)),
    positive("E4", math.pi / 3, description="universe [-E4, E4] of FLS input 4 (n = 4); as E1, E2",
             tuning=Tuning(**UNIVERSE_RANGE, order=4)),
    Variable("d2e", INPUT, 0.0, declared_type="PlantOutputAcceleration", description="tracking error acceleration d2e = d2ym - d2y (n >= 3)"),
    Variable("d3e", INPUT, 0.0, declared_type="PlantOutputJerk", description="third derivative of the tracking error d3e (n = 4)"),
    Variable("d2ym", INPUT, 0.0, declared_type="PlantOutputAcceleration", description="reference acceleration d2ym (fls_input = 2, n >= 3)"),
    Variable("d3ym", INPUT, 0.0, declared_type="PlantOutputJerk", description="third derivative of the reference d3ym (fls_input = 2, n = 4)"),
    Variable("d2E", OUTPUT, 0.0, declared_type="PlantOutputAcceleration", description="second derivative of the modified error (36) (n >= 3; else 0)",
             depends_on=("d2e",)),
    Variable("d3E", OUTPUT, 0.0, declared_type="PlantOutputJerk", description="third derivative of the modified error (36) (n = 4; else 0)",
             depends_on=("d3e",)),
    Variable("alpha3", OUTPUT, 1.0, description="contraction-expansion factor of input 3 (23) (n >= 3; else 1)",
             depends_on=("d2e", "d2ym")),
    Variable("alpha4", OUTPUT, 1.0, description="contraction-expansion factor of input 4 (23) (n = 4; else 1)",
             depends_on=("d3e", "d3ym")),
    *(Variable(f"theta{j}", OUTPUT, 0.0, description=f"rule weight theta_{j} (0 when {j} > sets^order)",
               initial_depends_on=THETA_INITIAL) for j in range(5, afc_math.RULES_MAX + 1)),
    # ---- the robust cures (docs/model.md section 14 (robust cures)): appended rows, each off at its start value 0
    Variable("alpha_min", PARAMETER, 0.0, minimum=0.0, maximum=1.0,
             description="floor on the contraction-expansion factor: alpha_i = max(alpha_i(x_i), alpha_min) (23a), "
                         "so 1 / alpha <= 1 / alpha_min (vud only); 0 = off, 1 = fixed universes"),
    non_negative("dead_zone", 0.0, "", "half-width d0 of the dead zone of the adaptive law: no adaptation of "
                                       "theta (and w_hat) while |tau| <= d0, tau = E^T P B (31a); 0 = off"),
    non_negative("sigma", 0.0, "1/s", "sigma-modification: the leakage -sigma theta_j added to dtheta_j "
                                      "(and -sigma w_hat to dw_hat) (31b); 0 = off"),
    non_negative("filter_time_constant", 0.0, "s", "T_m of the first-order filter on the error inputs e, de, ... "
                                                   "(F1), co-simulation only; 0 = off"),
)
ERROR_INPUTS = ("e", "de", "d2e", "d3e")  # e^(i), i = 0..3
# the measurement filter's state (F1): [started (0 or 1), time of the committed sample, f_0 .. f_(n-1)]
FILTER_STARTED, FILTER_TIME, FILTER_VALUES = 0, 1, 2
REFERENCE_INPUTS = ("ym", "dym", "d2ym", "d3ym")
ERROR_OUTPUTS = ("E", "dE", "d2E", "d3E")
ALPHA_OUTPUTS = ("alpha1", "alpha2", "alpha3", "alpha4")
THETA_OUTPUTS = tuple(f"theta{j}" for j in range(1, afc_math.RULES_MAX + 1))


def _model_exchange(table) -> ModelExchange:
    """theta1..thetaN (N = the table's rule weights) and w_hat: dtheta_j = gamma tau xi_j with the
    projection (31), dw_hat = gamma_w tau (variant 3; else 0); tau and xi depend on every input."""
    inputs = tuple((v.name, "dependent") for v in table if v.causality == INPUT)
    parameters = tuple(v.name for v in table if v.causality == PARAMETER)
    thetas = [v.name for v in table if v.causality == OUTPUT and v.name.startswith("theta") and v.name[5:].isdigit()]
    derivatives = tuple(Derivative(name, ((name, "dependent"), *inputs), parameters,
                                   f"d{name} of the adaptive law with projection (31)") for name in thetas)
    derivatives += (Derivative("w_hat", inputs, parameters, "dw_hat = gamma_w tau (variant 3; else 0)"),)
    return ModelExchange(derivatives=derivatives,
                         output_states=(("u", (*((name, "dependent") for name in thetas), ("w_hat", "fixed"))),))


def _test_inputs(t):
    return dict(e=0.3 * math.cos(3 * t), de=-0.9 * math.sin(3 * t), ym=0.2 * math.sin(t), dym=0.2 * math.cos(t))


# beside the table (fmu_src/afc_declaration.py), built when asked: pythonfmu runs this script again at
# every instantiate
def model_exchange() -> ModelExchange:
    """The Model Exchange interface of the native edition (docs/model_exchange.md)."""
    return _model_exchange(VARIABLES)


def test_drive() -> TestDrive:
    """How the tests drive this FMU."""
    return TestDrive(dict(variant=3), _test_inputs, 1e-3)

def _vector_getter(names):
    """d -> (d[names[0]], ...) as a tuple, also for one name."""
    if len(names) == 1:
        return lambda attributes, name=names[0]: (attributes[name],)
    return itemgetter(*names)



class AdaptiveFuzzyController(Fmi2Slave):
    VARIABLES = VARIABLES
    STATE_ATTRIBUTES = ("latch", "chatter", "theta", "xi", "modified", "filter")
    MODEL_DESCRIPTION = ("Direct adaptive fuzzy controller with variable universes of discourse "
                         "(Pan, Er, Huang, Wang, IEEE TFS 2011)")

    # A step at which a host that delays every link one step (Jacobi) gets ITAE, IAE, Ec within 1 % on the
    # three pendulum scenarios: the smallest Jacobi validated step of docs/convergence.md (the manipulator
    # needs its own, smaller one: docs/hosts.md). The tolerance: the relative tolerance a Model Exchange
    # host's solver needs for u within 0.1 % of the converged co-simulation (docs/model_exchange.md);
    # co-simulation ignores it
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=20.0, step_size=6.4e-5, tolerance=1e-9)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.latch = [0.0] * latch_rule.size(2)
        self.chatter = chatter_monitor.new_state()
        self.theta = [0.0] * afc_math.RULE_COUNT
        self.xi = (0.25, 0.25, 0.25, 0.25)
        self.modified = (0.0, 0.0)
        self.filter = [0.0] * (FILTER_VALUES + 2)  # the measurement filter (F1), FILTER_* layout
        self._p = None

    def cross_parameter_errors(self):
        n, m = self.order, self.sets
        if m ** n > afc_math.RULES_MAX:
            return [f"parameters order = {n}, sets = {m} give m^n = {m ** n} rules, above the bound "
                    f"{afc_math.RULES_MAX}; valid: sets^order <= {afc_math.RULES_MAX} "
                    f"(every sets 2..{afc_math.SETS_MAX} up to order 3, sets <= 3 at order 4)"]
        k = tuple(getattr(self, f"k{i}") for i in range(1, n + 1))
        q = tuple(getattr(self, f"q{i}") for i in range(1, n + 1))
        try:
            hurwitz = afc_math.is_positive_definite(afc_math.lyapunov_p(k, q))
        except ValueError:
            hurwitz = False
        if not hurwitz:
            polynomial = " + ".join([f"s^{n}"] + [f"{k[i - 1]!r} s^{n - i}" if n - i else f"{k[i - 1]!r}"
                                                  for i in range(1, n + 1)])
            return [f"parameters k1..k{n} = {k!r} are invalid for order = {n}: {polynomial} is not Hurwitz "
                    "(no positive definite P in (30)); valid: k with every root of the polynomial in the "
                    f"left half-plane, e.g. the coefficients of (s + 1)^{n}"]
        return []

    def _configure(self):
        """The constants of the per-step path (afc_math.controller_parameters, P B, boundaries,
        the inputs and outputs in use) from the current parameters."""
        n = self.order
        self._p = afc_math.controller_parameters(
            {v.name: getattr(self, v.name) for v in VARIABLES if v.causality == PARAMETER})
        self._error_inputs = ERROR_INPUTS[:n]
        self._error_vector = _vector_getter(ERROR_INPUTS[:n])
        self._reference_vector = _vector_getter(REFERENCE_INPUTS[:n])
        self._error_outputs = ERROR_OUTPUTS[:n]
        self._alpha_outputs = ALPHA_OUTPUTS[:n]
        self._theta_outputs = THETA_OUTPUTS[:self._p["rules"]]
        self._p_b = self._p["p_b"]
        self._default_shape = n == 2 and self.sets == 2
        self._filtered = self.filter_time_constant > 0.0  # the cures (F1), (31a), (31b): off at 0
        self._dead_zone = self.dead_zone > 0.0
        self._leaky = self.sigma > 0.0

    def _latch_initial_error(self):
        """e(t0), de(t0), ..., e^(n-1)(t0) and t0 of the modified error (36), from the latch rule's state."""
        afc_math.latch_error(self._p, latch_rule.latched(self.latch), self.latch[latch_rule.ORIGIN])

    def initialize(self, start_time):
        self._configure()
        n = self.order
        self.latch = [0.0] * latch_rule.size(n)  # n = the error vector's length
        if self.initial_error == INITIAL_ERROR_PINNED:
            latch_rule.pin(self.latch, start_time, [getattr(self, name) for name in INITIAL_ERROR_PARAMETERS])
        else:  # tentative: checked over the first doSteps (Remark 3, initial_error_latch)
            latch_rule.start(self.latch, start_time, self._error_vector(self.__dict__))
        self._latch_initial_error()
        chatter_monitor.start(self.chatter)
        self.filter = [0.0] * (FILTER_VALUES + n)  # not started: the first sample passes (F1)
        rules = self._p["rules"]
        attributes = self.__dict__
        attributes.update(dict.fromkeys(THETA_OUTPUTS[rules:], 0.0))
        attributes.update(dict.fromkeys(ERROR_OUTPUTS[n:], 0.0))
        attributes.update(dict.fromkeys(ALPHA_OUTPUTS[n:], 1.0))
        self.restart_adaptation()

    def restart_adaptation(self):
        self.theta = [float(self.theta0)] * self._p["rules"]
        self.__dict__.update(zip(self._theta_outputs, self.theta))
        self.w_hat = 0.0

    def watch_initial_error(self, time):
        """Let the latch rule see this doStep's inputs; restart on a re-latch, warn once."""
        events = latch_rule.observe(self.latch, time, self._error_vector(self.__dict__))
        if events & latch_rule.RELATCHED:
            self._latch_initial_error()
            self.restart_adaptation()
            self.filter[FILTER_STARTED] = 0.0  # the filter restarts at rest on the re-latched sample (F1)
            self.compute_outputs()  # E, dE, xi of this step from the new latch
        if events & latch_rule.DECIDED:
            message = latch_rule.warning(self.latch, self._error_inputs)
            if message:
                self.warn(message)

    def _set_fmu_state(self, state):
        super()._set_fmu_state(state)
        if self.initialized:  # the constants follow the restored parameters and latch
            self._configure()
            self._latch_initial_error()

    def compute_outputs(self):
        attributes = self.__dict__
        error = self._error_vector(attributes)
        if self._filtered:
            error = self._filtered_error = self._filter_error(error)
        reference = self._reference_vector(attributes)
        u, modified, alpha, xi = afc_math.controller_output(error, reference, self.time, self.theta,
                                                            self.w_hat, self._p)
        if not -_INF < u + sum(modified) < _INF:  # u or some E^(i) is NaN or inf (or all overflow together)
            self._overflow(u, modified, error)
        self.u = u
        if self._default_shape:  # n = 2, m = 2 unrolled: the per-step path
            self.E, self.dE = modified
            self.alpha1, self.alpha2 = alpha
        else:
            attributes.update(zip(self._error_outputs, modified))
            attributes.update(zip(self._alpha_outputs, alpha))
        self.modified = modified
        self.xi = xi  # a tuple; the FMU state stores it as a list
        self.outputs_stale = False

    def _filter_error(self, sample) -> tuple:
        """The filtered error inputs at this time (F1): the committed filter state advanced by the time
        since its sample; before the first doStep (not started) the sample itself."""
        state = self.filter
        if not state[FILTER_STARTED]:
            return tuple(sample)
        gain = afc_math.measurement_filter_gain(self.time - state[FILTER_TIME], self.filter_time_constant)
        return afc_math.filtered_measurements(state[FILTER_VALUES:], sample, gain)

    def _overflow(self, u, modified, error):
        self.fail(f"outputs overflow at t = {self.time!r}: u = {u!r}, E = {modified!r} from "
                  f"{', '.join(f'{name} = {value!r}' for name, value in zip(self._error_inputs, error))} "
                  f"(latched at t0 = {self.latch[latch_rule.ORIGIN]!r}: {latch_rule.latched(self.latch)!r}); "
                  "the inputs are out of range or the closed loop diverged")

    def step(self, current_time, step_size):
        if self.latch[latch_rule.OPEN]:  # the first few doSteps only
            self.watch_initial_error(current_time)
        tau = afc_math.adaptation_signal(self.modified, self._p_b)
        if self._dead_zone:
            tau = afc_math.dead_zone_signal(tau, self.dead_zone)  # (31a)
        if self._leaky:
            theta, w_hat = self._leaky_step(tau, step_size)  # (31b)
        else:
            theta = afc_math.adapted_weights(self.theta, tau, self.xi, self.gamma, self.m_theta, self.delta,
                                             step_size)
            w_hat = self.w_hat
            if self.variant == afc_math.VARIANT_FAE:
                w_hat += step_size * self.gamma_w * tau
        if not -_INF < w_hat + sum(theta) < _INF:  # some theta or w_hat is NaN or inf (or all overflow together)
            self.fail(f"adaptation diverged in doStep(t={current_time!r}, h={step_size!r}): tau = {tau!r} "
                      f"from E = {self.modified!r}; theta and w_hat keep their values at t; "
                      "the inputs are out of range or the closed loop diverged")
        self.theta = theta
        if self._default_shape:  # n = 2, m = 2 unrolled: the per-step path
            self.theta1, self.theta2, self.theta3, self.theta4 = theta
        else:
            self.__dict__.update(zip(self._theta_outputs, theta))
        self.w_hat = w_hat
        if self._filtered:  # commit the filter's sample at t (F1)
            self.filter = [1.0, current_time, *self._filtered_error]
        if chatter_monitor.update(self.chatter, self.u, step_size):
            self.warn(chatter_monitor.warning(self.chatter, step_size))
        return True

    def _leaky_step(self, tau, step_size):
        """theta and w_hat after one step of the law with sigma-modification (31b)."""
        rates = afc_math.adaptation_rates(self.theta, tau, self.xi, self.gamma, self.m_theta, self.delta)
        theta = afc_math.leaky_weights(self.theta, rates, self.sigma, step_size)
        w_hat = self.w_hat
        if self.variant == afc_math.VARIANT_FAE:
            w_hat += step_size * (afc_math.estimate_rate(tau, self.gamma_w) - self.sigma * w_hat)
        return theta, w_hat
