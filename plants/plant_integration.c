/* Fixed-step classical RK4: see plant_integration.py (rk4_advance, internal_step_count). */
#include <math.h>

#include "plant_integration.h"

long internal_step_count(double step_size, double max_internal_step) {
    if (step_size <= 0.0) return 0;
    double n = ceil(step_size / max_internal_step - SPLIT_TOLERANCE);
    return n > 1.0 ? (long)n : 1;
}

void rk4_advance(PlantDerivative derivative, double t, double *x1_io, double *x2_io, double u, double step_size,
                 double max_internal_step, const double *params) {
    long n = internal_step_count(step_size, max_internal_step);
    if (n == 0) return;
    double x1 = *x1_io, x2 = *x2_io;
    double h = step_size / (double)n;
    double half = 0.5 * h;
    double sixth = h / 6.0;
    for (long i = 0; i < n; i++) {
        double ti = t + (double)i * h; /* the grid point, not an accumulated sum */
        double tm = ti + half;
        double a1, b1, a2, b2, a3, b3, a4, b4;
        derivative(ti, x1, x2, u, params, &a1, &b1);
        derivative(tm, x1 + half * a1, x2 + half * b1, u, params, &a2, &b2);
        derivative(tm, x1 + half * a2, x2 + half * b2, u, params, &a3, &b3);
        derivative(ti + h, x1 + h * a3, x2 + h * b3, u, params, &a4, &b4);
        x1 = x1 + sixth * (a1 + 2.0 * (a2 + a3) + a4);
        x2 = x2 + sixth * (b1 + 2.0 * (b2 + b3) + b4);
    }
    *x1_io = x1;
    *x2_io = x2;
}
