/* Fixed-step classical RK4: see plant_integration.py (rk4_advance, rk4_advance_states, internal_step_count). */
#include <math.h>

#include "plant_integration.h"

long internal_step_count(double step_size, double max_internal_step) {
    if (step_size <= 0.0) return 0;
    double n = ceil(step_size / max_internal_step - SPLIT_TOLERANCE);
    return n > 1.0 ? (long)n : 1;
}

void rk4_advance_states(PlantDerivative derivative, double t, double x[], int states, double u,
                        double step_size, double max_internal_step, const double *params) {
    long n = internal_step_count(step_size, max_internal_step);
    if (n == 0) return;
    double h = step_size / (double)n;
    double half = 0.5 * h;
    double sixth = h / 6.0;
    double k1[PLANT_MAX_STATES], k2[PLANT_MAX_STATES], k3[PLANT_MAX_STATES], k4[PLANT_MAX_STATES];
    double stage[PLANT_MAX_STATES];
    for (long i = 0; i < n; i++) {
        double ti = t + (double)i * h; /* the grid point, not an accumulated sum */
        double tm = ti + half;
        derivative(ti, x, u, params, k1);
        for (int s = 0; s < states; s++) stage[s] = x[s] + half * k1[s];
        derivative(tm, stage, u, params, k2);
        for (int s = 0; s < states; s++) stage[s] = x[s] + half * k2[s];
        derivative(tm, stage, u, params, k3);
        for (int s = 0; s < states; s++) stage[s] = x[s] + h * k3[s];
        derivative(ti + h, stage, u, params, k4);
        for (int s = 0; s < states; s++) x[s] = x[s] + sixth * (k1[s] + 2.0 * (k2[s] + k3[s]) + k4[s]);
    }
}
