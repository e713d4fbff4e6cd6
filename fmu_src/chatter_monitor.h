/* Does the controller's own output u chatter?  The C twin of chatter_monitor.py
 * (docs/host_robustness.md):
 *   f = average(|u_k - u_k-1| / h) / max(average(|u_k|), U_FLOOR) / (2 pi)   [Hz],
 * both averages exponential over CHATTER_AVERAGING_TIME, judged after CHATTER_WARMUP s;
 * f > CHATTER_THRESHOLD_HZ is chatter, warned once. */
#ifndef AFC_CHATTER_MONITOR_H
#define AFC_CHATTER_MONITOR_H

#include <stddef.h>

#define CHATTER_AVERAGING_TIME 1.0 /* s, time constant of both averages */
#define CHATTER_WARMUP 1.0         /* s after the start before any verdict */
#define CHATTER_THRESHOLD_HZ 20.0  /* converged loops: < 1.9 Hz; chattering ones: > 170 Hz */
#define CHATTER_CONVERGED_HZ 2.0   /* what converged loops stay below (docs/host_robustness.md), for the message */
#define CHATTER_U_FLOOR 1e-9

typedef struct {
    double previous_u;     /* u at the previous doStep */
    double variation_rate; /* average of |u_k - u_k-1| / h */
    double magnitude;      /* average of |u_k| */
    double elapsed;        /* time since the start */
    double samples;        /* 0 until previous_u is set */
    double warned;         /* 1 once the warning was given */
} ChatterMonitor;

void chatter_start(ChatterMonitor *state);
double chatter_frequency(const ChatterMonitor *state);
/* account for the u of one doStep; 1 once, when chatter is first seen */
int chatter_update(ChatterMonitor *state, double u, double step_size);
/* the message for the host's log when chatter_update returned 1 */
void chatter_warning(const ChatterMonitor *state, double step_size, char *message, size_t size);

#endif
