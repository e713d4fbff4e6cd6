/* AdaptiveFuzzyController: the variable-universe direct adaptive fuzzy controller of
 * Pan, Er, Huang, Wang (IEEE TFS 19(5), 2011) as a native FMU: the C twin of
 * adaptive_fuzzy_controller_fmu.py.  The math is in afc_math.c; this file only adapts
 * it to the FMI layer.
 *
 * Co-simulation semantics (as the Python edition):
 * - u, E, dE, alpha depend directly on the inputs at the same communication point;
 * - doStep(t, h) advances theta (and w_hat for variant 3) with the inputs held at t:
 *   theta += h dtheta(t) (explicit Euler, the sampled-data update of an embedded target);
 * - e(0), de(0), ... of the modified error (Remark 3) are latched when initialisation ends.
 *
 * Model exchange (docs/model_exchange.md): the continuous states are theta1..thetaN and w_hat,
 * their derivatives the adaptive law [31] (adaptation_rates, estimate_rate) at the host's time,
 * state and inputs; no events (the projection (31) and the saturation (7) are continuous); the
 * initial error is latched from the inputs at exitInitializationMode (and follows inputs the
 * host sets in event mode at the start time), with no check window and no chatter monitor
 * (both watch co-simulation's communication steps).
 *
 * General form (docs/general_order.md): the order n and the number of sets m come from the parameters
 * `order` and `sets` when the declaration table has them, else n = 2, m = 2; the rule
 * weights are the table's theta1..thetaN (M = m^n <= N).
 */
#include <math.h>
#include <stdio.h>

#include "afc_math.h"
#include "chatter_monitor.h"
#include "fmi_layer.h"
#include "initial_error_latch.h"

/* Host robustness (docs/host_robustness.md): with the table's parameter initial_error, e(0), de(0), ... and the
 * time origin of the modified error come from initial_error_latch (checked over the first
 * doSteps, or pinned by e0, de0, ...), and chatter_monitor watches u; without it, e(0), de(0)
 * are the inputs at the end of initialisation, for good. */
#ifdef VR_initial_error
#define HOST_ROBUST 1
#define INITIAL_ERROR_PINNED 2
#else
#define HOST_ROBUST 0
#endif

/* the internal state (STATE_ATTRIBUTES: latch, chatter, xi; the Python edition's _p) */
typedef struct {
    InitialErrorLatch latch;        /* x(t0) = e(0), de(0), ... and t0 (Remark 3) */
    ChatterMonitor chatter;         /* chatter statistic of u */
    ControllerParameters p;         /* the constants of the per-step path, P B, the latch's Remark 3 */
    double xi[MAX_RULES];           /* the basis (8) at the last output evaluation */
    /* the measurement filter (F1): committed sample [started, its time, f_0 .. f_(n-1)], and the
     * filtered errors of the last output evaluation (the Python edition's filter, _filtered_error) */
    double filter[2 + MAX_ORDER];
    double filtered[MAX_ORDER];
    int adapt_cures;                /* some cure of the adaptive law is on: dead_zone, sigma, filter_time_constant */
} ControllerState;

#define STATE(m) ((ControllerState *)(m)->internal)

const size_t MODEL_INTERNAL_BYTES = sizeof(ControllerState);

/* value references of e, de, d2e, d3e; ym, dym, ...; E, dE, ...  (those the table has) */
static const int ERROR_VR[] = {VR_e, VR_de,
#ifdef VR_d2e
                               VR_d2e,
#endif
#ifdef VR_d3e
                               VR_d3e,
#endif
};
static const int REFERENCE_VR[] = {VR_ym, VR_dym,
#ifdef VR_d2ym
                                   VR_d2ym,
#endif
#ifdef VR_d3ym
                                   VR_d3ym,
#endif
};
static const int MODIFIED_ERROR_VR[] = {VR_E, VR_dE,
#ifdef VR_d2E
                                        VR_d2E,
#endif
#ifdef VR_d3E
                                        VR_d3E,
#endif
};
#define SUPPORTED_ORDER ((int)(sizeof ERROR_VR / sizeof ERROR_VR[0]))
#if N_STATES != N_theta + 1
#error "the declaration's model exchange states must be theta1..thetaN and w_hat"
#endif
static const char *const ERROR_NAMES[] = {"e", "de", "d2e", "d3e"};
#if HOST_ROBUST
static const int PINNED_ERROR_VR[] = {VR_e0, VR_de0,
#ifdef VR_d2e0
                                      VR_d2e0,
#endif
#ifdef VR_d3e0
                                      VR_d3e0,
#endif
};
#endif

static int order_of(ModelInstance *m) {
#ifdef VR_order
    return (int)V(m, order);
#else
    (void)m;
    return 2;
#endif
}

static int sets_of(ModelInstance *m) {
#ifdef VR_sets
    return (int)V(m, sets);
#else
    (void)m;
    return 2;
#endif
}

static int rules_of(int n, int sets) {
    int rules = 1;
    for (int i = 0; i < n; i++) rules *= sets;
    return rules;
}

void model_construct(ModelInstance *m) {
    ControllerState *state = STATE(m);
    int rules = rules_of(2, 2);
    for (int j = 0; j < rules; j++) state->xi[j] = 1.0 / rules;
}

/* ---- the robust cures (docs/model.md section 14 (robust cures)): each off at 0, kept in these functions.
 * A table without their rows (an older declaration) gives 0: the paper's controller. */
#ifdef VR_alpha_min
#define CURE(m, name) V(m, name)
#else
#define CURE(m, name) 0.0
#endif
enum { FILTER_STARTED = 0, FILTER_TIME = 1, FILTER_VALUES = 2 };

/* the filtered error inputs at this time (F1), in place: the committed filter state advanced by the
 * time since its sample; before the first doStep (not started) the sample itself */
static void filter_errors(ModelInstance *m, int n, double e[]) {
    ControllerState *state = STATE(m);
    if (state->filter[FILTER_STARTED] != 0.0) {
        double gain = measurement_filter_gain(m->s->time - state->filter[FILTER_TIME], CURE(m, filter_time_constant));
        filtered_measurements(n, state->filter + FILTER_VALUES, e, gain, e);
    }
    for (int i = 0; i < n; i++) state->filtered[i] = e[i];
}

/* commit the filter's sample at t (F1), after a doStep's adaptation */
static void commit_filter(ModelInstance *m, int n, double time) {
    ControllerState *state = STATE(m);
    state->filter[FILTER_STARTED] = 1.0;
    state->filter[FILTER_TIME] = time;
    for (int i = 0; i < n; i++) state->filter[FILTER_VALUES + i] = state->filtered[i];
}

/* theta and w_hat after one step of the law with sigma-modification (31b) */
static void leaky_step(ModelInstance *m, double tau, double step_size, const double theta[], double adapted[],
                       double *w_hat) {
    ControllerState *state = STATE(m);
    const ControllerParameters *p = &state->p;
    double rates[MAX_RULES], sigma = CURE(m, sigma);
    adaptation_rates(p->rules, theta, tau, state->xi, V(m, gamma), V(m, m_theta), V(m, delta), rates);
    leaky_weights(p->rules, theta, rates, sigma, step_size, adapted);
    if (p->variant == VARIANT_FAE) *w_hat += step_size * (estimate_rate(tau, V(m, gamma_w)) - sigma * *w_hat);
}

/* Model Exchange refuses the measurement filter (F1): its state would be a continuous state the
 * declaration does not have; a host filters e, de in its own blocks (or the Sensor's filter).
 * A cross-parameter rule, so that in initialisation mode the outputs keep their start values */
static int filter_in_model_exchange_error(ModelInstance *m, char *message, size_t size) {
    if (m->model_exchange && CURE(m, filter_time_constant) > 0.0) {
        snprintf(message, size, "parameter filter_time_constant = %.17g is invalid in Model Exchange; valid there: 0 "
                 "(the measurement filter (F1) is co-simulation only: filter e, de in the host, or with the Sensor's "
                 "filter_time_constant)", CURE(m, filter_time_constant));
        return MODEL_ERROR;
    }
    return MODEL_OK;
}

/* cross_parameter_errors: the rule count within the table's rule weights and, for the
 * general controller, k Hurwitz (a positive definite P of (30)) */
int model_cross_parameter_errors(ModelInstance *m, char *message, size_t size) {
    int n = order_of(m), sets = sets_of(m);
    if (n < 1 || n > SUPPORTED_ORDER || N_k < n || N_q < n || N_kappa < n || N_E < n) {
        snprintf(message, size, "parameter order = %d is invalid; valid range: 1 .. %d", n, SUPPORTED_ORDER);
        return MODEL_ERROR;
    }
    if (rules_of(n, sets) > N_theta) {
        snprintf(message, size, "parameters order = %d, sets = %d give m^n = %d rules, above the bound %d; "
                 "valid: sets^order <= %d (every sets 2..5 up to order 3, sets <= 3 at order 4)",
                 n, sets, rules_of(n, sets), N_theta, N_theta);
        return MODEL_ERROR;
    }
    if (filter_in_model_exchange_error(m, message, size) != MODEL_OK) return MODEL_ERROR;
#ifdef VR_order
    double k[MAX_ORDER], q[MAX_ORDER], p[MAX_ORDER][MAX_ORDER];
    for (int i = 0; i < n; i++) {
        k[i] = m->s->values[VRS_k[i]];
        q[i] = m->s->values[VRS_q[i]];
    }
    if (lyapunov_p(n, k, q, p) != 0 || !is_positive_definite(n, (const double (*)[MAX_ORDER])p)) {
        /* k as a tuple, the polynomial s^n + k1 s^(n-1) + ... + kn */
        char tuple[256], polynomial[512];
        int written = snprintf(polynomial, sizeof polynomial, "s^%d", n);
        for (int i = 0; i < n && written >= 0 && (size_t)written < sizeof polynomial; i++) {
            if (n - 1 - i)
                written += snprintf(polynomial + written, sizeof polynomial - (size_t)written, " + %.17g s^%d", k[i],
                                    n - 1 - i);
            else
                written += snprintf(polynomial + written, sizeof polynomial - (size_t)written, " + %.17g", k[i]);
        }
        snprintf(message, size, "parameters k1..k%d = %s are invalid for order = %d: %s is not Hurwitz (no "
                 "positive definite P in (30)); valid: k with every root of the polynomial in the left "
                 "half-plane, e.g. the coefficients of (s + 1)^%d", n, numbers_text(tuple, sizeof tuple, k, n, "()"),
                 n, polynomial, n);
        return MODEL_ERROR;
    }
#endif
    return MODEL_OK;
}

static void restart_adaptation(ModelInstance *m) {
    int rules = rules_of(order_of(m), sets_of(m));
    for (int j = 0; j < N_theta; j++) m->s->values[VRS_theta[j]] = j < rules ? V(m, theta0) : 0.0;
    V(m, w_hat) = 0.0;
}

/* the constants of the per-step path from the parameters (the Python edition's _configure, which
 * calls afc_math.controller_parameters); returns -1 if (30) has no solution */
static int configure(ModelInstance *m) {
    ControllerParameters *p = &STATE(m)->p;
    const double *values = m->s->values;
    int n = order_of(m), sets = sets_of(m);
    double k[MAX_ORDER], q[MAX_ORDER], matrix[MAX_ORDER][MAX_ORDER];
    p->order = n;
    p->sets = sets;
    p->rules = rules_of(n, sets);
    p->variant = (int)V(m, variant);
    p->fls_input = (int)V(m, fls_input);
    p->lambda_e = V(m, lambda_e);
    p->lambda_ce = V(m, lambda_ce);
    p->mf_slope = V(m, mf_slope);
    p->alpha_min = CURE(m, alpha_min); /* [23a]; 0 = off */
    /* with the three off (the paper's law) a doStep tests this alone */
    STATE(m)->adapt_cures = CURE(m, dead_zone) > 0.0 || CURE(m, sigma) > 0.0 || CURE(m, filter_time_constant) > 0.0;
    for (int i = 0; i < n; i++) {
        k[i] = values[VRS_k[i]];
        q[i] = values[VRS_q[i]];
        p->kappa[i] = values[VRS_kappa[i]];
        p->universe[i] = values[VRS_E[i]];
        membership_boundaries(p->universe[i], sets, p->boundaries[i]);
    }
    if (lyapunov_p(n, k, q, matrix) != 0) return -1;
    for (int i = 0; i < n; i++) p->p_b[i] = matrix[i][n - 1];
    return 0;
}

/* e(t0), de(t0), ..., e^(n-1)(t0) and t0 of the modified error (36), from the latch rule's state */
static void latch_initial_error(ModelInstance *m) {
    ControllerState *state = STATE(m);
    latch_error(&state->p, state->latch.latched, state->latch.origin);
}

int model_initialize(ModelInstance *m, double start_time) {
    ControllerState *state = STATE(m);
    int n = order_of(m);
    double sample[MAX_ORDER];
    for (int i = 0; i < n; i++) sample[i] = m->s->values[ERROR_VR[i]];
    if (configure(m) != 0)
        return fmu_fail(m, "the Lyapunov equation (30) has no solution for these k: "
                        "s^n + k1 s^(n-1) + ... + kn must be Hurwitz");
    state->filter[FILTER_STARTED] = 0.0; /* not started: the first sample passes (F1) */
#if HOST_ROBUST
    if ((int)V(m, initial_error) == INITIAL_ERROR_PINNED) {
        double pinned[MAX_ORDER];
        for (int i = 0; i < n; i++) pinned[i] = m->s->values[PINNED_ERROR_VR[i]];
        latch_pin(&state->latch, n, start_time, pinned);
    } else if (m->model_exchange) { /* the inputs the host set for the initial state: for good */
        latch_pin(&state->latch, n, start_time, sample);
    } else { /* tentative: checked over the first doSteps (Remark 3, initial_error_latch) */
        latch_start(&state->latch, n, start_time, sample);
    }
    chatter_start(&state->chatter);
#else
    latch_pin(&state->latch, n, start_time, sample); /* latched once (Remark 3) */
#endif
    latch_initial_error(m);
    restart_adaptation(m);
    return MODEL_OK;
}

/* the outputs are not finite: the error names the time, u, E, the inputs and the latched x(t0) */
MESSAGE_PATH static int fail_outputs_overflow(ModelInstance *m, double u, const double error[], const double e[]) {
    const InitialErrorLatch *latch = &STATE(m)->latch;
    int n = STATE(m)->p.order;
    char modified[256], inputs[256], latched[256];
    size_t used = 0;
    inputs[0] = 0;
    for (int i = 0; i < n && used < sizeof inputs; i++)
        used += (size_t)snprintf(inputs + used, sizeof inputs - used, "%s%s = %.17g", i ? ", " : "", ERROR_NAMES[i],
                                 e[i]);
    return fmu_fail(m, "outputs overflow at t = %.17g: u = %.17g, E = %s from %s (latched at t0 = %.17g: %s); the "
                    "inputs are out of range or the closed loop diverged", m->s->time, u,
                    numbers_text(modified, sizeof modified, error, n, "()"), inputs, latch->origin,
                    numbers_text(latched, sizeof latched, latch->latched, n, "[]"));
}

/* n = 2 and m = 2, the paper's controller: the per-step path reads and writes its variables by name (the
 * Python edition's _default_shape), any other shape through the tables of value references */
static int default_shape(const ControllerParameters *p) { return p->order == 2 && p->sets == 2; }

int model_compute_outputs(ModelInstance *m) {
    ControllerState *state = STATE(m);
    double *values = m->s->values;
    const ControllerParameters *p = &state->p;
    int n = p->order, rules = p->rules, paper_shape = default_shape(p);
    double e[MAX_ORDER], ym[MAX_ORDER], error[MAX_ORDER], alpha[MAX_ORDER], theta[MAX_RULES], xi[MAX_RULES];
    if (paper_shape) {
        e[0] = V(m, e), e[1] = V(m, de), ym[0] = V(m, ym), ym[1] = V(m, dym);
        theta[0] = V(m, theta1), theta[1] = V(m, theta2), theta[2] = V(m, theta3), theta[3] = V(m, theta4);
    } else {
        for (int i = 0; i < n; i++) {
            e[i] = values[ERROR_VR[i]];
            ym[i] = values[REFERENCE_VR[i]];
        }
        for (int j = 0; j < rules; j++) theta[j] = values[VRS_theta[j]];
    }
    if (CURE(m, filter_time_constant) > 0.0) filter_errors(m, n, e); /* (F1), off at 0 */
    double u = controller_output(e, ym, m->s->time, theta, V(m, w_hat), p, error, alpha, xi); /* [9] */
    /* u or some E^(i) is NaN or inf (or all overflow together): one test of their sum, as the Python edition's */
    double modified_sum = 0.0;
    if (paper_shape) {
        modified_sum = (modified_sum + error[0]) + error[1];
    } else {
        for (int i = 0; i < n; i++) modified_sum += error[i];
    }
    if (!isfinite(u + modified_sum)) return fail_outputs_overflow(m, u, error, e);
    V(m, u) = u;
    if (paper_shape) {
        V(m, E) = error[0], V(m, dE) = error[1], V(m, alpha1) = alpha[0], V(m, alpha2) = alpha[1];
        state->xi[0] = xi[0], state->xi[1] = xi[1], state->xi[2] = xi[2], state->xi[3] = xi[3];
    } else {
        for (int i = 0; i < n; i++) {
            values[MODIFIED_ERROR_VR[i]] = error[i];
            values[VRS_alpha[i]] = alpha[i];
        }
        for (int j = 0; j < rules; j++) state->xi[j] = xi[j];
    }
    m->outputs_stale = 0;
    return MODEL_OK;
}

#if HOST_ROBUST
/* let the latch rule see this doStep's inputs; restart on a re-latch, warn once */
#if defined(__GNUC__)
__attribute__((noinline)) /* the first doSteps only: apart from the per-step path of every other */
#endif
static int watch_initial_error(ModelInstance *m, double time) {
    ControllerState *state = STATE(m);
    double sample[MAX_ORDER];
    int n = (int)state->latch.order;
    for (int i = 0; i < n; i++) sample[i] = m->s->values[ERROR_VR[i]];
    int events = latch_observe(&state->latch, time, sample);
    if (events & LATCH_RELATCHED) {
        latch_initial_error(m);
        restart_adaptation(m);
        state->filter[FILTER_STARTED] = 0.0; /* the filter restarts at rest on the re-latched sample (F1) */
        if (model_compute_outputs(m) != MODEL_OK) return MODEL_ERROR; /* E, dE, xi from the new latch */
    }
    if (events & LATCH_DECIDED) {
        char message[2048];
        if (latch_warning(&state->latch, ERROR_NAMES, message, sizeof message)) fmu_warn(m, "%s", message);
    }
    return MODEL_OK;
}
#endif

#if HOST_ROBUST
/* u chatters (chatter_monitor): the warning, once */
MESSAGE_PATH static void warn_chatter(ModelInstance *m, double step_size) {
    char message[2048];
    chatter_warning(&STATE(m)->chatter, step_size, message, sizeof message);
    fmu_warn(m, "%s", message);
}
#endif

/* theta or w_hat would not be finite: the error names the step, tau and E; nothing changes */
MESSAGE_PATH static int fail_adaptation_diverged(ModelInstance *m, double current_time, double step_size, double tau,
                                    const double error[]) {
    char modified[256];
    return fmu_fail(m, "adaptation diverged in doStep(t=%.17g, h=%.17g): tau = %.17g from E = %s; theta and w_hat "
                    "keep their values at t; the inputs are out of range or the closed loop diverged", current_time,
                    step_size, tau, numbers_text(modified, sizeof modified, error, STATE(m)->p.order, "()"));
}

#if defined(__GNUC__)
#define SHAPE_INLINE inline __attribute__((always_inline))
#else
#define SHAPE_INLINE inline
#endif

/* the adaptive law's step [31] from the latched state; `paper_shape` (a constant where it is inlined): n = 2,
 * m = 2 (default_shape), so that the loops over the 4 rules are unrolled and the variables read by name */
static SHAPE_INLINE int adapt(ModelInstance *m, double current_time, double step_size, const int paper_shape) {
    ControllerState *state = STATE(m);
    double *values = m->s->values;
    const ControllerParameters *p = &state->p;
    int n = paper_shape ? 2 : p->order, rules = paper_shape ? 4 : p->rules;
    double error[MAX_ORDER], theta[MAX_RULES], adapted[MAX_RULES];
    if (paper_shape) {
        error[0] = V(m, E), error[1] = V(m, dE);
        theta[0] = V(m, theta1), theta[1] = V(m, theta2), theta[2] = V(m, theta3), theta[3] = V(m, theta4);
    } else {
        for (int i = 0; i < n; i++) error[i] = values[MODIFIED_ERROR_VR[i]];
        for (int j = 0; j < rules; j++) theta[j] = values[VRS_theta[j]];
    }
    double tau = adaptation_signal(n, error, p->p_b); /* [31] */
    double w_hat = V(m, w_hat);
    int cures = state->adapt_cures;
    if (cures && CURE(m, dead_zone) > 0.0) tau = dead_zone_signal(tau, CURE(m, dead_zone)); /* (31a), off at 0 */
    if (cures && CURE(m, sigma) > 0.0) { /* (31b), off at 0 */
        leaky_step(m, tau, step_size, theta, adapted, &w_hat);
    } else {
        adapted_weights(rules, theta, tau, state->xi, V(m, gamma), V(m, m_theta), V(m, delta), step_size, adapted);
        if (p->variant == VARIANT_FAE) w_hat += step_size * V(m, gamma_w) * tau;
    }
    /* some theta or w_hat is NaN or inf (or all overflow together): one test of their sum, as the Python edition's */
    double theta_sum = 0.0;
    for (int j = 0; j < rules; j++) theta_sum += adapted[j];
    if (!isfinite(w_hat + theta_sum)) return fail_adaptation_diverged(m, current_time, step_size, tau, error);
    if (paper_shape) {
        V(m, theta1) = adapted[0], V(m, theta2) = adapted[1], V(m, theta3) = adapted[2], V(m, theta4) = adapted[3];
    } else {
        for (int j = 0; j < rules; j++) values[VRS_theta[j]] = adapted[j];
    }
    V(m, w_hat) = w_hat;
    if (cures && CURE(m, filter_time_constant) > 0.0) commit_filter(m, n, current_time); /* (F1) */
#if HOST_ROBUST
    if (chatter_update(&state->chatter, V(m, u), step_size)) warn_chatter(m, step_size);
#endif
    return MODEL_OK;
}

int model_step(ModelInstance *m, double current_time, double step_size) {
    ControllerState *state = STATE(m);
#if HOST_ROBUST
    if (state->latch.open != 0.0 && watch_initial_error(m, current_time) != MODEL_OK) return MODEL_ERROR;
#endif
    return default_shape(&state->p) ? adapt(m, current_time, step_size, 1) : adapt(m, current_time, step_size, 0);
}

/* ---------------------------------------------------------------- model exchange */

int model_get_continuous_states(ModelInstance *m, double x[]) {
    for (int j = 0; j < N_theta; j++) x[j] = m->s->values[VRS_theta[j]];
    x[N_theta] = V(m, w_hat);
    return MODEL_OK;
}

int model_set_continuous_states(ModelInstance *m, const double x[]) {
    for (int j = 0; j < N_theta; j++) m->s->values[VRS_theta[j]] = x[j];
    V(m, w_hat) = x[N_theta];
    return MODEL_OK;
}

/* dtheta_j [31] and dw_hat at the instance's time, theta, w_hat and inputs: tau from the modified
 * error E and the basis xi of the outputs (controller_output [9]), as a doStep takes them */
int model_get_derivatives(ModelInstance *m, double dx[]) {
    ControllerState *state = STATE(m);
    if (m->outputs_stale && m->s->initialized == 0.0) {
        /* initialisation mode with invalid parameters (the outputs keep their start values, and so do
         * the derivatives: 0); exitInitializationMode reports the parameter */
        for (int j = 0; j < N_STATES; j++) dx[j] = 0.0;
        return MODEL_OK;
    }
    if (m->outputs_stale && model_compute_outputs(m) != MODEL_OK) return MODEL_ERROR;
    const double *values = m->s->values;
    const ControllerParameters *p = &state->p;
    int n = p->order, rules = p->rules;
    double error[MAX_ORDER], theta[MAX_RULES];
    for (int i = 0; i < n; i++) error[i] = values[MODIFIED_ERROR_VR[i]];
    for (int j = 0; j < rules; j++) theta[j] = values[VRS_theta[j]];
    double tau = adaptation_signal(n, error, p->p_b); /* [31] */
    if (CURE(m, dead_zone) > 0.0) tau = dead_zone_signal(tau, CURE(m, dead_zone)); /* (31a), off at 0 */
    adaptation_rates(rules, theta, tau, state->xi, V(m, gamma), V(m, m_theta), V(m, delta), dx); /* [31] */
    for (int j = rules; j < N_theta; j++) dx[j] = 0.0; /* rule weights beyond sets^order stay 0 */
    dx[N_theta] = p->variant == VARIANT_FAE ? estimate_rate(tau, V(m, gamma_w)) : 0.0;
    if (CURE(m, sigma) > 0.0) { /* (31b), off at 0 */
        leaky_rates(rules, theta, dx, CURE(m, sigma), dx);
        dx[N_theta] -= CURE(m, sigma) * V(m, w_hat);
    }
    return MODEL_OK;
}

int model_get_event_indicators(ModelInstance *m, double z[]) {
    (void)m; (void)z;
    return MODEL_OK;
}

int model_get_locals(ModelInstance *m, double values[]) {
    (void)m; (void)values;
    return MODEL_OK;
}

/* the event update: in event mode at the start time (the initial event iteration, before any
 * integration) the latched e(t0), de(t0), ... follow inputs the host set there, so that E(t0) = 0
 * holds for the inputs the continuous phase starts from; pinned values (initial_error = 2) stay */
int model_update_discrete_states(ModelInstance *m, int *states_changed) {
    *states_changed = 0;
#if HOST_ROBUST
    ControllerState *state = STATE(m);
    if (m->model_exchange && m->s->time == m->s->start_time && (int)V(m, initial_error) != INITIAL_ERROR_PINNED) {
        int n = (int)state->latch.order, moved = 0;
        double sample[MAX_ORDER];
        for (int i = 0; i < n; i++) {
            sample[i] = m->s->values[ERROR_VR[i]];
            moved = moved || sample[i] != state->latch.latched[i];
        }
        if (moved) {
            latch_pin(&state->latch, n, m->s->start_time, sample);
            latch_initial_error(m);
            m->outputs_stale = 1;
        }
    }
#else
    (void)m;
#endif
    return MODEL_OK;
}
