/* The host-robust latch of the initial error: see initial_error_latch.h and .py. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "initial_error_latch.h"

void latch_start(InitialErrorLatch *state, int n, double time, const double sample[]) {
    state->order = n;
    state->open = LATCH_CHECK_STEPS;
    state->origin = state->previous_time = state->rejected_time = time;
    state->relatches = state->confirmed = 0.0;
    for (int i = 0; i < n; i++) state->latched[i] = state->previous[i] = state->rejected[i] = sample[i];
}

void latch_pin(InitialErrorLatch *state, int n, double time, const double values[]) {
    latch_start(state, n, time, values);
    state->open = 0.0;
}

int latch_consistent(int n, const double previous[], const double current[], double h) {
    for (int i = 0; i + 1 < n; i++) {
        double change = current[i] - previous[i];
        double predicted = 0.5 * h * (current[i + 1] + previous[i + 1]);
        double scale = fabs(change) >= fabs(predicted) ? fabs(change) : fabs(predicted);
        if (fabs(change - predicted) > LATCH_RELATIVE_TOLERANCE * scale + LATCH_ABSOLUTE_FLOOR) return 0;
    }
    return 1;
}

static void relatch(InitialErrorLatch *state, double time, const double current[]) {
    int n = (int)state->order;
    if (state->relatches == 0.0) { /* keep the first latch rejected, for the warning */
        state->rejected_time = state->origin;
        memcpy(state->rejected, state->latched, sizeof(double) * (size_t)n);
    }
    state->relatches += 1.0;
    state->origin = time;
    memcpy(state->latched, current, sizeof(double) * (size_t)n);
}

/* _start_agrees: is the first latch rejected (the start inputs) consistent with the current sample? */
static int start_agrees(const InitialErrorLatch *state, double time, const double current[]) {
    return time > state->rejected_time &&
           latch_consistent((int)state->order, state->rejected, current, time - state->rejected_time);
}

/* _restore_start: the start inputs were right, the samples in between were placeholders */
static void restore_start(InitialErrorLatch *state) {
    memcpy(state->latched, state->rejected, sizeof(double) * (size_t)state->order);
    state->origin = state->rejected_time;
    state->relatches = 0.0;
}

int latch_observe(InitialErrorLatch *state, double time, const double sample[]) {
    if (state->open <= 0.0) return 0;
    int n = (int)state->order;
    double current[MAX_ORDER];
    int differ = 0;
    for (int i = 0; i < n; i++) {
        current[i] = sample[i];
        differ = differ || current[i] != state->previous[i];
    }
    double h = time - state->previous_time;
    int events = 0;
    if (differ) {
        if (h > 0.0 && n > 1 && state->relatches != 0.0 && start_agrees(state, time, current)) {
            restore_start(state); /* fmpy's SSP simulator: 0 for two steps after consistent start values */
            state->open = 0.0;
            state->confirmed = 1.0;
            return LATCH_RELATCHED | LATCH_DECIDED;
        }
        if (h <= 0.0 || !latch_consistent(n, state->previous, current, h)) {
            relatch(state, time, current);
            events = LATCH_RELATCHED;
        } else if (n > 1) {
            state->open = 0.0;
            state->confirmed = 1.0;
            return LATCH_DECIDED; /* a consistent, informative pair: the latch stays, for good */
        }
    }
    memcpy(state->previous, current, sizeof(double) * (size_t)n);
    state->previous_time = time;
    state->open -= 1.0;
    if (state->open <= 0.0) {
        state->open = 0.0;
        events |= LATCH_DECIDED;
    }
    return events;
}

static size_t values_text(const char *const names[], const double values[], int n, char *out, size_t size) {
    size_t used = 0;
    for (int i = 0; i < n && used < size; i++)
        used += (size_t)snprintf(out + used, size - used, "%s%s = %.9g", i ? ", " : "", names[i], values[i]);
    return used;
}

int latch_warning(const InitialErrorLatch *state, const char *const names[], char *message, size_t size) {
    int n = (int)state->order;
    if (state->relatches == 0.0) return 0;
    char rejected[512], kept[512], moved[64] = "", confirmed[160] = "";
    values_text(names, state->rejected, n, rejected, sizeof rejected);
    values_text(names, state->latched, n, kept, sizeof kept);
    if (state->relatches != 1.0) snprintf(moved, sizeof moved, " (moved %d times)", (int)state->relatches);
    if (!(state->confirmed != 0.0 || n == 1))
        snprintf(confirmed, sizeof confirmed, "; no later pair of samples agreed with their derivatives within "
                 "%d doSteps", LATCH_CHECK_STEPS);
    snprintf(message, size,
             "initial error re-latched%s: rejected %s at t = %.9g as placeholders (the host did not propagate "
             "initial values); kept %s at t = %.9g as e(0) and time origin of the modified error (Remark 3)%s; "
             "adaptation restarted there. Propagate initial values before exitInitializationMode, or pin them "
             "(parameter initial_error = 2 with e0, de0, ...)",
             moved, rejected, state->rejected_time, kept, state->origin, confirmed);
    return 1;
}
