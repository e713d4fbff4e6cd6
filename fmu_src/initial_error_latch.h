/* Which inputs give e(0), de(0), ... of the modified tracking error (Remark 3), in any FMI
 * host: the C twin of initial_error_latch.py (docs/host_robustness.md), function for
 * function.  The state is a struct of doubles (the Python edition's flat list, same fields),
 * so the FMU state copies and serialises it exactly. */
#ifndef AFC_INITIAL_ERROR_LATCH_H
#define AFC_INITIAL_ERROR_LATCH_H

#include <stddef.h>

#include "afc_math.h"

#define LATCH_CHECK_STEPS 8            /* doSteps watched at most before the latch is decided */
#define LATCH_RELATIVE_TOLERANCE 0.25  /* a placeholder pair misses by ~100 %, a smooth signal by O(h^2) */
#define LATCH_ABSOLUTE_FLOOR 1e-9      /* below it a mismatch does not count */

enum { LATCH_RELATCHED = 1, LATCH_DECIDED = 2 }; /* bits returned by latch_observe */

typedef struct {
    double open;          /* doSteps left to watch; 0 = decided */
    double origin;        /* t0: time of the latched sample */
    double previous_time; /* time of the previous sample */
    double rejected_time; /* time of the first latch rejected */
    double relatches;     /* how many times the latch moved */
    double confirmed;     /* 1 once a consistent pair of differing samples decided the latch */
    double latched[MAX_ORDER];  /* x(t0) = [e0, de0, ...] */
    double previous[MAX_ORDER]; /* the previous sample */
    double rejected[MAX_ORDER]; /* the first latch rejected */
    double order;               /* n */
} InitialErrorLatch;

/* latch sample (the inputs at exitInitializationMode) tentatively at t0 = time */
void latch_start(InitialErrorLatch *state, int n, double time, const double sample[]);
/* latch values (parameters) for good at t0 = time: no window, no warning */
void latch_pin(InitialErrorLatch *state, int n, double time, const double values[]);
/* 1 if every component of the pair agrees with its derivative (trapezoidal rule over h > 0) */
int latch_consistent(int n, const double previous[], const double current[], double h);
/* watch the inputs of one doStep at time; a bit set of LATCH_RELATCHED and LATCH_DECIDED */
int latch_observe(InitialErrorLatch *state, double time, const double sample[]);
/* the one message to log once decided after a re-latch (returns 1), else 0 */
int latch_warning(const InitialErrorLatch *state, const char *const names[], char *message, size_t size);

#endif
