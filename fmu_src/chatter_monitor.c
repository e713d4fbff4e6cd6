/* The chatter monitor of u: see chatter_monitor.h and .py. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "chatter_monitor.h"

#define PI 3.141592653589793

void chatter_start(ChatterMonitor *state) { memset(state, 0, sizeof *state); }

static double floored_magnitude(const ChatterMonitor *state) {
    return state->magnitude >= CHATTER_U_FLOOR ? state->magnitude : CHATTER_U_FLOOR;
}

double chatter_frequency(const ChatterMonitor *state) {
    return state->variation_rate / floored_magnitude(state) / (2.0 * PI);
}

/* f > CHATTER_THRESHOLD_HZ needs variation_rate > CHATTER_THRESHOLD_HZ 2 pi magnitude up to the few
 * roundings (relative 1e-16 each) of f's two divisions: below this line, a relative 1e-9 under it, f is
 * below the threshold without dividing (the same verdict as chatter_monitor.update's; NaN is not below) */
#define CHATTER_CLEAR_BELOW (CHATTER_THRESHOLD_HZ * (2.0 * PI) * (1.0 - 1e-9))

int chatter_update(ChatterMonitor *state, double u, double step_size) {
    if (!(step_size > 0.0)) return 0;
    double weight = step_size / CHATTER_AVERAGING_TIME;
    if (weight > 1.0) weight = 1.0;
    if (state->samples != 0.0) {
        double rate = fabs(u - state->previous_u) / step_size;
        state->variation_rate += weight * (rate - state->variation_rate);
    } else {
        state->samples = 1.0;
    }
    state->magnitude += weight * (fabs(u) - state->magnitude);
    state->previous_u = u;
    state->elapsed += step_size;
    if (state->warned != 0.0 || state->elapsed < CHATTER_WARMUP) return 0;
    if (state->variation_rate < CHATTER_CLEAR_BELOW * floored_magnitude(state)) return 0;
    if (chatter_frequency(state) > CHATTER_THRESHOLD_HZ) {
        state->warned = 1.0;
        return 1;
    }
    return 0;
}

void chatter_warning(const ChatterMonitor *state, double step_size, char *message, size_t size) {
    /* chatter_monitor.warning's text, word for word */
    snprintf(message, size,
             "u chatters with communication step %g s: over the last ~%g s it varies like a %.4g Hz sine "
             "(total variation %.4g/s, mean |u| %.4g): over the %g Hz threshold (converged loops stay below "
             "%g Hz), so the results are not the controller's. If e, de are exact (a simulation without a sensor): "
             "the step is too large for the loop; use a smaller step (largest validated for a host that delays "
             "every link, Jacobi: %g s for the paper's pendulum scenarios, %g s for the manipulator), or a master "
             "that respects direct feedthrough (u depends directly on e, de, ym, dym: set them, then read u, at the "
             "same communication point). If e, de are measured (sensor noise, quantisation, a sample-and-hold or a "
             "delay, as on a rig): a smaller step does not help, the variable universe magnifies what the "
             "measurement adds by up to 1 / (1 - lambda_ce) near zero error; try the robust cures (alpha_min, "
             "dead_zone, sigma, filter_time_constant; docs/model.md section 14) or fixed universes (variant 2 or 3)",
             step_size, CHATTER_AVERAGING_TIME, chatter_frequency(state), state->variation_rate, state->magnitude,
             CHATTER_THRESHOLD_HZ, CHATTER_CONVERGED_HZ, 6.4e-5, 3.2e-5);  /* chatter_monitor.py's JACOBI_VALIDATED_STEP */
}
