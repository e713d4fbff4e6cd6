"""AdaptiveFuzzyController: the variable-universe direct adaptive fuzzy controller as an FMU.

Pan, Er, Huang, Wang, IEEE Trans. Fuzzy Systems 19(5), 2011; SPEC.md sections 1-5, 9.
The math is in ``afc_math``; this class only adapts it to FMI.

Co-simulation semantics:
* u (and E, dE, alpha1, alpha2) depend directly on the inputs at the same
  communication point: after the master sets e, de, ym, dym, reading u
  gives u for those inputs (computed on demand, no one-step delay).
* doStep(t, h) advances theta (and w_hat for variant 3) over the step with
  the inputs held at their values at t: the sampled-data update
  ``theta += h * dtheta(t)`` (explicit Euler) that an embedded target runs.
* e(0), de(0) of the modified error (Remark 3) and its time origin come from
  the inputs, robust to hosts that hand placeholders at initialisation
  (``initial_error_latch``, docs/host_robustness.md), or from parameters.
* The controller watches its own u for chatter (``chatter_monitor``) and
  warns once, naming the step and the remedy.
"""
import math

import afc_math
import chatter_monitor
import initial_error_latch as latch_rule
# pythonfmu's C loader finds the model class by the pattern "class X(Fmi2Slave):",
# so the project's base class is imported under that name.
from afc_slave_base import INPUT, OUTPUT, PARAMETER, Variable, finite, non_negative, positive
from afc_slave_base import TableSlave as Fmi2Slave

DIMENSIONLESS = ""
_INF = math.inf
FEEDTHROUGH = ("e", "de", "ym", "dym")
ERROR_INPUTS = ("e", "de")  # the error vector [e, de, ...] of the plant's order n
INITIAL_ERROR_PARAMETERS = ("e0", "de0", "d2e0", "d3e0")  # pinned x(0), first n used
INITIAL_ERROR_FROM_INPUTS = 1
INITIAL_ERROR_PINNED = 2

VARIABLES = (
    Variable("variant", PARAMETER, 1, kind="Integer", minimum=1, maximum=3,
             description="1 = vud (variable universes, proposed), 2 = fixed universes, "
                         "3 = fixed universes + approximation-error estimator"),
    Variable("fls_input", PARAMETER, 1, kind="Integer", minimum=1, maximum=2,
             description="FLS input: 1 = modified error [E, dE], 2 = state [ym - e, dym - de]"),
    positive("k1", 2.0, description="Hurwitz gain k1 of s^2 + k1 s + k2"),
    positive("k2", 1.0, description="Hurwitz gain k2 of s^2 + k1 s + k2"),
    positive("q1", 10.0, description="Q = diag(q1, q2) of the Lyapunov equation (30)"),
    positive("q2", 10.0, description="Q = diag(q1, q2) of the Lyapunov equation (30)"),
    positive("gamma", 300.0, description="learning rate gamma of the adaptive law (31)"),
    positive("gamma_w", 300.0, description="learning rate of w_hat (variant 3)"),
    positive("m_theta", 200.0, description="projection bound M_theta (31)"),
    positive("delta", 5.0, description="projection boundary layer delta (31)"),
    non_negative("lambda_e", 5.0, "1/s", "decay rate of the modified error (Remark 3); 0 = off"),
    Variable("lambda_ce", PARAMETER, 0.99, description="contraction-expansion depth lambda (23)",
             minimum=0.0, maximum=1.0, exclusive_minimum=True, exclusive_maximum=True),
    positive("kappa1", 10.0, description="contraction-expansion width kappa_1 (23)"),
    positive("kappa2", 10.0, description="contraction-expansion width kappa_2 (23)"),
    positive("mf_slope", 7.0, description="slope s of the sigmoid membership functions"),
    positive("E1", math.pi / 3, description="universe [-E1, E1] of FLS input 1"),
    positive("E2", math.pi / 3, description="universe [-E2, E2] of FLS input 2"),
    finite("theta0", 0.0, description="initial value of every theta_j"),
    Variable("e", INPUT, 0.0, description="tracking error e = ym - y"),
    Variable("de", INPUT, 0.0, description="tracking error rate de = dym - dy"),
    Variable("ym", INPUT, 0.0, description="reference ym (used with fls_input = 2)"),
    Variable("dym", INPUT, 0.0, description="reference rate dym (used with fls_input = 2)"),
    Variable("u", OUTPUT, 0.0, description="control input u = theta^T xi (+ w_hat) (9)",
             depends_on=FEEDTHROUGH),
    Variable("E", OUTPUT, 0.0, description="modified tracking error E (Remark 3)", depends_on=("e", "de")),
    Variable("dE", OUTPUT, 0.0, description="its time derivative dE", depends_on=("e", "de")),
    Variable("alpha1", OUTPUT, 1.0, description="contraction-expansion factor of input 1 (23)",
             depends_on=FEEDTHROUGH),
    Variable("alpha2", OUTPUT, 1.0, description="contraction-expansion factor of input 2 (23)",
             depends_on=FEEDTHROUGH),
    Variable("theta1", OUTPUT, 0.0, description="rule weight theta_1 (rule (1,1))"),
    Variable("theta2", OUTPUT, 0.0, description="rule weight theta_2 (rule (1,2))"),
    Variable("theta3", OUTPUT, 0.0, description="rule weight theta_3 (rule (2,1))"),
    Variable("theta4", OUTPUT, 0.0, description="rule weight theta_4 (rule (2,2))"),
    Variable("w_hat", OUTPUT, 0.0, description="approximation-error estimate (variant 3; else 0)"),
    # appended rows (value references are table order: never reorder)
    Variable("initial_error", PARAMETER, INITIAL_ERROR_FROM_INPUTS, kind="Integer", minimum=1, maximum=2,
             description="e(0), de(0) of the modified error: 1 = from the inputs, checked over the first "
                         "doSteps (host-robust, docs/host_robustness.md); 2 = pinned by e0, de0, ..."),
    finite("e0", 0.0, description="pinned e(0) (initial_error = 2)"),
    finite("de0", 0.0, description="pinned de(0) (initial_error = 2)"),
    finite("d2e0", 0.0, description="pinned d2e(0) (initial_error = 2, plant order n >= 3)"),
    finite("d3e0", 0.0, description="pinned d3e(0) (initial_error = 2, plant order n = 4)"),
)


class AdaptiveFuzzyController(Fmi2Slave):
    VARIABLES = VARIABLES
    STATE_ATTRIBUTES = ("latch", "chatter", "p12", "p22", "xi")
    MODEL_DESCRIPTION = ("Direct adaptive fuzzy controller with variable universes of discourse "
                         "(Pan, Er, Huang, Wang, IEEE TFS 2011)")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.latch = [0.0] * latch_rule.size(len(ERROR_INPUTS))
        self.chatter = chatter_monitor.new_state()
        self.p12 = self.p22 = 0.0
        self.xi = [0.25, 0.25, 0.25, 0.25]

    def initialize(self, start_time):
        _, self.p12, self.p22 = afc_math.lyapunov_p(self.k1, self.k2, self.q1, self.q2)
        self.latch = [0.0] * latch_rule.size(len(ERROR_INPUTS))  # n = the error vector's length
        if self.initial_error == INITIAL_ERROR_PINNED:
            latch_rule.pin(self.latch, start_time, [getattr(self, name) for name in INITIAL_ERROR_PARAMETERS])
        else:  # tentative: checked over the first doSteps (Remark 3, initial_error_latch)
            latch_rule.start(self.latch, start_time, [getattr(self, name) for name in ERROR_INPUTS])
        chatter_monitor.start(self.chatter)
        self.restart_adaptation()

    def restart_adaptation(self):
        self.theta1 = self.theta2 = self.theta3 = self.theta4 = float(self.theta0)
        self.w_hat = 0.0

    def watch_initial_error(self, time):
        """Let the latch rule see this doStep's inputs; restart on a re-latch, warn once."""
        events = latch_rule.observe(self.latch, time, [getattr(self, name) for name in ERROR_INPUTS])
        if events & latch_rule.RELATCHED:
            self.restart_adaptation()
            self.compute_outputs()  # E, dE, xi of this step from the new latch
        if events & latch_rule.DECIDED:
            message = latch_rule.warning(self.latch, ERROR_INPUTS)
            if message:
                self.warn(message)

    def compute_outputs(self):
        lambda_e = self.lambda_e
        e, de = self.e, self.de
        latch = self.latch  # x(t0) and t0 (initial_error_latch)
        error, error_rate = afc_math.modified_error(
            e, de, self.time - latch[latch_rule.ORIGIN], latch[latch_rule.LATCHED], latch[latch_rule.LATCHED + 1],
            lambda_e)
        x1, x2 = afc_math.fls_inputs(e, de, self.ym, self.dym, error, error_rate, self.fls_input)
        variant = self.variant
        if variant == afc_math.VARIANT_VUD:
            alpha1 = afc_math.contraction_factor(x1, self.lambda_ce, self.kappa1)
            alpha2 = afc_math.contraction_factor(x2, self.lambda_ce, self.kappa2)
        else:
            alpha1 = alpha2 = 1.0
        xi = afc_math.fuzzy_basis(afc_math.normalized_input(x1, alpha1, self.E1),
                                  afc_math.normalized_input(x2, alpha2, self.E2), self.mf_slope)
        u = self.theta1 * xi[0] + self.theta2 * xi[1] + self.theta3 * xi[2] + self.theta4 * xi[3]
        if variant == afc_math.VARIANT_FAE:
            u += self.w_hat
        if not (-_INF < u < _INF and -_INF < error < _INF and -_INF < error_rate < _INF):  # also NaN
            self.fail(f"outputs overflow at t = {self.time!r}: u = {u!r}, E = {error!r}, dE = {error_rate!r} "
                      f"from e = {e!r}, de = {de!r} (latched e(0), de(0) = {latch_rule.latched(latch)!r}); "
                      "the inputs are out of range or the closed loop diverged")
        self.u, self.E, self.dE, self.alpha1, self.alpha2 = u, error, error_rate, alpha1, alpha2
        self.xi = xi  # a tuple; the FMU state stores it as a list
        self.outputs_stale = False

    def step(self, current_time, step_size):
        if self.latch[latch_rule.OPEN]:  # the first few doSteps only
            self.watch_initial_error(current_time)
        tau = afc_math.adaptation_signal(self.E, self.dE, self.p12, self.p22)
        gamma, m_theta, delta = self.gamma, self.m_theta, self.delta
        rate = afc_math.projected_rate
        xi = self.xi
        theta1 = self.theta1 + step_size * rate(self.theta1, tau, xi[0], gamma, m_theta, delta)
        theta2 = self.theta2 + step_size * rate(self.theta2, tau, xi[1], gamma, m_theta, delta)
        theta3 = self.theta3 + step_size * rate(self.theta3, tau, xi[2], gamma, m_theta, delta)
        theta4 = self.theta4 + step_size * rate(self.theta4, tau, xi[3], gamma, m_theta, delta)
        w_hat = self.w_hat
        if self.variant == afc_math.VARIANT_FAE:
            w_hat += step_size * self.gamma_w * tau
        if not (-_INF < theta1 < _INF and -_INF < theta2 < _INF and -_INF < theta3 < _INF
                and -_INF < theta4 < _INF and -_INF < w_hat < _INF):  # also False for NaN
            self.fail(f"adaptation diverged in doStep(t={current_time!r}, h={step_size!r}): tau = {tau!r} "
                      f"from E = {self.E!r}, dE = {self.dE!r}; theta and w_hat keep their values at t; "
                      "the inputs are out of range or the closed loop diverged")
        self.theta1, self.theta2, self.theta3, self.theta4, self.w_hat = theta1, theta2, theta3, theta4, w_hat
        if chatter_monitor.update(self.chatter, self.u, step_size):
            self.warn(chatter_monitor.warning(self.chatter, step_size))
        return True
