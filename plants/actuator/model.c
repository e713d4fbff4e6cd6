/* Actuator: the limits between the controller and a plant as a native FMU: the C twin of this
 * folder's model.py (saturate, slew_rate, slew: the same operations in the same order) and fmu.py.
 * docs/model.md section 13: the command sampled and delayed by the chain (sampled_chain.c, (C1),
 * (C2)), then
 *
 *   v = min(max(c, -u_max), u_max)                 (A1)
 *   dr/dt = min(max((v - r) / Td, -R), R)          (A2)  Modelica's SlewRateLimiter
 *
 * Model Exchange: r is the continuous state slew_state, (A2) its derivative. */
#include <math.h>
#include <stdio.h>

#include "sampled_slave.h"

typedef struct {
    SampledState sampled;
    double slew;          /* r of (A2) */
    double slew_started;  /* r follows v until the first doStep (co-simulation) or the host's states (ME) */
    double target;        /* v of (A1) at the last output computation (model exchange's derivative reads it) */
} ActuatorState;

#define ACTUATOR(m) ((ActuatorState *)(m)->internal)

const size_t MODEL_INTERNAL_BYTES = sizeof(ActuatorState);
const int SAMPLED_CHANNELS = 1;
const int SAMPLED_INPUTS[] = {VR_u};
const char *const SAMPLED_INPUT_NAMES = "u";
const char *const SAMPLED_OUTPUT_NAMES = "u_applied";

/* v of (A1) (saturate) */
static double saturate(double command, double limit) {
    if (limit == 0.0) return command;
    if (command > limit) return limit;
    if (command < -limit) return -limit;
    return command;
}

/* dr/dt of (A2) (slew_rate) */
static double slew_rate(double applied, double target, double rate, double time_constant) {
    double speed = (target - applied) / time_constant;
    if (speed > rate) return rate;
    if (speed < -rate) return -rate;
    return speed;
}

/* r after duration of (A2) with the target held: the exact solution (slew) */
static double slew(double applied, double target, double duration, double rate, double time_constant) {
    double gap = target - applied;
    double band = rate * time_constant;
    if (-band <= gap && gap <= band) return target - gap * exp(-duration / time_constant);
    double ramp = ((gap > 0.0 ? gap : -gap) - band) / rate;
    double sign = gap > 0.0 ? 1.0 : -1.0;
    if (duration <= ramp) return applied + sign * rate * duration;
    return target - sign * band * exp(-(duration - ramp) / time_constant);
}

double sampled_process(ModelInstance *m, long k, int channel, double value, double previous) {
    (void)m; (void)k; (void)channel; (void)previous;
    return value;
}

/* the saturated command that holds now, from the chain's values */
static double target_of(ModelInstance *m, const double held[]) { return saturate(held[0], V(m, u_max)); } /* (A1) */

void sampled_set_outputs(ModelInstance *m, const double held[]) {
    ActuatorState *a = ACTUATOR(m);
    double target = target_of(m, held);
    a->target = target;
    if (a->slew_started == 0.0) a->slew = target; /* at rest until the first doStep: r = v */
    V(m, slew_state) = a->slew;
    V(m, u_applied) = V(m, rate_limit) != 0.0 ? a->slew : target;
}

void sampled_advance(ModelInstance *m, double begin, double end, const double held[]) {
    ActuatorState *a = ACTUATOR(m);
    double target = target_of(m, held);
    if (a->slew_started == 0.0) {
        a->slew = target;
        a->slew_started = 1.0;
    }
    if (V(m, rate_limit) != 0.0 && end > begin)
        a->slew = slew(a->slew, target, end - begin, V(m, rate_limit), V(m, rate_time_constant)); /* (A2) */
}

int sampled_feeds_through(ModelInstance *m) { return V(m, rate_limit) == 0.0; }

void sampled_initialize(ModelInstance *m) {
    ACTUATOR(m)->slew = 0.0;
    ACTUATOR(m)->slew_started = 0.0;
    ACTUATOR(m)->target = 0.0;
}

int model_cross_parameter_errors(ModelInstance *m, char *message, size_t size) {
    if (V(m, sample_period) == 0.0 && V(m, delay_samples) != 0.0) {
        snprintf(message, size, "parameter delay_samples = %.17g is invalid with sample_period = 0; valid range: 0 "
                 "(a delay in samples needs a clock of its own: give sample_period > 0)", V(m, delay_samples));
        return MODEL_ERROR;
    }
    return MODEL_OK;
}

/* model exchange: the state r (slew_state); the layer has computed the outputs (and so r at rest) before */
int model_get_continuous_states(ModelInstance *m, double x[]) {
    x[0] = ACTUATOR(m)->slew;
    return MODEL_OK;
}

int model_set_continuous_states(ModelInstance *m, const double x[]) {
    ACTUATOR(m)->slew = x[0];
    ACTUATOR(m)->slew_started = 1.0; /* the host integrates r from here */
    return MODEL_OK;
}

/* dr/dt of (A2) at the held command (the layer computed the outputs, and so v, before); 0 without a
 * rate limit (r keeps its initial value) */
int model_get_derivatives(ModelInstance *m, double dx[]) {
    ActuatorState *a = ACTUATOR(m);
    dx[0] = V(m, rate_limit) == 0.0 ? 0.0 : slew_rate(a->slew, a->target, V(m, rate_limit), V(m, rate_time_constant));
    return MODEL_OK;
}
